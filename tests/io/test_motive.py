"""OptiTrack Motive CSV exports.

No Motive export ships with ../shared/data, so the tests write samples that
mirror the exact layout of two public real exports:

* format 1.23 (Motive 2.x): Skylark0924/Rofunc,
  ``data/MULTIMODAL/optitrack_data/Take 2023-03-29 06.23.40 PM.csv`` -- labelled
  Type/Name/ID rows, rigid bodies of 7 columns, quoted marker IDs, the rigid
  body's markers both as ``Rigid Body Marker`` and as ``Marker`` columns;
* format 1.21 (Motive 1.9): cmuphyscomp/hmv-s16,
  ``python/rhinoscripts/sample_optitrack_take.csv`` -- unlabelled header rows,
  ``Error Per Marker`` and ``Marker Quality`` columns, ``Unlabeled:108`` markers,
  a ``Time`` column, trailing empty cells for markers that are gone.
"""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.io import read_markers, read_motive_csv

RIGID_ID = "7264DAA5CE1811ED641E45F35C844C9A"


def _take(seed=0, frames=30):
    """Marker trajectories in millimetres, NaN where Motive leaves the cells empty."""
    rng = np.random.default_rng(seed)
    base = {"Hand:Marker1": [-91.9, 882.9, 252.6], "Hand:Marker2": [-118.7, 761.5, 232.2],
            "Hand:Marker3": [-59.6, 767.2, 163.4], "Unlabeled 1000": [358.1, 1083.2, -402.7]}
    take = {name: np.asarray(p) + np.cumsum(rng.normal(0, 0.5, (frames, 3)), axis=0) for name, p in base.items()}
    take["Hand:Marker2"][10:14] = np.nan
    take["Unlabeled 1000"][:5] = np.nan
    return take


def _cells(values, scale):
    return ["" if np.isnan(v) else f"{v * scale:.6f}" for v in values]


def motive_123(take, units="Millimeters", rate=120.0, total=None):
    """Lines of a format-1.23 export: a rigid body 'Hand', its markers, an unlabeled marker."""
    scale = {"Millimeters": 1.0, "Meters": 1e-3, "Centimeters": 0.1}[units]
    frames = len(next(iter(take.values())))
    total = frames if total is None else total
    rigid_markers = [n for n in take if n.startswith("Hand:")]
    types = [""] + ["Rigid Body"] * 7 + ["Rigid Body Marker"] * 3 * len(rigid_markers) + ["Marker"] * 3 * len(take)
    names = ["Hand"] * 7 + [n for n in rigid_markers for _ in range(3)] + [n for n in take for _ in range(3)]
    ids = [RIGID_ID] * (7 + 3 * len(rigid_markers)) + [f'"C5B9801{k}CE1B11ED641E45F35C844C9A"'
                                                       for k in range(len(take)) for _ in range(3)]
    parts = ["Rotation"] * 4 + ["Position"] * (3 + 3 * len(rigid_markers) + 3 * len(take))
    axes = ["X", "Y", "Z", "W"] + ["X", "Y", "Z"] * (1 + len(rigid_markers) + len(take))
    lines = [f"Format Version,1.23,Take Name,Take 2023-03-29 06.23.40 PM,Take Notes,,Capture Frame Rate,"
             f"{rate:.6f},Export Frame Rate,{rate:.6f},Capture Start Time,2023-03-29 06.23.40.520 PM,"
             f"Capture Start Frame,87471,Total Frames in Take,{total},Total Exported Frames,{total},"
             f"Rotation Type,Quaternion,Length Units,{units},Coordinate Space,Global",
             "",
             ",".join(types[:1] + ["Type"] + types[1:]),
             ",".join(["", "Name"] + names),
             ",".join(["", "ID"] + ids),
             ",".join(["", ""] + parts),
             ",".join(["Frame", "Time (Seconds)"] + axes)]
    for k in range(frames):
        centre = np.nanmean([take[n][k] for n in rigid_markers], axis=0)
        row = [str(k), f"{k / rate:.6f}", "0.032550", "0.490528", "0.814384", "0.308385", *_cells(centre, scale)]
        # Rigid Body Marker cells hold the solved body's marker positions, not the
        # measurement: make them differ so that reading them by mistake shows.
        for n in rigid_markers:
            row += _cells(np.nan_to_num(take[n][k], nan=0.0) + 5.0, scale)
        for n in take:
            row += _cells(take[n][k], scale)
        lines.append(",".join(row))
    return lines


