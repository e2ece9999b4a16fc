"""Vicon Nexus CSV exports (the Trajectories section).

No Nexus export ships with ../shared/data, so the tests write samples in the layout that public readers of real
exports document: sections of a name line, a rate line, a name row (``Subject:Marker`` above each X column), a
``Frame,Sub Frame,X,Y,Z`` row and a units row, ended by a blank line; two blank lines before the first section
(Nexus 2.16); a ``Devices`` section of analog channels (1000 Hz, sub frames) before the trajectories and a
``Model Outputs`` section after them; unlabelled trajectories named ``*12``; empty cells for missing samples.
"""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.io import read_markers, read_vicon_csv

NAMES = ["Sub:RH_TOP", "Sub:RH_LEFT", "Sub:RIDX3", "*12"]


def _take(frames=25, seed=0):
    """Trajectories (T, 4, 3) in millimetres, NaN where Nexus leaves the cells empty."""
    rng = np.random.default_rng(seed)
    base = np.array([[120.5, -33.2, 870.1], [95.0, -10.4, 860.3], [160.2, 20.9, 845.7], [400.0, 300.0, 20.0]])
    take = base + np.cumsum(rng.normal(0, 0.8, (frames, 4, 3)), axis=0)
    take[5:9, 2] = np.nan
    take[:3, 3] = np.nan
    return take


def _cells(values, scale=1.0):
    return ["" if np.isnan(v) else f"{v * scale:.5f}" for v in values]


def trajectories(take, *, rate=100, first=1, unit="mm", scale=1.0, names=NAMES, derivatives=False, frames=None):
    """Lines of a Trajectories section (name line to its last data row)."""
    per = 9 if derivatives else 3
    axes = ["X", "Y", "Z", "X'", "Y'", "Z'", "X''", "Y''", "Z''"][:per]
    units = [unit] * 3 + ([f"{unit}/s"] * 3 + [f"{unit}/s^2"] * 3 if derivatives else [])
    lines = ["Trajectories", str(rate), ",".join(["", ""] + [c for n in names for c in [n] + [""] * (per - 1)]),
             ",".join(["Frame", "Sub Frame"] + axes * len(names)), ",".join(["", ""] + units * len(names))]
    frames = range(first, first + len(take)) if frames is None else frames
    for number, row in zip(frames, take):
        cells = []
        for marker in row:
            cells += _cells(marker, scale) + (["1.0"] * 3 + ["-2.0"] * 3 if derivatives else [])
        lines.append(",".join([str(number), "0"] + cells))
    return lines


def devices(frames=3):
    """A Devices section: a force plate's analog channels at 1000 Hz, ten sub frames per frame."""
    lines = ["Devices", "1000", ",,Imported AMTI OR6 Series Force Plate #1 - Force,,,Imported AMTI OR6 Series "
             "Force Plate #1 - Moment,,", "Frame,Sub Frame,Fx,Fy,Fz,Mx,My,Mz", ",,N,N,N,N.mm,N.mm,N.mm"]
    lines += [f"{f},{s},1.5,-2.0,700.0,10.0,20.0,-3.0" for f in range(1, frames + 1) for s in range(10)]
    return lines


def model_outputs(frames=3):
    lines = ["Model Outputs", "100", ",,Sub:RWristAngles,,", "Frame,Sub Frame,X,Y,Z", ",,deg,deg,deg"]
    return lines + [f"{f},0,10.0,-4.5,2.0" for f in range(1, frames + 1)]


def _write(tmp_path, *sections, name="trial.csv", lead=("", ""), end="\r\n"):
    lines = list(lead)
    for k, section in enumerate(sections):
        lines += ([""] if k else []) + section
    path = tmp_path / name
    path.write_bytes((end.join(lines) + end).encode())
    return path


