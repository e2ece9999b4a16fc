"""Units at the boundary (issue 14): honest files untouched, certain mistakes converted with a warning,
impossible data refused in one line, and ``units=`` obeyed."""

from __future__ import annotations

import contextlib
import warnings

import numpy as np
import pytest

from handcap import HandcapError, MarkerSequence
from handcap.core.errors import HandcapWarning
from handcap.io import (
    read_markers,
    read_points,
    read_rig,
    save_npz,
    write_markers,
    write_markers_npz,
    write_points_npz,
)
from handcap.io._units import HAND_SPREAD, marker_spread, median_speed, rig_spread
from handcap.io.cameras import write_cameras_toml
from handcap.layouts import load_layout
from handcap.core.points import PointCloudSequence

RECORDING = "markers/hand_embodiment_glove/recording.tsv"
GLOVE = [m.name for m in load_layout("glove-13").hand_markers]


@pytest.fixture(scope="module")
def glove(shared_data):
    """The real glove recording (millimetres, read honestly), first 600 frames."""
    return read_markers(shared_data / RECORDING).frames(0, 600)


def _trc_declared(markers, path, unit):
    """A TRC of ``markers`` written in millimetres whose header says ``unit``."""
    write_markers(markers, path)
    path.write_text(path.read_text().replace("\tmm\t", f"\t{unit}\t", 1))
    return path


@contextlib.contextmanager
def _no_handcap_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error", HandcapWarning)
        yield


# -- figures against independent computations ---------------------------------------------------------------

def test_spread_is_the_median_of_the_largest_pairwise_distance():
    rng = np.random.default_rng(5)
    positions = rng.normal(size=(30, 6, 3))
    positions[4, :5] = np.nan                      # one marker seen: the frame does not count
    expected = [max(np.linalg.norm(p[i] - p[j]) for i in range(6) for j in range(6)
                    if not (np.isnan(p[i]).any() or np.isnan(p[j]).any()))
                for t, p in enumerate(positions) if t != 4]
    assert marker_spread(positions) == pytest.approx(np.median(expected))


def test_speed_of_a_marker_moving_alone():
    positions = np.zeros((11, 1, 3))
    positions[:, 0, 0] = np.linspace(0.0, 1.0, 11)        # 0.1 m per frame
    assert median_speed(positions, 100.0) == pytest.approx(10.0)


# -- honest files are left alone --------------------------------------------------------------------------

def test_real_glove_is_left_alone_with_and_without_the_hand(shared_data, glove):
    with _no_handcap_warning():
        as_hand = read_markers(shared_data / RECORDING, hand=GLOVE)
    assert as_hand.warnings == ()
    np.testing.assert_array_equal(as_hand.positions[:600], glove.positions)
    spread = marker_spread(glove.select(GLOVE).positions)
    assert HAND_SPREAD[0] < spread < HAND_SPREAD[1]


@pytest.mark.parametrize("name", ["ezc3d/Vicon.c3d", "auto_marker_label/S09_KneeltoRun02.c3d",
                                  "kineticstoolkit/kinematics_racing_static.c3d"])
def test_real_body_captures_are_left_alone(shared_data, name):
    with _no_handcap_warning():
        markers = read_markers(shared_data / "markers" / name)
    assert markers.warnings == ()


def test_two_hands_with_prefixes_are_not_one_wide_hand(glove, tmp_path):
    """Both hands carry the layout's names under Left:/Right: prefixes, 60 cm apart: each hand is measured alone."""
    hand = glove.select(GLOVE)
    both = np.concatenate([hand.positions, hand.positions + [0.6, 0.0, 0.0]], axis=1)
    names = [f"Left:{n}" for n in GLOVE] + [f"Right:{n}" for n in GLOVE]
    write_markers_npz(MarkerSequence(both, names, hand.rate), tmp_path / "two.npz")
    with _no_handcap_warning():
        markers = read_markers(tmp_path / "two.npz", hand=GLOVE)
    np.testing.assert_array_equal(markers.positions, both)


# -- certain mistakes are converted, with a warning -------------------------------------------------------

def test_trc_in_millimetres_declared_as_metres_is_read_in_millimetres(glove, tmp_path):
    path = _trc_declared(glove, tmp_path / "g.trc", "m")
    with pytest.warns(HandcapWarning, match="read as millimetres"):
        markers = read_markers(path, hand=GLOVE)
    np.testing.assert_allclose(markers.positions, glove.positions, atol=1e-9)
    assert len(markers.warnings) == 1 and "metres" in markers.warnings[0]


def test_metres_declared_as_millimetres_is_read_in_metres(glove, tmp_path):
    """A hand 0.18 mm across in millimetres, 1.8 mm in centimetres: only metres fit."""
    # TRC is written in millimetres: these numbers are the glove's in metres, under a header saying mm.
    path = _trc_declared(MarkerSequence(glove.positions / 1000.0, glove.names, glove.rate), tmp_path / "g.trc", "mm")
    with pytest.warns(HandcapWarning, match="read as metres"):
        markers = read_markers(path, hand=GLOVE)
    np.testing.assert_allclose(markers.positions, glove.positions, atol=1e-6)     # 6 decimals in the file


def test_the_warning_travels_with_the_markers(glove, tmp_path):
    path = _trc_declared(glove, tmp_path / "g.trc", "m")
    with pytest.warns(HandcapWarning):
        markers = read_markers(path, hand=GLOVE)
    write_markers(markers, tmp_path / "g.npz")
    assert read_markers(tmp_path / "g.npz").warnings == markers.warnings


