"""TRC files (OpenSim / Motion Analysis): round trips and hand-written samples."""

import numpy as np
import pytest

from handcap import HandcapError, MarkerSequence
from handcap.io import read_markers, read_trc, write_markers, write_trc

# A TRC as OpenSim's examples write it (tab-separated, trailing tabs, a blank
# line before the data, empty fields for a missing marker).
SAMPLE = "\n".join([
    "PathFileType\t4\t(X/Y/Z)\tsubject01_walk1.trc",
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
    "60.00\t60.00\t3\t2\t{units}\t60.00\t1\t3",
    "Frame#\tTime\tR.ASIS\t\t\tL.ASIS\t\t\t",
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\t",
    "",
    "1\t0.000000\t{a}\t{b}\t{c}\t1\t2\t3\t",
    "2\t0.016667\t\t\t\t4\t5\t6\t",
    "3\t0.033333\t7\t8\t9\t10\t11\t12\t",
    "",
])


def _sample(tmp_path, units="mm", scale=1.0, name="s.trc"):
    path = tmp_path / name
    path.write_text(SAMPLE.format(units=units, a=100 * scale, b=200 * scale, c=300 * scale))
    return path


def test_sample_is_read(tmp_path):
    markers = read_trc(_sample(tmp_path))
    assert markers.names == ("R.ASIS", "L.ASIS")
    assert markers.rate == 60.0
    np.testing.assert_array_equal(markers.missing, [[False, False], [True, False], [False, False]])
    np.testing.assert_allclose(markers.positions[0], [[0.1, 0.2, 0.3], [0.001, 0.002, 0.003]])


@pytest.mark.parametrize("units, scale", [("m", 1e-3), ("cm", 0.1), ("mm", 1.0)])
def test_units_from_the_header(tmp_path, units, scale):
    # The same first marker written in m, cm and mm gives the same metres.
    markers = read_trc(_sample(tmp_path, units, scale))
    np.testing.assert_allclose(markers.positions[0, 0], [0.1, 0.2, 0.3], rtol=1e-12)


def _random(seed, frames=50, count=7, rate=120.0):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(-1.5, 1.5, size=(frames, count, 3))
    positions[rng.random((frames, count)) < 0.15] = np.nan
    names = [f"Subject:M{m}" for m in range(count - 1)] + ["right elbow"]
    return MarkerSequence(positions, names, rate)


@pytest.mark.parametrize("seed, rate", [(0, 120.0), (1, 69.9), (2, 1000 / 3)])
def test_round_trip(tmp_path, seed, rate):
    markers = _random(seed, rate=rate)
    write_trc(markers, tmp_path / "r.trc")
    back = read_trc(tmp_path / "r.trc")
    assert back.names == markers.names
    assert back.rate == markers.rate
    np.testing.assert_array_equal(back.missing, markers.missing)
    # Six decimals of a millimetre.
    np.testing.assert_allclose(back.positions, markers.positions, atol=5e-10 + 1e-12)


def test_round_trip_through_the_dispatcher(tmp_path):
    markers = _random(4)
    write_markers(markers, tmp_path / "r.TRC")
    np.testing.assert_allclose(read_markers(tmp_path / "r.TRC").positions, markers.positions, atol=1e-9)


def test_same_data_same_bytes(tmp_path):
    markers = _random(5)
    write_trc(markers, tmp_path / "a.trc")
    write_trc(markers, tmp_path / "b.trc")
    assert (tmp_path / "a.trc").read_bytes().replace(b"a.trc", b"b.trc") == (tmp_path / "b.trc").read_bytes()


def test_names_trc_cannot_store_are_refused(tmp_path):
    markers = MarkerSequence(np.zeros((2, 2, 3)), ["a\tb", "c"], 100.0)
    with pytest.raises(HandcapError, match="cannot be stored in TRC"):
        write_trc(markers, tmp_path / "bad.trc")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("edit, match", [
    (("60.00\t60.00\t3\t2", "60.00\t60.00\t3\t3"), "NumMarkers is 3 but the marker row names 2"),
    (("60.00\t60.00\t3\t2", "60.00\t60.00\t4\t2"), "NumFrames is 4 but the file holds 3 data rows"),
    (("\tL.ASIS\t\t\t", "\t\t\t\t"), "NumMarkers is 2 but the marker row names 1"),
    (("X2\tY2\tZ2", "X2\tY2"), "coordinate row has 5 labels, expected 6"),
    (("3\t0.033333\t7\t8", "3\t0.033333\t7\tx8"), r"line 9, column 'R.ASIS Y', holds 'x8', not a number"),
    (("3\t0.033333\t7\t8\t9", "3\t0.033333\t7\t8"), "line 9 has 8 cells, the other data lines 9"),
    (("1\t0.000000\t1", "1\t0.000000\t1\t0"), "line 7 has 10 cells, the other data lines 9"),
    (("PathFileType", "PathType"), "not a TRC file"),
    (("DataRate\t", "Rate\t"), "TRC header lacks DataRate"),
])
def test_inconsistent_files_are_refused(tmp_path, edit, match):
    path = tmp_path / "bad.trc"
    path.write_text(SAMPLE.format(units="mm", a=1, b=2, c=3).replace(*edit))
    with pytest.raises(HandcapError, match=match):
        read_trc(path)


def test_cut_file_is_refused(tmp_path):
    markers = _random(6, frames=20)
    write_trc(markers, tmp_path / "r.trc")
    text = (tmp_path / "r.trc").read_text()
    (tmp_path / "cut.trc").write_text(text[:-30])
    with pytest.raises(HandcapError, match="line 26 has .* cells, the other|ends in the middle of a line"):
        read_trc(tmp_path / "cut.trc")
    (tmp_path / "cut.trc").write_text(text[:text.rindex("\n", 0, -1) + 1])
    with pytest.raises(HandcapError, match="NumFrames is 20 but the file holds 19"):
        read_trc(tmp_path / "cut.trc")