def test_trajectories_read_in_metres_with_missing_samples(tmp_path):
    take = _take()
    markers = read_markers(_write(tmp_path, trajectories(take, rate=240, first=101)))
    assert markers.names == tuple(NAMES) and markers.rate == 240.0 and markers.n_frames == 25
    np.testing.assert_allclose(markers.positions, take * 1e-3, atol=5e-9, equal_nan=True)
    assert markers.missing[5:9, 2].all() and markers.missing[:3, 3].all() and markers.missing.sum() == 7
    assert markers.index("RIDX3") == 2 and not markers.warnings


def test_other_sections_before_and_after_are_skipped(tmp_path):
    take = _take()
    path = _write(tmp_path, devices(), trajectories(take, rate=100), model_outputs(), lead=())
    markers = read_vicon_csv(path)
    assert markers.names == tuple(NAMES) and markers.rate == 100.0
    np.testing.assert_allclose(markers.positions, take * 1e-3, atol=5e-9, equal_nan=True)


def test_velocity_and_acceleration_columns_are_skipped(tmp_path):
    take = _take()
    markers = read_vicon_csv(_write(tmp_path, trajectories(take, derivatives=True)))
    np.testing.assert_allclose(markers.positions, take * 1e-3, atol=5e-9, equal_nan=True)


@pytest.mark.parametrize(("unit", "scale"), [("mm", 1.0), ("m", 1e-3), ("cm", 0.1)])
def test_the_units_row_gives_the_unit(tmp_path, unit, scale):
    take = _take()
    markers = read_vicon_csv(_write(tmp_path, trajectories(take, unit=unit, scale=scale), end="\n"))
    np.testing.assert_allclose(markers.positions, take * 1e-3, atol=5e-9 / scale, equal_nan=True)


def test_a_file_in_mm_that_says_m_asks_for_the_unit_or_takes_the_one_given(tmp_path):
    # Markers 951 m apart: in mm or in cm they would fit a capture, so the user is asked.
    take = _take()
    with pytest.raises(HandcapError, match="951 m apart.*--units mm[|]cm"):
        read_vicon_csv(_write(tmp_path, trajectories(take, unit="m")))
    # The unit given overrides the file's.
    markers = read_vicon_csv(_write(tmp_path, trajectories(take, unit="m"), name="b.csv"), units="mm")
    np.testing.assert_allclose(markers.positions, take * 1e-3, atol=5e-9, equal_nan=True)


def test_skipped_frame_numbers_become_missing_frames_with_a_warning(tmp_path):
    take = _take(frames=10)
    numbers = [1, 2, 3, 4, 7, 8, 9, 10, 11, 12]
    with pytest.warns(UserWarning, match="2 frame number"):
        markers = read_vicon_csv(_write(tmp_path, trajectories(take, frames=numbers)))
    assert markers.n_frames == 12 and markers.missing[4:6].all()
    np.testing.assert_allclose(markers.positions[[n - 1 for n in numbers]], take * 1e-3, atol=5e-9, equal_nan=True)
    assert any("have no row" in w for w in markers.warnings)


def test_a_tab_separated_txt_export_reads_the_same(tmp_path):
    take = _take()
    sections = devices() + [""] + trajectories(take, first=7) + [""] + model_outputs()
    lines = [line.replace(",", "\t") for line in sections]
    path = tmp_path / "trial.txt"
    path.write_text("\n".join(lines) + "\n")
    markers = read_markers(path)
    assert markers.names == tuple(NAMES)
    np.testing.assert_allclose(markers.positions, take * 1e-3, atol=5e-9, equal_nan=True)
    other = tmp_path / "notes.txt"
    other.write_text("a note\n")
    with pytest.raises(HandcapError, match="not a Vicon Nexus CSV export"):
        read_markers(other)


def test_a_motive_csv_is_still_read_as_motive(tmp_path):
    path = tmp_path / "take.csv"
    path.write_text("Format Version,1.23,Export Frame Rate,120.0,Total Exported Frames,2,Length Units,Millimeters\n\n"
                    ",Type,Marker,Marker,Marker\n,Name,Hand:M1,Hand:M1,Hand:M1\n,ID,1,1,1\n,,Position,Position,Position"
                    "\nFrame,Time (Seconds),X,Y,Z\n0,0.0,10.0,20.0,30.0\n1,0.008333,11.0,21.0,31.0\n")
    markers = read_markers(path)
    assert markers.names == ("Hand:M1",) and markers.rate == 120.0
    np.testing.assert_allclose(markers.positions[1, 0], [0.011, 0.021, 0.031])


