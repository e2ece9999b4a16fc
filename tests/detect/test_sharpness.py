"""The blur of the printed edges: its estimate against known blur, and a blurred camera named in a warning."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from handcap.cli import main
from handcap.detect.sharpness import BLUR_LEARNED, edge_blur
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
            image = maker.scene().image
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
