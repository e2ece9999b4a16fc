"""Calibration boards: their specification and their detection in images and videos.

The three ideas live in their own modules, all named here:

* :mod:`~handcap.multiview.board_spec` -- the board (:class:`Board`), its spec string
  (:func:`parse_board`, e.g. ``checkerboard:9x6:0.025`` or ``charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted``)
  and the board frame, written down once;
* :mod:`~handcap.multiview.board_corners` -- the board's corners in one image (:func:`detect_board`), in the
  canonical order every camera shares;
* :mod:`~handcap.multiview.board_recordings` -- the board in what one camera recorded: a video, a folder of
  images or image files (:func:`detect_in_files`), as :class:`BoardDetections` ``(T, N, 2)`` pixels.
"""

from handcap.multiview.board_corners import detect_board
from handcap.multiview.board_recordings import (IMAGE_SUFFIXES, BoardDetections, detect_in_files, detect_in_images,
                                                detect_in_video, image_files, is_image_file)
from handcap.multiview.board_spec import (DEFAULT_DICTIONARY, DEFAULT_MARKER_SCALE, KINDS, MIN_CHARUCO_CORNERS, Board,
                                          parse_board)

__all__ = ["Board", "BoardDetections", "detect_board", "detect_in_files", "detect_in_images", "detect_in_video",
           "image_files", "is_image_file", "parse_board"]
__all__ += ["DEFAULT_DICTIONARY", "DEFAULT_MARKER_SCALE", "IMAGE_SUFFIXES", "KINDS", "MIN_CHARUCO_CORNERS"]
