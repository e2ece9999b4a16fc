"""Qualisys QTM TSV exports, against the real glove recording in ../shared/data."""

import time

import numpy as np
import pytest

from handcap import HandcapError
from handcap.io import read_markers, read_qualisys_tsv

RECORDING = "markers/hand_embodiment_glove/recording.tsv"
NAMES = ("hand_top", "hand_left", "hand_right", "thumb_tip", "thumb_middle", "little_tip", "little_middle",
         "ring_tip", "ring_middle", "middle_middle", "middle_tip", "index_tip", "index_middle", "right_elbow",
         "back_top", "back_left", "back_right", "right_shoulder", "pillow_top", "pillow_left", "pillow_right")


@pytest.fixture(scope="module")
def recording(shared_data):
    return read_qualisys_tsv(shared_data / RECORDING)


@pytest.fixture
def lines(shared_data):
    """The real file's lines, each with its CRLF ending."""
    return (shared_data / RECORDING).read_text().splitlines(keepends=True)


def test_real_recording_sizes(recording):
    assert recording.positions.shape == (6000, 21, 3)
    assert recording.rate == 100.0
    assert recording.names == NAMES
    assert recording.residuals is None


def test_real_recording_is_in_metres(recording):
    # First data row of the file: hand_top 110.406 135.075 460.584 (mm).
    np.testing.assert_allclose(recording.positions[0, 0], [0.110406, 0.135075, 0.460584], atol=1e-12)
    assert np.nanmax(np.abs(recording.positions)) < 1.0


@pytest.mark.parametrize("name, gaps", [
    ("thumb_tip", (17, 57)),
    ("ring_tip", (1, 42)),
    ("middle_tip", (2, 47)),
])
def test_real_gaps(recording, name, gaps):
    stats = {g.name: g for g in recording.gaps()}
    assert (stats[name].n_gaps, stats[name].max_gap) == gaps
    if name == "middle_tip":
        assert sorted(stats[name].gap_lengths) == [31, 47]


def test_other_markers_have_no_gaps(recording):
    with_gaps = {g.name for g in recording.gaps() if g.n_gaps or g.leading or g.trailing}
    assert with_gaps == {"thumb_tip", "ring_tip", "middle_tip"}


def test_reading_is_fast(shared_data):
    start = time.perf_counter()
    read_markers(shared_data / RECORDING)
    assert time.perf_counter() - start < 2.0


def _write(tmp_path, lines, name="rec.tsv"):
    path = tmp_path / name
    path.write_text("".join(lines), newline="")
    return path


def test_file_cut_at_a_line_boundary_is_refused(tmp_path, lines):
    with pytest.raises(HandcapError, match="NO_OF_FRAMES is 6000 but the file holds 5990 data rows"):
        read_qualisys_tsv(_write(tmp_path, lines[:-10]))


