"""Cameras started one by one, calibrated from a moving board: offsets from the board's motion, then the rig.

Known truth: a board moving smoothly through the cage, filmed at four times the rate; each camera keeps every
fourth frame from its own phase and starts its own number of frames late. Real data (caliscope's four webcams):
``tests/multiview/test_calibration.py``.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.multiview.board_recordings import BoardDetections
from handcap.multiview.board_sync import board_offsets, shift_boards
from handcap.multiview.boards import parse_board
from handcap.multiview.calibration import calibrate_rig
from handcap.multiview.intrinsics import calibrate_intrinsics
from handcap.objects.rigid import kabsch
from handcap.synth.cameras import cage_rig

UP, FRAMES = 4, 150
START = np.array([0, 6, -4, 9])
PHASE = np.array([0, 1, 3, 2])


def _moving_board(rig, board, seed=0):
    """Each camera's BoardDetections of a board moving smoothly (see the module docstring)."""
    rng = np.random.default_rng(seed)
    middle = board.object_points.mean(axis=0)
    n = (FRAMES + 2 * START.max() + 2) * UP
    t = np.arange(n) / (30.0 * UP)
    pixels = np.full((len(rig), n, board.n_corners, 2), np.nan)
    for k in range(n):
        centre = np.array([0.0, 0.0, 1.0]) + 0.15 * np.array([np.sin(2.1 * t[k]), np.sin(1.7 * t[k] + 1),
                                                               0.5 * np.sin(2.9 * t[k])])
        facing = np.array([np.cos(1.2 * t[k]), np.sin(1.2 * t[k]), 0.6 * np.sin(1.3 * t[k])])
        facing /= np.linalg.norm(facing)
        x = np.cross(-facing, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        rotation = Rotation.from_rotvec(-facing * 0.6 * np.sin(1.1 * t[k])).as_matrix() \
            @ np.stack([x, np.cross(-facing, x), -facing], axis=1)
        corners = (board.object_points - middle) @ rotation.T + centre
        projected, _ = rig.project(corners)
        for c, camera in enumerate(rig):
            towards = camera.center - centre
            if facing @ towards > np.cos(np.radians(70)) * np.linalg.norm(towards) \
                    and camera.in_image(projected[c]).all():
                pixels[c, k] = projected[c] + rng.normal(0.0, 0.3, projected[c].shape)
    views = []
    for c, camera in enumerate(rig):
        hi = (np.arange(FRAMES) + START[c] + START.max()) * UP + PHASE[c]
        views.append(BoardDetections(board, pixels[c, hi], camera.size, f"{camera.name}.mp4",
                                     [f"frame {f}" for f in range(FRAMES)], np.arange(FRAMES)))
    return views


@pytest.fixture(scope="module")
def filmed():
    board = parse_board("charuco:7x5:0.04")
    rig = cage_rig(4, seed=1)
    return rig, _moving_board(rig, board)


def _centres_mm(rig, truth) -> float:
    """Largest distance of the calibrated camera centres from the truth after the best rigid fit, mm."""
    rotation, translation = kabsch(rig.centers, truth.centers)
    return 1000 * float(np.linalg.norm(rig.centers @ rotation.T + translation - truth.centers, axis=1).max())


def test_board_motion_gives_each_cameras_offset_and_the_rig_calibrates(filmed):
    truth, views = filmed
    cameras = [calibrate_intrinsics(v, name=c.name).camera for v, c in zip(views, truth)]
    sync = board_offsets(views, cameras, max_offset=20, names=truth.names)
    expected = START + PHASE / UP
    assert sync.warnings == () and np.abs(sync.offsets - expected).max() < 0.1, sync.summary()
    assert sync.after < 0.5 * sync.before  # millimetres here
    synced = calibrate_rig(shift_boards(views, sync.offsets), names=truth.names, cameras=cameras)
    assert _centres_mm(synced.rig, truth) < 6 and synced.rms.max() < 0.6 and synced.converged
    # as they came, frame f of each camera another moment: the pairs' board fits are far off
    assert sync.before > 10 * sync.after


def test_shifted_boards_interpolate_and_keep_the_reference_frames(filmed):
    truth, views = filmed
    shifted = shift_boards(views, [0.0, 0.5, 2.0, np.nan])
    assert all(np.array_equal(s.frames, views[0].frames) for s in shifted)
    assert np.array_equal(shifted[0].pixels, views[0].pixels, equal_nan=True)
    assert np.isnan(shifted[3].pixels).all()
    # camera 2's frame f shows the reference's f + 2: the reference's frame 10 is its frame 8
    assert np.array_equal(shifted[2].pixels[10], views[2].pixels[8], equal_nan=True)
    both = np.isfinite(views[1].pixels[9]).all() and np.isfinite(views[1].pixels[10]).all()
    if both:
        np.testing.assert_allclose(shifted[1].pixels[10], (views[1].pixels[9] + views[1].pixels[10]) / 2)
    with pytest.raises(HandcapError, match="one offset per camera"):
        shift_boards(views, [0.0])


def test_a_bundle_adjustment_cut_short_says_so(filmed, monkeypatch):
    truth, views = filmed
    cameras = [calibrate_intrinsics(v, name=c.name).camera for v, c in zip(views, truth)]
    monkeypatch.setattr("handcap.multiview.rig.MAX_EVALUATIONS", 2)
    boards = shift_boards(views, START + PHASE / UP)
    assert not calibrate_rig(boards, names=truth.names, cameras=cameras).converged
