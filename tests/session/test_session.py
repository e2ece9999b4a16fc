"""handcap process: runs every stage, resumes after a kill without redoing finished stages (manifests and
their times), reruns only what an edited setting touches, and refuses a bad session file in one line."""

import json
import re

import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.session import load_session, process
from handcap.session.example import new_session
from handcap.steps import metrics as metrics_step


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sess") / "lab"
    new_session(folder, takes=2, frames=260)
    return folder


def _finished(folder):
    return {p.name: json.loads(p.read_text())["finished"] + str(p.stat().st_mtime_ns)
            for p in sorted(folder.glob("results/*/*.manifest.json"))}


def test_process_resume_and_rerun(made, monkeypatch, capsys):
    session = load_session(made / "session.toml")
    real = metrics_step.metrics

    def killed(motion, **kw):
        if "take2" in str(motion):
            raise KeyboardInterrupt  # the run is killed during take2's metrics
        return real(motion, **kw)

    monkeypatch.setattr(metrics_step, "metrics", killed)
    with pytest.raises(KeyboardInterrupt):
        process(session, workers=1)
    monkeypatch.setattr(metrics_step, "metrics", real)
    before = {p: json.loads(p.read_text()) for p in made.glob("results/*/*.manifest.json")}
    assert {(p.parent.name, p.name) for p in before} == {
        ("take1", f"{s}.manifest.json") for s in ("calibrate", "solve", "metrics", "report")} | {
        ("take2", "calibrate.manifest.json"), ("take2", "solve.manifest.json")}
    stamps = {p: p.stat().st_mtime_ns for p in before}
    runs = process(session, workers=1)
    status = {(r.take, r.stage): r.status for r in runs}
    assert status == {("take1", "calibrate"): "skipped", ("take1", "solve"): "skipped",
                      ("take1", "metrics"): "skipped", ("take1", "report"): "skipped",
                      ("take2", "calibrate"): "skipped", ("take2", "solve"): "skipped",
                      ("take2", "metrics"): "done", ("take2", "report"): "done",
                      ("hands1", "fit"): "done", ("hands1", "metrics"): "done", ("hands1", "report"): "done"}
    assert all(p.stat().st_mtime_ns == stamps[p] for p in before)  # finished stages untouched
    manifest = json.loads((made / "results/take2/metrics.manifest.json").read_text())
    assert manifest["settings"] == {"leave_one_out": False} and set(manifest["inputs"]) == {"motion", "markers",
                                                                                            "truth"}
    assert manifest["figures"]["joint_error_mm"][0] < 10
    keypoints = json.loads((made / "results/hands1/metrics.manifest.json").read_text())
    assert keypoints["figures"]["joint_error_mm"][0] < 4  # 2 mm of keypoint noise
    assert (made / "results/take2/report.html").stat().st_size > 1_000_000
    # an edited setting reruns its stage and what depends on it, not calibrate
    text = (made / "session.toml").read_text().replace("filter_cutoff = 8.0", "filter_cutoff = 5.0")
    (made / "session.toml").write_text(text)
    runs = process(load_session(made / "session.toml"), workers=1)
    assert {(r.take, r.stage) for r in runs if r.status == "done"} == {
        (t, s) for t in ("take1", "take2") for s in ("solve", "metrics", "report")}  # hands1 has its own fit
    capsys.readouterr()
    assert main(["process", str(made / "session.toml"), "--dry-run"]) == 0
    assert "planned" not in capsys.readouterr().out


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('stages = ["calibrate"', 'stages = ["align", "calibrate"'), "unknown stage 'align'"),
    (lambda t: re.sub(r"filter_cutoff = [0-9.]+", 'filter_cutoff = "fast"', t),
     "stages.solve.filter_cutoff must be a number"),
    (lambda t: t.replace("method = \"lm\"", "speed = 3"), "stages.solve.speed is not a setting of solve"),
    (lambda t: t.replace("take1/markers.c3d", "take9/markers.c3d"), "takes[0].markers: no such file"),
    (lambda t: t.replace('kind = "markers"', 'kind = "video"', 1), "takes[0].kind 'video'"),
    (lambda t: t.replace('keypoints = "hands1/keypoints.c3d"', 'markers = "take1/markers.c3d"'),
     "takes[2].markers is not an input of a keypoints take"),
    (lambda t: t.replace('name = "take2"', 'name = "take1"'), "unique name"),
    (lambda t: t + "\n[extra]\nx = 1\n", "unknown table 'extra'"),
    (lambda t: t.replace("[session]", "[session"), "not TOML"),
])
def test_bad_session_files(made, tmp_path, capsys, edit, message):
    text = (made / "session.toml").read_text()
    bad = made / "bad.toml"
    bad.write_text(edit(text))
    try:
        assert main(["process", str(bad)]) == 2
        err = capsys.readouterr().err
        assert message in err and str(bad) in err and len(err.strip().splitlines()) == 1, err
    finally:
        bad.unlink()
    with pytest.raises(HandcapError, match="no such session file"):
        load_session(tmp_path / "none.toml")
