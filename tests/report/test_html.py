"""The HTML report: self-contained (no network), every section present, and in headless Chromium (when
installed; .ci/run installs Debian's) it loads with no script error and its 3D view draws the skeleton."""

import re
import shutil
import subprocess

import numpy as np
import pytest

from handcap.cli import main
from handcap.synth.scene import SynthConfig, synthesize, write_capture

pytest.importorskip("plotly", reason="the report needs the extra 'report' (plotly)")


def _take(folder, seed):
    capture = synthesize(SynthConfig(motion="grasp", frames=260, rate=100.0, seed=seed, cameras=6), progress=False)
    write_capture(capture, folder)
    capture.attachment.save(folder / "attachment.npz")
    assert main(["solve", str(folder / "markers.c3d"), "--attachment", str(folder / "attachment.npz"),
                 "--out", str(folder / "motion.npz")]) == 0
    return capture


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    root = tmp_path_factory.mktemp("session")
    for k in (1, 2):
        (root / f"take{k}").mkdir()
        _take(root / f"take{k}", k)
    return root


def test_take_report_is_self_contained_and_complete(session, tmp_path, capsys):
    out = tmp_path / "take1.html"
    assert main(["report", str(session / "take1"), "--out", str(out)]) == 0
    page = out.read_text()
    assert not re.search(r"<script[^>]+src=", page) and not re.search(r"<link[^>]+href=['\"]?http", page)
    assert page.count("Plotly.newPlot") >= 4  # 3D view, residuals, gaps, joint angles
    for heading in ("3D view", "Marker residuals", "Gaps", "Joint angles", "Quality", "Warnings", "Settings"):
        assert heading in page, heading
    assert "motion.npz" in page and "truth.npz" in page and "scene.toml" in page
    assert "joint error (mm)" in page  # the figures, computed against the synthetic truth
    # beside the published ones: this take's MSNR in the row of DexterCap's 9.31 (Table 2)
    row = re.search(r"<tr><td>MSNR \(dB\)</td><td>([0-9.]+)</td><td>9\.31 ± 0\.22</td>", page)
    assert row and "Against the published figures" in page and "ARCTIC (Vicon)" in page


def test_published_rows_hold_this_takes_figures():
    from handcap.report.metrics import PAPER_COLUMNS, metrics_table, paper_rows

    figures = {"msnr_db": 24.5678, "jerk_m_s3": [8.1, 4.3], "diversity": 0.94, "frames": 120}
    rows = paper_rows(figures)
    assert [r[0] for r in rows] == ["MSNR (dB)", "jerk (m/s^3)", "diversity"]
    assert rows[0][:3] == ("MSNR (dB)", "24.568", "9.31 ± 0.22") and rows[1][1] == "8.100 ± 4.300"
    assert all(len(r) == 2 + len(PAPER_COLUMNS) for r in rows)
    assert "MSNR (dB)              24.568" in metrics_table(figures)


def test_session_report_links_every_take(session, tmp_path):
    out = tmp_path / "session.html"
    assert main(["report", str(session), "--out", str(out)]) == 0
    index = out.read_text()
    assert "session-take1.html" in index and "session-take2.html" in index
    assert (tmp_path / "session-take2.html").stat().st_size > 1_000_000  # plotly.js is inside


def test_bad_report_inputs(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    for argv, message in ((["report", str(tmp_path / "empty"), "--out", str(tmp_path / "r.html")], "no hand motion"),
                          (["report", str(tmp_path / "empty"), "--out", str(tmp_path / "r.pdf")], "an .html file"),
                          (["report", str(tmp_path / "none"), "--out", str(tmp_path / "r.html")], "no hand motion")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "r.html").exists()


def _chromium():
    return next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)


def _shoot(browser, page, png):
    run = subprocess.run([browser, "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                          "--hide-scrollbars", "--window-size=1280,1400", "--virtual-time-budget=10000",
                          "--enable-logging=stderr", "--v=0", f"--screenshot={png}", page.as_uri()],
                         capture_output=True, text=True, timeout=180)
    console = [line for line in run.stderr.splitlines() if ":CONSOLE" in line]
    return console


def test_report_in_headless_chromium(session, tmp_path):
    import matplotlib.image

    browser = _chromium()
    if browser is None:
        pytest.skip("no Chromium (apt-get install chromium; .ci/run installs it)")
    out = tmp_path / "take.html"
    assert main(["report", str(session / "take1"), "--out", str(out)]) == 0
    console = _shoot(browser, out, tmp_path / "take.png")
    errors = [line for line in console if re.search(r"Uncaught|Error|not defined|Failed", line)]
    assert errors == [], errors
    blank = tmp_path / "blank.html"
    blank.write_text("<!doctype html><html><body></body></html>")
    _shoot(browser, blank, tmp_path / "blank.png")
    shot = matplotlib.image.imread(tmp_path / "take.png")[..., :3]
    empty = matplotlib.image.imread(tmp_path / "blank.png")[..., :3]
    red = (np.abs(shot - np.array([214, 39, 40]) / 255).max(axis=-1) < 0.12).sum()  # the skeleton's colour
    assert red > 150 and (np.abs(empty - np.array([214, 39, 40]) / 255).max(axis=-1) < 0.12).sum() == 0
    assert shot.std() > 5 * max(empty.std(), 1e-3)


def test_the_3d_views_frames_hold_the_solved_skeleton_and_markers(session):
    """The view's frames are written as plain dicts, unchecked by plotly: plotly must still accept the figure, and
    each frame must show that frame's joints and markers (mm, to 0.01)."""
    import plotly.graph_objects as go

    from handcap.hand.anatomy import PARENTS
    from handcap.report.html import VIEW_FRAMES, view_figure
    from handcap.report.take import read_take

    take = read_take(session / "take1")
    view = view_figure(take)
    go.Figure(view)  # raises on anything plotly does not know
    n = take.motion.n_frames
    step = -(-n // VIEW_FRAMES)
    assert [f["name"] for f in view["frames"]] == [str(t) for t in range(0, n, step)]
    for frame in view["frames"][::7]:
        t = int(frame["name"])
        skeleton, markers = frame["data"]
        joints = take.motion.joints[t] * 1000
        child = next(j for j, p in enumerate(PARENTS) if p >= 0)  # the first bone: parent, child, break
        assert np.allclose([skeleton[a][:2] for a in "xyz"], joints[[PARENTS[child], child]].T, atol=0.006)
        assert np.isnan(skeleton["x"][2])
        assert np.allclose(np.stack([markers[a] for a in "xyz"], axis=1), take.markers.positions[t] * 1000,
                           atol=0.006, equal_nan=True)
