"""The UCI hand-postures table: static records of unlabeled points."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.io import UciPostures, read_markers, read_uci_postures

POSTURES = "markers/uci_hand_postures/Postures.csv"


@pytest.fixture(scope="module")
def postures(shared_data):
    return read_uci_postures(shared_data / POSTURES)


def test_real_table(postures):
    assert isinstance(postures, UciPostures)
    assert len(postures) == 11022
    assert set(np.unique(postures.classes)) == {1, 2, 3}
    assert set(np.unique(postures.users)) <= set(range(15))
    assert postures.counts.min() >= 3 and postures.counts.max() == 12


def test_first_record_in_metres(postures):
    # Line 2: 1,0,54.26387995,71.46677614,-64.80770878,... then '?' from point 5 on.
    assert postures.classes[0] == 1 and postures.users[0] == 0
    assert postures.points[0].shape == (5, 3)
    np.testing.assert_allclose(postures.points[0][0], [0.05426387995, 0.07146677614, -0.06480770878])


def test_points_are_finite_and_hand_sized(postures):
    everything = np.concatenate(postures.points)
    assert np.isfinite(everything).all()
    assert np.abs(everything).max() < 0.5


def test_arrays_are_read_only(postures):
    with pytest.raises(ValueError):
        postures.points[0][0, 0] = 1.0


def test_read_markers_points_to_the_uci_reader(shared_data):
    with pytest.raises(HandcapError, match="not an OptiTrack Motive CSV export; read it with "
                                           "handcap.io.read_uci_postures"):
        read_markers(shared_data / POSTURES)


HEADER = "Class,User," + ",".join(f"X{k},Y{k},Z{k}" for k in range(3))


@pytest.mark.parametrize("rows, match", [
    (["1,0,1,2,3,4,5,6,?,?,?"], None),
    (["1,0,1,2,3,4,5,?,?,?,?"], r"line 2, point 1 is only partly absent"),
    (["1,0,1,2,3,4,5,6,?,?"], "data lines have 10 cells, expected 11"),
    (["1,0,1,2,3,4,five,6,?,?,?"], r"line 2, column 'Y1', holds 'five', not a number"),
    (["1.5,0,1,2,3,4,5,6,?,?,?"], "Class or User that is not a whole number"),
])
def test_small_tables(tmp_path, rows, match):
    path = tmp_path / "p.csv"
    path.write_text("\n".join([HEADER] + rows) + "\n")
    if match is None:
        table = read_uci_postures(path)
        np.testing.assert_allclose(table.points[0], [[0.001, 0.002, 0.003], [0.004, 0.005, 0.006]])
    else:
        with pytest.raises(HandcapError, match=match):
            read_uci_postures(path)


def test_wrong_header_is_refused(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("Class,User,A,B,C\n1,0,1,2,3\n")
    with pytest.raises(HandcapError, match="not the UCI hand-postures CSV"):
        read_uci_postures(path)