# -- uncertain or impossible data are refused in one line ----------------------------------------------------

def test_declared_wrong_without_a_hand_asks_for_the_unit(glove, tmp_path):
    path = _trc_declared(glove, tmp_path / "g.trc", "m")
    with pytest.raises(HandcapError, match=r"fit mm or cm: give the unit \(--units mm\|cm\)") as err:
        read_markers(path)
    assert "\n" not in str(err.value)


def test_units_given_override_the_file(glove, tmp_path):
    path = _trc_declared(glove, tmp_path / "g.trc", "m")
    with _no_handcap_warning():
        markers = read_markers(path, units="mm")
    np.testing.assert_allclose(markers.positions, glove.positions, atol=1e-9)
    with pytest.warns(HandcapWarning, match="read in cm as asked"):
        read_markers(path, units="cm", hand=GLOVE)


@pytest.mark.parametrize("suffix", [".npz", ".trc"])
def test_coordinates_of_1e30_fit_no_unit(glove, tmp_path, suffix):
    """1e30 m is 1e27 m read as millimetres: no unit makes it a capture."""
    path = tmp_path / f"huge{suffix}"
    huge = glove.positions * 1e30
    if suffix == ".npz":
        save_npz(path, {"positions": huge, "names": np.array(glove.names), "rate": np.array(glove.rate)})
    else:
        _trc_declared(MarkerSequence(huge / 1000.0, glove.names, glove.rate), path, "m")
    with pytest.raises(HandcapError, match="fit no length unit") as err:
        read_markers(path, hand=GLOVE)
    assert "\n" not in str(err.value)
    with pytest.raises(HandcapError, match="fit no length unit"):
        read_markers(path, units="mm")


def test_points_file_in_millimetres_as_metres(glove, tmp_path):
    points = PointCloudSequence.from_markers(MarkerSequence(glove.positions * 1000.0, glove.names, glove.rate))
    write_points_npz(points, tmp_path / "p.npz")
    with pytest.raises(HandcapError, match="--units mm"):
        read_points(tmp_path / "p.npz")
    read = read_points(tmp_path / "p.npz", units="mm")
    np.testing.assert_allclose(read.padded(), PointCloudSequence.from_markers(glove).padded(), atol=1e-12)


@pytest.mark.parametrize("units", ["inch", "M", 3])
def test_unknown_units_are_refused(glove, tmp_path, units):
    write_markers(glove, tmp_path / "g.npz")
    if units == "M":
        read_markers(tmp_path / "g.npz", units=units)    # case does not matter
        return
    with pytest.raises(HandcapError, match="units must be mm, cm or m"):
        read_markers(tmp_path / "g.npz", units=units)


# -- camera rigs --------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def caliscope(shared_data):
    return read_rig(shared_data / "calibration" / "caliscope_4cam" / "camera_array.toml")


def test_real_rigs_are_left_alone(shared_data, caliscope):
    with _no_handcap_warning():
        qca = read_rig(shared_data / "calibration" / "pose2sim_4cam" / "Calib.qca.txt")
    assert caliscope.warnings == () and qca.warnings == ()
    assert 1.0 < rig_spread(caliscope.centers) < 10.0 and 1.0 < rig_spread(qca.centers) < 10.0


def test_rig_in_millimetres_of_a_large_room_is_read_in_millimetres(caliscope, tmp_path):
    """Cameras 5 m apart written in mm: 5000 "m" or 50 "m" in cm are both too far for a hand: only mm fits."""
    wide = caliscope.scaled(3.0)
    write_cameras_toml(wide.scaled(1000.0), tmp_path / "mm.toml")
    with pytest.warns(HandcapWarning, match="read as millimetres"):
        rig = read_rig(tmp_path / "mm.toml")
    np.testing.assert_allclose(rig.centers, wide.centers, atol=1e-9)
    assert len(rig.warnings) == 1


def test_rig_in_millimetres_of_a_small_room_asks_for_the_unit(caliscope, tmp_path):
    write_cameras_toml(caliscope.scaled(1000.0), tmp_path / "mm.toml")
    with pytest.raises(HandcapError, match=r"fit mm or cm: give the unit"):
        read_rig(tmp_path / "mm.toml")
    rig = read_rig(tmp_path / "mm.toml", units="mm")
    np.testing.assert_allclose(rig.centers, caliscope.centers, atol=1e-9)
    assert rig.warnings == ()


def test_rig_units_relative_to_the_formats_own(shared_data):
    """A QCA is in millimetres: units='mm' changes nothing, units='m' scales by 1000 (and warns)."""
    path = shared_data / "calibration" / "pose2sim_4cam" / "Calib.qca.txt"
    honest = read_rig(path)
    np.testing.assert_array_equal(read_rig(path, units="mm").centers, honest.centers)
    with pytest.warns(HandcapWarning, match="read in m as asked"):
        metres = read_rig(path, units="m")
    np.testing.assert_allclose(metres.centers, honest.centers * 1000.0)


def test_intrinsics_only_rig_skips_the_unit_check(caliscope, tmp_path):
    """Known intrinsics for a rig calibration: positions are not used, so a millimetre file is no error."""
    write_cameras_toml(caliscope.scaled(1000.0), tmp_path / "mm.toml")
    with _no_handcap_warning():
        rig = read_rig(tmp_path / "mm.toml", positions=False)
    np.testing.assert_array_equal(rig[0].matrix, caliscope[0].matrix)
