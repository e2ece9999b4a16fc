"""Training is deterministic for a seed; models round-trip through .npz; the joint regressor's frames."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.occlusion import OcclusionModel
from handcap.occlusion.data import simulate_take
from handcap.occlusion.takes import PosedTake
from handcap.occlusion.evaluate import marker_error_table, occlusion_windows
from handcap.occlusion.regressor import matrix_from_6d, outputs_to_world, targets_in_frame
from handcap.occlusion.train import registration_weights, train_occlusion_model


@pytest.fixture(scope="module")
def small_take():
    return simulate_take("active-9", "random", 400, 100.0, seed=5)


def _train(take, seed):
    return train_occlusion_model([take], "active-9", seed=seed, epochs=2, regressor_epochs=2,
                                 samples_per_epoch=2000)


def _arrays(model):
    return {**model.predictor.arrays(), **model.regressor.arrays()}


def test_training_is_deterministic_for_a_seed(small_take):
    a, b, c = _train(small_take, 3), _train(small_take, 3), _train(small_take, 4)
    same, other = _arrays(a), _arrays(b)
    assert all(np.array_equal(same[k], other[k]) for k in same)
    assert not np.array_equal(same["ae_w0"], _arrays(c)["ae_w0"])


def test_augmented_training_is_deterministic_for_a_seed(small_take, tmp_path):
    """As the shipped models are trained (per-sample augmentation) plus time-warped copies: same bytes."""
    from dataclasses import replace

    from handcap.occlusion.augment import SUBJECT_AUGMENTATION
    augmentation = replace(SUBJECT_AUGMENTATION, copies=1)
    for name in ("a", "b"):
        train_occlusion_model([small_take], "active-9", seed=3, epochs=2, regressor_epochs=2, samples_per_epoch=2000,
                              augmentation=augmentation).save(tmp_path / f"{name}.npz")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    plain = train_occlusion_model([small_take], "active-9", seed=3, epochs=2, regressor_epochs=2,
                                  samples_per_epoch=2000)
    assert not np.array_equal(OcclusionModel.load(tmp_path / "a.npz").predictor.net.weights[0],
                              plain.predictor.net.weights[0])


def test_model_round_trip(small_take, tmp_path):
    model = _train(small_take, 0)
    path = tmp_path / "m.npz"
    model.save(path)
    loaded = OcclusionModel.load(path)
    assert loaded.names == model.names and loaded.side == "right" and loaded.layout == "active-9"
    assert loaded.info["seed"] == "0" and loaded.info["posed_frames"] == "400"
    frame = small_take.positions[:5].copy()
    frame[:, 4] = np.nan
    assert np.array_equal(loaded.predictor.predict(frame), model.predictor.predict(frame))
    assert all(np.array_equal(x, y) for x, y in zip(loaded.regressor.predict(small_take.positions[:5]),
                                                    model.regressor.predict(small_take.positions[:5])))
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(HandcapError, match="not a readable"):
        OcclusionModel.load(path)


def test_wrist_pose_survives_the_registered_frame():
    rng = np.random.default_rng(0)
    phi, orient = rng.normal(0, 0.3, (7, 27)), Rotation.random(7, random_state=1).as_rotvec()
    transl = rng.normal(0, 1, (7, 3))
    rotation = Rotation.random(7, random_state=2).as_matrix()
    centre, template_centre = rng.normal(0, 1, (7, 3)), rng.normal(0, 0.1, (7, 3))
    out = targets_in_frame(phi, orient, transl, rotation, centre, template_centre)
    phi2, orient2, transl2 = outputs_to_world(out, rotation, centre, template_centre)
    assert np.allclose(phi2, phi) and np.allclose(transl2, transl)
    assert np.allclose(Rotation.from_rotvec(orient2).as_matrix(), Rotation.from_rotvec(orient).as_matrix())
    m = matrix_from_6d(rng.normal(size=(5, 6)))
    assert np.allclose(m @ np.swapaxes(m, -1, -2), np.eye(3)) and np.allclose(np.linalg.det(m), 1)


def test_registration_weights_favour_the_rigid_markers():
    from handcap.layouts import load_layout
    layout = load_layout("glove-13")
    w = registration_weights(layout, layout.names)
    assert w[:3].tolist() == [1.0, 1.0, 1.0] and (w[3:] == 0.1).all()
    assert (registration_weights(layout, layout.names[3:]) == 1).all()  # no rigid triad: equal weights


def test_training_needs_the_layout_markers(small_take):
    with pytest.raises(HandcapError, match="lacks marker"):
        train_occlusion_model([small_take], "glove-13", epochs=1)
    with pytest.raises(HandcapError, match="at least one take"):
        train_occlusion_model([], "active-9", epochs=1)
    empty = PosedTake(np.full((50, 9, 3), np.nan), small_take.names, 100.0)
    with pytest.raises(HandcapError, match="training frames"):
        train_occlusion_model([empty], "active-9", epochs=1)


def test_occlusion_windows_hide_exactly_k_of_fully_seen_frames(glove_split):
    _, test = glove_split
    visible = ~np.isnan(test).any(axis=-1)
    starts, frames, hidden = occlusion_windows(visible, 100.0, 0.5, 3, 200, np.random.default_rng(0))
    assert frames == 50 and (hidden.sum(axis=1) == 3).all()
    for s in starts:
        assert visible[s - 34:s + frames].all()
    with pytest.raises(HandcapError, match="keep 3"):
        occlusion_windows(visible, 100.0, 0.5, 11, 5, np.random.default_rng(0))


def test_table3_on_real_data(glove_split, glove_model):
    """Even a briefly trained network beats the baselines on the real glove (benchmarks/occlusion.py has
    the full grid with the fully trained one)."""
    _, test = glove_split
    table = marker_error_table(test, 100.0, glove_model.predictor, counts=(1, 4), durations=(0.2, 1.0),
                               seeds=range(2), windows=100)
    assert (table["nn"] < table["ac"]).all() and (table["nn"] < table["lk"]).all(), table
    assert (table["nn"] < table["nn-raw"]).all()  # the discontinuity offset helps
    assert (table["lk"] > 0.01).all()  # the fingers really move in these windows


def test_cli_trains_the_joint_regressor_from_poses(tmp_path, small_take):
    """``train-occlusion --poses``: a hand motion per take (as ``handcap solve`` writes) trains the regressor."""
    import subprocess
    import sys

    from handcap.core.markers import MarkerSequence
    from handcap.core.motion import HandMotion
    from handcap.hand import OpenHand
    from handcap.io import write_hand_motion, write_markers

    take, poses, out = tmp_path / "take.c3d", tmp_path / "motion.npz", tmp_path / "model.npz"
    write_markers(MarkerSequence(small_take.positions, small_take.names, 100.0), take)
    hand_pose = OpenHand().hand_pose_from_phi(small_take.phi)
    write_hand_motion(HandMotion(small_take.betas, small_take.global_orient, hand_pose, small_take.transl, 100.0,
                                 phi=small_take.phi), poses)
    r = subprocess.run([sys.executable, "-m", "handcap.cli", "train-occlusion", str(take), "--poses", str(poses),
                        "--layout", "active-9", "--epochs", "1", "--samples-per-epoch", "5000", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "joint regressor on 400 posed frames" in r.stdout
    assert OcclusionModel.load(out).regressor is not None


def test_info_says_how_much_data_it_saw(small_take):
    """Issue 14: the model (and train-occlusion) says how much data it saw; too few frames get a warning."""
    from handcap.core.errors import HandcapWarning
    from handcap.occlusion.augment import Augmentation

    other = simulate_take("active-9", "grasp", 300, 100.0, seed=6)
    with pytest.warns(HandcapWarning, match="trained on 700 frames"):
        model = train_occlusion_model([small_take, other], "active-9", epochs=1, regressor_epochs=1,
                                      samples_per_epoch=1000, augmentation=Augmentation(copies=0))
    assert model.warnings == ("the occlusion model was trained on 700 frames (fewer than 1000): expect poor fills; "
                              "train on longer takes, or add synthetic ones (train-occlusion --synthetic)",)
    model = train_occlusion_model([small_take, other], "active-9", epochs=1, regressor_epochs=1,
                                  samples_per_epoch=1000, augmentation=Augmentation(copies=2))
    info = model.info
    assert (info["takes"], info["synthetic_takes"], info["recorded_takes"], info["subjects"]) == (2, 2, 0, 2)
    assert info["frames"] == 700 and info["augmented_copies"] == 4 and info["samples"] == 1000
    assert 700 * 2 / 1.6 <= info["augmented_frames"] <= 700 * 2 / 0.6  # copies at 0.6-1.6x speed
    assert "scale 12 %" in info["augmentation"] and "2 time-warped copies" in info["augmentation"]
    assert info["posed_frames"] == 700 + info["augmented_frames"]
    assert model.warnings == ()  # 700 frames and two copies of them


def test_prefixed_names_train_the_same_model(small_take):
    """Issue 14: ``Subject:name`` columns are matched as fill matches them (MarkerSequence.index)."""
    prefixed = PosedTake(small_take.positions[:, ::-1], tuple(f"Hand:{n}" for n in small_take.names[::-1]), 100.0)
    plain = PosedTake(small_take.positions, small_take.names, 100.0)
    a = train_occlusion_model([plain], "active-9", epochs=1, samples_per_epoch=1000)
    b = train_occlusion_model([prefixed], "active-9", epochs=1, samples_per_epoch=1000)
    assert all(np.array_equal(x, y) for x, y in zip(a.predictor.arrays().values(), b.predictor.arrays().values()))
    twice = PosedTake(np.concatenate([small_take.positions] * 2, axis=1),
                      tuple(f"A:{n}" for n in small_take.names) + tuple(f"B:{n}" for n in small_take.names), 100.0)
    with pytest.raises(HandcapError, match="ambiguous"):
        train_occlusion_model([twice], "active-9", epochs=1)


def test_cli_train_and_fill_accept_the_same_prefixed_file(tmp_path, small_take, capsys):
    from handcap.cli import main  # in-process, as the command line runs it (loads torch)
    from handcap.core.markers import MarkerSequence
    from handcap.io import read_markers, write_markers

    take, model, out = tmp_path / "take.npz", tmp_path / "model.npz", tmp_path / "filled.npz"
    positions = small_take.positions.copy()
    positions[100:120, 5] = np.nan
    write_markers(MarkerSequence(positions, [f"Glove:{n}" for n in small_take.names], 100.0), take)
    assert main(["train-occlusion", str(take), "--layout", "active-9", "--epochs", "1", "--out", str(model)]) == 0
    r = capsys.readouterr()
    assert "saw 1 take(s) (1 recorded, 0 synthetic) of 1 subject(s), 400 frames" in r.out
    assert "warning: the occlusion model was trained on 400 frames" in r.err
    assert main(["fill", str(take), "--model", str(model), "--out", str(out)]) == 0
    filled = read_markers(out)
    assert filled.names == tuple(f"Glove:{n}" for n in small_take.names)
    assert not np.isnan(filled.positions).any()
    assert np.abs(filled.positions[100:120, 5] - small_take.positions[100:120, 5]).max() < 0.03


def test_cli_trains_on_synthetic_subjects_and_says_so(tmp_path, capsys):
    """``train-occlusion --synthetic 1 --augment --speed-copies 1``: no recorded take at all."""
    from handcap.cli import main  # in-process, as the command line runs it (loads torch)

    out = tmp_path / "generic.npz"
    assert main(["train-occlusion", "--synthetic", "1", "--augment", "--speed-copies", "1", "--layout", "active-9",
                 "--epochs", "1", "--samples-per-epoch", "5000", "--out", str(out)]) == 0
    r = capsys.readouterr()
    assert "saw 9 take(s) (0 recorded, 9 synthetic) of 9 subject(s), 5400 frames; 9 augmented copies" in r.out
    assert "augmentation: every sample: scale 12 %" in r.out and "1 time-warped copy per take" in r.out
    info = OcclusionModel.load(out).info
    assert info["synthetic_takes"] == "9" and info["augmented_copies"] == "9"
    assert main(["train-occlusion", "--layout", "active-9", "--out", str(tmp_path / "none.npz")]) == 2
    assert "give takes to train on, or --synthetic" in capsys.readouterr().err


def test_offset_consistent_loss_is_the_error_of_the_filled_gap():
    # Independent computation in numpy: the filler's prediction in a gap is the output there plus (truth before
    # minus output before) on the hidden coordinates; the loss is its squared error there, plus a tenth of the
    # plain weighted error.
    import torch

    from handcap.occlusion.predictor import ABSOLUTE_WEIGHT, offset_consistent_loss

    rng = np.random.default_rng(0)
    module = torch.nn.Linear(6, 6)
    x0, x1, y0, y1 = (rng.normal(size=(5, 6)) for _ in range(4))
    hidden = np.zeros((5, 6))
    hidden[:, :3] = 1.0
    w = np.where(hidden > 0, 1.0, 0.1)
    batch = tuple(torch.from_numpy(a.astype(np.float32)) for a in (x0, x1, y0, y1, w, hidden))
    got = float(offset_consistent_loss(module, batch).detach())
    weight = module.weight.detach().numpy().astype(np.float64)
    bias = module.bias.detach().numpy().astype(np.float64)
    out0, out1 = x0 @ weight.T + bias, x1 @ weight.T + bias
    filled = out1 + (y0 - out0) * hidden
    want = ((filled - y1) ** 2 * hidden).sum() / hidden.sum() + ABSOLUTE_WEIGHT * ((out1 - y1) ** 2 * w).sum() / w.sum()
    assert got == pytest.approx(want, rel=1e-5)


def test_pairs_stay_within_a_take_and_bad_lengths_are_refused(small_take):
    from handcap.occlusion.predictor import draw_pairs, train_marker_predictor

    lengths, steps = np.array([30, 200, 5]), np.array([29, 100, 0])
    pairs = draw_pairs(lengths, steps, 20000, np.random.default_rng(0))
    take = np.searchsorted(np.cumsum(lengths), pairs, side="right")
    assert np.array_equal(take[:, 0], take[:, 1])  # never across takes
    gap = pairs[:, 1] - pairs[:, 0]
    assert (gap >= 0).all() and (gap <= steps[take[:, 0]]).all() and (gap[take[:, 0] == 2] == 0).all()
    assert (gap[take[:, 0] == 1] >= 1).all() and gap[take[:, 0] == 1].max() == 100
    np.testing.assert_allclose(np.bincount(take[:, 0]) / len(pairs), lengths / lengths.sum(), atol=0.01)
    # Log-uniform: as many distances in 1-9 as in 10-100 (about).
    one = gap[take[:, 0] == 1]
    assert 0.4 < np.mean(one < 10) < 0.6

    positions = small_take.positions
    with pytest.raises(HandcapError, match="do not add up"):
        train_marker_predictor(positions, small_take.names, epochs=1, samples_per_epoch=100, lengths=[100, 100])
    with pytest.raises(HandcapError, match="pair_seconds"):
        train_occlusion_model([small_take], "active-9", epochs=1, pair_seconds=-1.0)
    # Takes of one frame each: no pair can span two takes, so every pair is a frame with itself (no error to
    # learn from the gap) and training still runs.
    model = train_marker_predictor(positions[:50], small_take.names, epochs=1, samples_per_epoch=200,
                                   lengths=[1] * 50, pair_steps=100)
    assert np.isfinite(model.net.weights[0]).all()


def test_paper_training_without_pairs_is_recorded(small_take):
    model = train_occlusion_model([small_take], "active-9", epochs=1, regressor_epochs=1, samples_per_epoch=500,
                                  pair_seconds=0.0)
    assert model.info["pair_seconds"] == 0.0
    assert _train(small_take, 0).info["pair_seconds"] == 1.0
