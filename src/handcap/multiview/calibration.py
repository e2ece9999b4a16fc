"""Camera calibration from a planar board: intrinsics per camera, then the whole rig.

DexterCap (section 3.1.1) calibrates its cameras "using the standard procedure
with the OpenCV library". That is what this module does, in two stages:

1. **Intrinsics** (:func:`calibrate_intrinsics`): :func:`cv2.calibrateCamera`
   on the board views of one camera (Zhang's method, OpenCV's five distortion
   terms ``k1 k2 p1 p2 k3``), dropping views that reproject much worse than
   the others and calibrating again.
2. **Rig** (:func:`calibrate_rig`): every camera films the same board at the
   same instants (synchronised recordings; frame index = time). Each view's
   board pose comes from :func:`cv2.solvePnP`; two cameras that saw the board
   at the same instant know their relative pose, and chaining those over a
   maximum spanning tree of the cameras (weighted by shared views) places every
   camera. :func:`bundle_adjust` then refines every camera pose and every board
   pose together (and optionally the intrinsics) by minimising the reprojection
   error of all corners with :func:`scipy.optimize.least_squares`, a sparse
   Jacobian and a robust loss.

World frame of a rig (written down once)
----------------------------------------
``origin="board"`` (default): the board as it lay at ``origin_frame`` (by
default the first frame in which the first camera sees it). The origin is the
board frame's origin (corner 0 of a checkerboard, the outer corner of a
ChArUco board, see :mod:`handcap.multiview.boards`), x runs along the board's
rows, and z points out of the printed face, towards the cameras that see it;
y = z x x. A board lying face up on the floor thus gives z up, as DESIGN.md
wants. ``origin="camera"``: the first camera's frame (OpenCV's: x right, y
down, z along its optical axis), that camera at the origin. Either way the
unit is the metre, fixed by the board's square size.

References
----------
Zhang Z. (2000), A flexible new technique for camera calibration, IEEE TPAMI
22(11), doi:10.1109/34.888718.
Triggs B. et al. (2000), Bundle adjustment -- a modern synthesis, Vision
Algorithms: Theory and Practice, doi:10.1007/3-540-44480-7_21.
"""


from handcap.multiview.bundle import LOSSES, BundleAdjustment, bundle_adjust
from handcap.multiview.intrinsics import MIN_VIEWS, Intrinsics, board_poses, calibrate_intrinsics
from handcap.multiview.rig import ORIGINS, RigCalibration, calibrate_rig

__all__ = ["LOSSES", "MIN_VIEWS", "ORIGINS", "BundleAdjustment", "Intrinsics", "RigCalibration", "board_poses",
           "bundle_adjust", "calibrate_intrinsics", "calibrate_rig"]