def _bad(tmp_path, lines, name="bad.csv"):
    path = tmp_path / name
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return path


@pytest.mark.parametrize(("edit", "message"), [
    (lambda lines: [lines[0].replace("Trajectories", "Devices")] + lines[1:], "without a Trajectories section"),
    (lambda lines: lines[:3], "stops within its header rows"),
    (lambda lines: lines[:5], "holds no frames"),
    (lambda lines: lines[:1] + ["fast"] + lines[2:], "frame rate in Hz"),
    (lambda lines: lines[:1] + ["0"] + lines[2:], "frame rate is 0"),
    (lambda lines: lines[:3] + [lines[3].replace("Sub Frame", "Time")] + lines[4:], "Frame and Sub Frame"),
    (lambda lines: lines[:3] + [lines[3][::-1].replace("Z", "W", 1)[::-1]] + lines[4:], "lacks some of its X, Y, Z"),
    (lambda lines: lines[:2] + [lines[2].replace("RH_LEFT", "RH_TOP")] + lines[3:], "names marker 'Sub:RH_TOP' twice"),
    (lambda lines: lines[:2] + [",,,,,"] + lines[3:], "names no marker"),
    (lambda lines: lines[:4] + [lines[4].replace("mm", "in", 1)] + lines[5:], "units"),
    (lambda lines: lines[:4] + [lines[4].replace("mm", "furlong")] + lines[5:], "unknown length unit"),
    (lambda lines: lines[:6] + [lines[6].replace("2,0,", "1,0,", 1)] + lines[7:], "must increase"),
    (lambda lines: lines[:6] + [lines[6].replace("2,0,", "2.5,0,", 1)] + lines[7:], "no whole number"),
    (lambda lines: lines[:-1] + ["25,0," + ",".join(["1.0"] * 12), "9999,0," + ",".join(["1.0"] * 12)],
     "more frame numbers have no row"),
    (lambda lines: lines[:7] + [lines[7].replace(".", "x", 1)] + lines[8:], "not a number"),
    (lambda lines: lines[:7] + [lines[7] + ",5.0,6.0"] + lines[8:], "cells"),
])
def test_bad_files_are_refused_in_one_line(tmp_path, edit, message):
    lines = edit(trajectories(_take()))
    with pytest.raises(HandcapError, match=message) as err:
        read_markers(_bad(tmp_path, lines))
    assert "\n" not in str(err.value)


def test_a_cut_file_and_a_csv_of_neither_kind_are_refused(tmp_path):
    path = tmp_path / "cut.csv"
    path.write_bytes(("\r\n".join(trajectories(_take())))[:-7].encode())
    with pytest.raises(HandcapError, match="truncated"):
        read_markers(path)
    with pytest.raises(HandcapError, match="Format Version.*Trajectories"):
        read_markers(_bad(tmp_path, ["a,b,c", "1,2,3"]))


def test_convert_reads_a_nexus_export_and_never_touches_it(tmp_path, capsys):
    take = _take()
    source = _write(tmp_path, devices(), trajectories(take), model_outputs())
    before = source.read_bytes()
    assert main(["convert", str(source), str(tmp_path / "trial.trc")]) == 0
    assert "25 frames, 4 markers at 100 Hz" in capsys.readouterr().out
    np.testing.assert_allclose(read_markers(tmp_path / "trial.trc").positions, take * 1e-3, atol=1e-8, equal_nan=True)
    bad = _bad(tmp_path, trajectories(take)[:3])
    assert main(["convert", str(bad), str(tmp_path / "bad.trc")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "header rows" in err and not (tmp_path / "bad.trc").exists()
    assert source.read_bytes() == before
