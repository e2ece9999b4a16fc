"""Every file in ../shared/data/markers loads with sane numbers or fails with one clear line."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.io import read_markers, read_uci_postures

# What each file gives: (frames, rate Hz, markers), or the start of the error it raises.
EXPECTED = {
    "ezc3d/Vicon.c3d": (580, 100.0, 51),
    "ezc3d/Qualisys.c3d": (340, 200.0, 55),
    "ezc3d/Optotrak.c3d": "truncated C3D file",  # header promises 1149 frames, 29 are there
    "hand_embodiment_glove/recording.tsv": (6000, 100.0, 21),
    "uci_hand_postures/Postures.csv": "not an OptiTrack Motive",
    "auto_marker_label/S09_KneeltoRun02.c3d": (1479, 240.0, 75),
    "auto_marker_label/KneeltoProne01.c3d": (1745, 240.0, 62),
    "kineticstoolkit/kinematics_racing_probing_acromion_R.c3d": (140, 69.5, 41),
    "kineticstoolkit/kinematics_racing_probing_radial_styloid_R.c3d": (140, 69.5, 41),
    "kineticstoolkit/kinematics_racing_probing_ulnar_styloid_R.c3d": (140, 69.5, 41),
    "kineticstoolkit/kinematics_racing_propulsion.c3d": (700, 69.992615, 41),
    "kineticstoolkit/kinematics_racing_static.c3d": (700, 69.9, 41),
    "kineticstoolkit/c3d_test_suite/Sample01/Eb015pi.c3d": (450, 50.0, 26),
    "kineticstoolkit/c3d_test_suite/Sample01/Eb015pr.c3d": (450, 50.0, 26),
    **{f"kineticstoolkit/c3d_test_suite/Sample02/{o}_{k}.c3d": (89, 50.0, 36)
       for o in ("dec", "pc", "sgi") for k in ("int", "real")},
}


def data_files(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")
                  if p.is_file() and not p.name.upper().startswith("LICENSE"))


def test_the_table_covers_every_file(shared_data):
    assert data_files(shared_data / "markers") == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_real_file(shared_data, name):
    path = shared_data / "markers" / name
    expect = EXPECTED[name]
    if isinstance(expect, str):
        with pytest.raises(HandcapError, match=expect) as err:
            read_markers(path)
        assert "\n" not in str(err.value)
        return
    markers = read_markers(path)
    assert (markers.n_frames, markers.n_markers) == expect[::2]
    assert markers.rate == pytest.approx(expect[1], rel=1e-6)
    seen = markers.positions[~markers.missing]
    # Metres: a lab is a few metres across, a marker never kilometres or micrometres away.
    assert 0.05 < np.ptp(seen, axis=0).max() < 20


def test_uci_postures_read_as_static_point_sets(shared_data):
    postures = read_uci_postures(shared_data / "markers" / "uci_hand_postures" / "Postures.csv")
    assert len(postures.points) == 11022
    counts = np.array([len(p) for p in postures.points])
    assert counts.min() >= 3 and counts.max() <= 12
    assert 0.01 < np.abs(np.concatenate(postures.points)).max() < 1.0  # millimetres became metres