def test_file_cut_inside_a_line_is_refused(tmp_path, lines):
    last = lines[-1][:len(lines[-1]) // 2]
    with pytest.raises(HandcapError, match="line 6012 has|ends in the middle of a line"):
        read_qualisys_tsv(_write(tmp_path, lines[:-1] + [last]))


def test_file_cut_inside_the_last_number_is_refused(tmp_path, lines):
    last = lines[-1].rstrip("\r\n")[:-2]
    with pytest.raises(HandcapError, match="ends in the middle of a line"):
        read_qualisys_tsv(_write(tmp_path, lines[:-1] + [last]))


def test_missing_column_is_refused(tmp_path, lines):
    # Drop the 'thumb_tip Y' column (index 2 + 3 * 3 + 1) everywhere.
    def drop(line, k=12):
        cells = line.rstrip("\r\n").split("\t")
        return "\t".join(cells[:k] + cells[k + 1:]) + "\r\n"
    edited = lines[:11] + [drop(line) for line in lines[11:]]
    with pytest.raises(HandcapError, match="no column 'thumb_tip Y'"):
        read_qualisys_tsv(_write(tmp_path, edited))


def test_non_numeric_cell_is_refused(tmp_path, lines):
    cells = lines[20].split("\t")
    cells[5] = "12.3.4"
    edited = lines[:20] + ["\t".join(cells)] + lines[21:]
    with pytest.raises(HandcapError, match=r"line 21, column 'hand_left X', holds '12.3.4', not a number"):
        read_qualisys_tsv(_write(tmp_path, edited))


def test_wrong_marker_count_is_refused(tmp_path, lines):
    edited = [line.replace("NO_OF_MARKERS\t21", "NO_OF_MARKERS\t20") for line in lines]
    with pytest.raises(HandcapError, match="NO_OF_MARKERS is 20 but MARKER_NAMES lists 21"):
        read_qualisys_tsv(_write(tmp_path, edited))


def test_missing_header_key_is_refused(tmp_path, lines):
    edited = [line for line in lines if not line.startswith("FREQUENCY")]
    with pytest.raises(HandcapError, match="header lacks FREQUENCY"):
        read_qualisys_tsv(_write(tmp_path, edited))


def test_duplicated_row_is_refused(tmp_path, lines):
    # Frame count right, but one frame twice and the last one lost.
    edited = lines[:100] + [lines[99]] + lines[100:-1]
    with pytest.raises(HandcapError, match="frame numbers jump"):
        read_qualisys_tsv(_write(tmp_path, edited))


OLD_STYLE = [
    "NO_OF_FRAMES\t3", "NO_OF_CAMERAS\t4", "NO_OF_MARKERS\t2", "FREQUENCY\t240",
    "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--", "TIME_STAMP\t2009-05-18, 14:05:03",
    "DATA_INCLUDED\t3D", "EVENT\tstart\t1\t0.000", "MARKER_NAMES\tRTHUMB\tRINDEX",
    "10.0\t20.0\t30.0\t1.0\t2.0\t3.0",
    "0.000\t0.000\t0.000\t1.5\t2.5\t3.5",
    "11.0\tnull\t31.0\t0.000\t2.0\t3.0",
]


def test_old_export_without_column_header(tmp_path):
    # No Frame/Time columns, 0.000 triplets and 'null' for missing samples; a
    # single zero coordinate is a real value.
    path = tmp_path / "old.tsv"
    path.write_text("\r\n".join(OLD_STYLE) + "\r\n")
    markers = read_qualisys_tsv(path)
    assert markers.names == ("RTHUMB", "RINDEX") and markers.rate == 240.0
    np.testing.assert_array_equal(markers.missing, [[False, False], [True, False], [True, False]])
    np.testing.assert_allclose(markers.positions[2, 1], [0.0, 0.002, 0.003])
    np.testing.assert_allclose(markers.positions[0, 0], [0.010, 0.020, 0.030])


def test_frame_and_time_without_column_header(tmp_path):
    lines = OLD_STYLE[:11] + [f"{k + 1}\t{k / 240:.5f}\t" + row for k, row in enumerate(OLD_STYLE[11:])]
    path = tmp_path / "ft.tsv"
    path.write_text("\n".join(lines) + "\n")
    np.testing.assert_allclose(read_qualisys_tsv(path).positions[0, 1], [0.001, 0.002, 0.003])


def test_6d_export_is_refused(tmp_path):
    path = tmp_path / "6d.tsv"
    path.write_text("\n".join(OLD_STYLE).replace("DATA_INCLUDED\t3D", "DATA_INCLUDED\t6D") + "\n")
    with pytest.raises(HandcapError, match="holds 6D data; export 3D marker trajectories"):
        read_qualisys_tsv(path)


@pytest.mark.parametrize("content, match", [
    ("", "empty file"),
    ("hello\tworld\n1\t2\n", "not a Qualisys TSV export"),
    ("\0\1\2binary", "binary data, not a Qualisys TSV export"),
])
def test_files_that_are_not_tsv_exports(tmp_path, content, match):
    path = tmp_path / "x.tsv"
    path.write_bytes(content.encode("latin-1"))
    with pytest.raises(HandcapError, match=match):
        read_markers(path)


def test_rows_ending_with_a_tab(tmp_path, lines):
    # Every line ending with a tab is accepted; one row that lost a value is not.
    edited = lines[:12] + [line.rstrip("\r\n") + "\t\r\n" for line in lines[12:]]
    assert read_qualisys_tsv(_write(tmp_path, edited)).n_frames == 6000
    cells = edited[500].split("\t")
    edited[500] = "\t".join(cells[:7] + cells[8:])
    with pytest.raises(HandcapError, match="line 501 has 65 cells, the other data lines 66"):
        read_qualisys_tsv(_write(tmp_path, edited))
