"""The blur of the printed edges: its estimate against known blur, and a blurred camera named in a warning."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from handcap.cli import main
from handcap.core.camera_rig import CameraRig
from handcap.core.cameras import Camera
from handcap.detect.sharpness import BLUR_LEARNED, edge_blur, image_blur
from handcap.patterns import session_pattern


def _board(sigma: float, turn_deg: float = 20.0):
    """A checkerboard of 24 px squares turned by ``turn_deg``, antialiased (drawn 4x larger, averaged down), blurred
    by ``sigma``; and its white squares' corners (B, 4, 2), pixels."""
    k, side, n = 4, 24, 9
    big = np.full((400 * k, 400 * k), 60, np.uint8)
    cells = (np.indices((n, n)).sum(axis=0) % 2 == 1)
    turn = cv2.getRotationMatrix2D((200.0, 200.0), turn_deg, 1.0)
    quads = []
    for r, c in zip(*np.nonzero(cells)):
        square = np.array([[c, r], [c + 1, r], [c + 1, r + 1], [c, r + 1]], float) * side + 200 - n * side / 2
        placed = square @ turn[:, :2].T + turn[:, 2]
        cv2.fillPoly(big, [np.rint((placed + 0.5) * k - 0.5).astype(np.int32)], 220)
        quads.append(placed)
    # The black squares between them: the board's dark cells and its border stay at 60 grey levels.
    image = cv2.resize(big, (400, 400), interpolation=cv2.INTER_AREA).astype(np.float32)
    if sigma:
        image = cv2.GaussianBlur(image, (0, 0), sigma)
    return np.clip(image, 0, 255).astype(np.uint8), np.array(quads)


def test_the_blur_of_a_known_edge_is_measured():
    measured = {sigma: edge_blur(*_board(sigma)) for sigma in (0.0, 1.0, 1.5, 2.0, 3.0)}
    sharp = measured[0.0]
    assert sharp < 0.8  # the antialiased edge itself
    for sigma in (1.0, 1.5, 2.0):
        expected = np.hypot(sigma, sharp)
        assert abs(measured[sigma] - expected) < 0.15 * expected, (sigma, measured[sigma], expected)
    # Measured: 0.56, 1.14, 1.60, 2.06 and 3.03 px, against 0.56, 1.15, 1.60, 2.08 and 3.05 px.
    assert abs(measured[3.0] - np.hypot(3.0, sharp)) < 0.15 * 3.0 and measured[2.0] > BLUR_LEARNED


def test_no_square_or_no_contrast_gives_nan():
    image, quads = _board(0.0)
    assert np.isnan(edge_blur(image, np.zeros((0, 4, 2))))
    assert np.isnan(edge_blur(np.full_like(image, 128), quads))


def test_an_unread_square_far_from_the_corners_scale_is_not_measured():
    sharp, quads = _board(0.0)
    # A bright soft-edged object (a held cylinder) beside the board, found as one unread "white square" of 120 px.
    image = sharp.astype(np.float32)
    blob = np.zeros_like(image)
    cv2.rectangle(blob, (260, 20), (380, 140), 1.0, -1)
    blob = cv2.GaussianBlur(blob, (0, 0), 6.0)
    image = np.clip(image * (1 - blob) + 230 * blob, 0, 255).astype(np.uint8)
    outline = np.array([[[260.0, 20.0], [380.0, 20.0], [380.0, 140.0], [260.0, 140.0]]])
    corners = np.unique(np.round(quads.reshape(-1, 2), 6), axis=0)
    alone = edge_blur(image, outline)
    assert alone > 4.0  # what the object alone would call the image
    # Unread, with the board's squares read or unread: the object is 5 times the corners' spacing, left out.
    with_board = image_blur(image, quads[:3], outline, np.r_[corners, outline[0]])
    assert with_board == pytest.approx(edge_blur(image, quads[:3]))
    assert image_blur(image, np.zeros((0, 4, 2)), np.r_[quads[:3], outline], np.r_[corners, outline[0]]) \
        == pytest.approx(edge_blur(image, quads[:3]))
    # The board's own squares unread and blurred by 2 px: measured as before (they are of the corners' scale).
    soft, _ = _board(2.0)
    assert image_blur(soft, np.zeros((0, 4, 2)), quads, corners) == pytest.approx(edge_blur(soft, quads))
    assert image_blur(soft, np.zeros((0, 4, 2)), quads, corners) > BLUR_LEARNED
    # Alone in an image (its four corners the only ones), a square is its own scale.
    assert image_blur(image, np.zeros((0, 4, 2)), outline, outline[0]) == pytest.approx(alone)


def test_rendered_hands_are_within_what_the_networks_learned_and_blurred_ones_are_not(scenes):
    for scene in scenes:
        assert edge_blur(scene.image, scene.blocks) < BLUR_LEARNED
        assert edge_blur(cv2.GaussianBlur(scene.image, (0, 0), 2.0), scene.blocks) > BLUR_LEARNED


def test_a_blurred_camera_is_named_in_a_stored_warning(tmp_path, capsys):
    pytest.importorskip("torch", reason="the detector's networks")
    from handcap.detect.scenes import PageMaker
    from handcap.synth.pages import PageLook

    maker = PageMaker(5, look=PageLook(square_px=(14.0, 16.0), tilt_deg=(0.0, 15.0), occluders=(0, 0),
                                       size=(480, 360), glint=0.0))
    for cam in ("sharp", "soft"):
        (tmp_path / cam).mkdir()
        for t in range(2):
            image = maker.scene().image  # its size drawn per photograph: each padded to the rig's 480 x 360 below
            image = cv2.copyMakeBorder(image, 0, 360 - image.shape[0], 0, 480 - image.shape[1], cv2.BORDER_REPLICATE)
            cv2.imwrite(str(tmp_path / cam / f"{t:06d}.png"), image if cam == "sharp"
                        else cv2.GaussianBlur(image, (0, 0), 2.0))
    pattern = tmp_path / "pattern.toml"
    session_pattern().save(pattern)
    out = tmp_path / "det.npz"
    assert main(["detect", str(tmp_path / "sharp"), str(tmp_path / "soft"), "--pattern", str(pattern),
                 "--out", str(out), "--rate", "30"]) == 0
    said = [w for w in np.load(out)["warnings"] if "blurred" in w]
    assert len(said) == 1 and said[0].startswith("2 of 4 images (camera soft)"), said
    assert said[0] in capsys.readouterr().err
    # With a rig too: the warning once named its cameras in the variable that held the rig, so the naming from the
    # other cameras that follows it failed ("need a CameraRig, got list").
    camera = Camera("sharp", (480, 360), [[500.0, 0, 239.5], [0, 500.0, 179.5], [0, 0, 1]])
    CameraRig([camera, Camera("soft", (480, 360), camera.matrix, translation=(0.1, 0.0, 0.0))]).save(
        tmp_path / "rig.toml")
    assert main(["detect", str(tmp_path / "sharp"), str(tmp_path / "soft"), "--pattern", str(pattern),
                 "--rig", str(tmp_path / "rig.toml"), "--out", str(tmp_path / "rig.npz"), "--rate", "30"]) == 0
    assert [w for w in np.load(tmp_path / "rig.npz")["warnings"] if "blurred" in w] == said