def motive_121(take, rate=120.0):
    """Lines of a format-1.21 export (no row labels, error and quality columns), in metres."""
    frames = len(next(iter(take.values())))
    rigid_markers = [n for n in take if n.startswith("Hand:")]
    unlabeled = {n.replace("Unlabeled 1000", "Unlabeled:108"): v for n, v in take.items() if n.startswith("Unl")}
    labeled = {n: v for n, v in take.items() if n.startswith("Hand:")}
    markers = {**unlabeled, **labeled}
    types = ["Rigid Body"] * 8 + ["Rigid Body Marker"] * 4 * len(rigid_markers) + ["Marker"] * 3 * len(markers)
    names = (["Hand"] * 8 + [f"Hand_{i + 1}" for i in range(len(rigid_markers)) for _ in range(4)]
             + [n for n in markers for _ in range(3)])
    parts = (["Rotation"] * 4 + ["Position"] * 3 + ["Error Per Marker"]
             + ["Position", "Position", "Position", "Marker Quality"] * len(rigid_markers)
             + ["Position"] * 3 * len(markers))
    axes = (["X", "Y", "Z", "W", "X", "Y", "Z", ""] + ["X", "Y", "Z", ""] * len(rigid_markers)
            + ["X", "Y", "Z"] * len(markers))
    lines = [f"Format Version,1.21,Take Name,Take 2016-01-05 03.49.50 PM,Capture Frame Rate,{rate:.6f},"
             f"Export Frame Rate,{rate:.6f},Capture Start Time,2016-01-05 03.49.50.755 PM,Total Frames in Take,"
             f"{frames},Total Exported Frames,{frames},Rotation Type,Quaternion,Length Units,Meters,"
             "Coordinate Space,Global",
             "",
             ",".join(["", ""] + types),
             ",".join(["", ""] + names),
             ",".join(["", ""] + ['"CF5107FCB3ED11E565670A50E6808782"'] * len(types)),
             ",".join(["", ""] + parts),
             ",".join(["Frame", "Time"] + axes)]
    for k in range(frames):
        row = [str(k), f"{k / rate:.6f}", "0.000035", "0.000016", "-0.000030", "-1.000000",
               "0.060002", "0.019150", "0.076611", "0.000004"]
        for n in rigid_markers:
            row += _cells(np.nan_to_num(take[n][k]) + 5.0, 1e-3) + ["0.998795"]
        for n in markers:
            row += _cells(markers[n][k], 1e-3)
        lines.append(",".join(row))
    return lines


def _write(tmp_path, lines, name="take.csv", end="\r\n"):
    path = tmp_path / name
    path.write_bytes((end.join(lines) + end).encode())
    return path


@pytest.mark.parametrize("units", ["Millimeters", "Meters", "Centimeters"])
def test_units_give_the_same_metres(tmp_path, units):
    take = _take()
    markers = read_motive_csv(_write(tmp_path, motive_123(take, units=units)))
    expected = np.stack([take[n] for n in markers.names], axis=1) * 1e-3
    # Six decimals in the file's unit.
    np.testing.assert_allclose(markers.positions, expected, atol={"Millimeters": 5e-10, "Meters": 5e-7,
                                                                  "Centimeters": 5e-9}[units] + 1e-12)


def test_labeled_and_unlabeled_markers_are_read(tmp_path):
    take = _take()
    markers = read_markers(_write(tmp_path, motive_123(take, rate=240.0)))
    # The Rigid Body Marker columns (offset by 5 mm in the sample) are not read.
    assert markers.names == ("Hand:Marker1", "Hand:Marker2", "Hand:Marker3", "Unlabeled 1000")
    assert markers.rate == 240.0
    assert markers.n_frames == 30
    assert markers.index("Marker2") == 1
    np.testing.assert_allclose(markers.positions[:, 0], take["Hand:Marker1"] * 1e-3, atol=1e-9)


def test_empty_cells_are_missing(tmp_path):
    markers = read_motive_csv(_write(tmp_path, motive_123(_take())))
    stats = {g.name: g for g in markers.gaps()}
    assert list(stats["Hand:Marker2"].gap_lengths) == [4]
    assert stats["Unlabeled 1000"].leading == 5
    assert markers.missing.sum() == 9


def test_format_121(tmp_path):
    take = _take()
    markers = read_motive_csv(_write(tmp_path, motive_121(take, rate=100.0)))
    assert markers.names == ("Unlabeled:108", "Hand:Marker1", "Hand:Marker2", "Hand:Marker3")
    assert markers.rate == 100.0
    np.testing.assert_allclose(markers.positions[:, 1], take["Hand:Marker1"] * 1e-3, atol=5e-7)
    assert markers.missing[:, 0].sum() == 5


@pytest.mark.parametrize("end", ["\n", "\r\n"])
def test_line_endings(tmp_path, end):
    assert read_motive_csv(_write(tmp_path, motive_123(_take()), end=end)).n_frames == 30


def test_file_cut_at_a_line_boundary_is_refused(tmp_path):
    lines = motive_123(_take())
    with pytest.raises(HandcapError, match="Total Exported Frames is 30 but the file holds 25 data rows"):
        read_motive_csv(_write(tmp_path, lines[:-5]))


def test_file_cut_inside_a_line_is_refused(tmp_path):
    lines = motive_123(_take())
    path = tmp_path / "cut.csv"
    path.write_text("\n".join(lines)[:-40])
    with pytest.raises(HandcapError, match="has .* cells, expected|ends in the middle of a line"):
        read_motive_csv(path)
    path.write_text("\n".join(lines)[:-2])
    with pytest.raises(HandcapError, match="ends in the middle of a line"):
        read_motive_csv(path)


@pytest.mark.parametrize("row, match", [
    ("Name", "lacks its 'Name' header row"),
    ("Type", "lacks its 'Type' header row"),
    ("Frame", "lacks its 'Frame,Time' column header row"),
])
def test_missing_header_rows_are_refused(tmp_path, row, match):
    lines = [line for line in motive_123(_take()) if not line.startswith((f",{row},", f"{row},"))]
    with pytest.raises(HandcapError, match=match):
        read_motive_csv(_write(tmp_path, lines))


def test_missing_row_in_a_121_file_is_refused(tmp_path):
    lines = motive_121(_take())
    del lines[3]
    with pytest.raises(HandcapError, match="3 header rows above 'Frame'"):
        read_motive_csv(_write(tmp_path, lines))


def test_garbage_cell_is_refused(tmp_path):
    lines = motive_123(_take())
    cells = lines[12].split(",")
    cells[-2] = "1.2e"
    lines[12] = ",".join(cells)
    with pytest.raises(HandcapError, match=r"line 13, column .* \(Unlabeled 1000 Y\), holds '1.2e', not a number"):
        read_motive_csv(_write(tmp_path, lines))


def test_short_row_is_refused(tmp_path):
    lines = motive_123(_take())
    lines[9] = lines[9].rsplit(",", 3)[0]
    with pytest.raises(HandcapError, match="line 10 has 27 cells, the other data lines 30"):
        read_motive_csv(_write(tmp_path, lines))


@pytest.mark.parametrize("edit, match", [
    (("Length Units,Millimeters", "Length Units,Furlongs"), "unknown length unit 'Furlongs'"),
    (("Length Units,Millimeters,", ""), "no Length Units"),
    (("Format Version,1.23", "Format Version,1.1"), "format version '1.1' is not supported"),
    (("Export Frame Rate,120.000000", "Export Frame Rate,fast"), "Export Frame Rate must be a number"),
])
def test_bad_metadata_is_refused(tmp_path, edit, match):
    lines = motive_123(_take())
    lines[0] = lines[0].replace(*edit)
    with pytest.raises(HandcapError, match=match):
        read_motive_csv(_write(tmp_path, lines))


def test_rigid_bodies_only_is_refused(tmp_path):
    lines = [",".join(line.split(",")[:9]) for line in motive_123(_take())]
    lines[0] = motive_123(_take())[0]
    with pytest.raises(HandcapError, match=r"no Marker position columns \(found Rigid Body\)"):
        read_motive_csv(_write(tmp_path, lines))


def test_uci_table_is_not_a_motive_export(shared_data):
    with pytest.raises(HandcapError, match="not an OptiTrack Motive CSV export; read it with "
                                           "handcap.io.read_uci_postures"):
        read_markers(shared_data / "markers/uci_hand_postures/Postures.csv")


@pytest.mark.parametrize("content, match", [
    (b"", "empty file"),
    (b"a,b,c\n1,2,3\n", "not a marker CSV handcap reads: an OptiTrack Motive CSV export starts"),
    (b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR", "binary data"),
])
def test_files_that_are_not_motive_exports(tmp_path, content, match):
    path = tmp_path / "x.csv"
    path.write_bytes(content)
    with pytest.raises(HandcapError, match=match):
        read_markers(path)
