"""handcap process: runs every stage, resumes after a kill without redoing finished stages (manifests and
their times), reruns only what an edited setting touches, and refuses a bad session file in one line."""

import json
import re

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.session import load_session, process
from handcap.session.example import new_session
from handcap.steps import metrics as metrics_step



@pytest.fixture(scope="module")
def made(tmp_path_factory, gl_ok):
    folder = tmp_path_factory.mktemp("sess") / "lab"
    new_session(folder, takes=2, frames=260, image_frames=2, progress=False)
    return folder


MARKER_STAGES = ("calibrate", "solve", "metrics", "report")
HELD_STAGES = ("calibrate", "solve", "object", "metrics", "report")  # the marker takes track the cylinder they hold
IMAGE_STAGES = ("detect", "triangulate", "clean", *MARKER_STAGES)
CALIBRATED = tuple(s for s in IMAGE_STAGES if s != "calibrate")  # by its calibration take's attachment


def test_process_resume_and_rerun(made, monkeypatch, capsys):
    session = load_session(made / "session.toml")
    assert {t.kind for t in session.takes} == {"images", "markers", "keypoints"}
    real = metrics_step.metrics

    victim = []

    def killed(motion, **kw):
        if victim[-1] in str(motion):
            raise KeyboardInterrupt  # the run is killed during this take's metrics
        return real(motion, **kw)

    monkeypatch.setattr(metrics_step, "metrics", killed)
    for take in ("take2", "images1"):  # killed twice, once in a take of markers and once in one of images
        victim.append(take)
        with pytest.raises(KeyboardInterrupt):
            process(session, workers=1)
    monkeypatch.setattr(metrics_step, "metrics", real)
    before = {p: json.loads(p.read_text()) for p in made.glob("results/*/*.manifest.json")}
    finished = {(p.parent.name, p.name.split(".")[0]) for p in before}
    assert finished == ({(t, s) for t in ("take1", "take2") for s in HELD_STAGES}  # take2 ended in the second run
                        | {("hands1", s) for s in ("fit", "metrics", "report")}
                        | {("calib-images", s) for s in IMAGE_STAGES}
                        | {("images1", s) for s in CALIBRATED[:-2]})
    stamps = {p: p.stat().st_mtime_ns for p in before}
    runs = process(session, workers=1)
    status = {(r.take, r.stage): r.status for r in runs}
    assert status == {**{key: "skipped" for key in finished},
                      ("images1", "metrics"): "done", ("images1", "report"): "done"}
    assert all(p.stat().st_mtime_ns == stamps[p] for p in before)  # finished stages untouched
    manifest = json.loads((made / "results/take2/metrics.manifest.json").read_text())
    assert manifest["settings"] == {"leave_one_out": False} and set(manifest["inputs"]) == {"motion", "markers",
                                                                                            "truth", "object"}
    assert manifest["figures"]["joint_error_mm"][0] < 10
    # the cylinder tracked from its markers (its shape learnt from the take) puts them where the truth has them
    assert manifest["figures"]["object_error_mm"][0] < 1 and manifest["figures"]["object_error_mm"][2] == 260
    keypoints = json.loads((made / "results/hands1/metrics.manifest.json").read_text())
    assert keypoints["figures"]["joint_error_mm"][0] < 4  # 2 mm of keypoint noise
    images = json.loads((made / "results/images1/metrics.manifest.json").read_text())
    assert images["figures"]["mre_mm"][0] < 1 and images["figures"]["joint_error_mm"][0] < 15
    with np.load(made / "results/images1/detections.npz") as detections:  # rig and template: views name squares too
        assert len(detections["block_from_views"]) == len(detections["block_text"])
    calibrate = json.loads((made / "results/calib-images/calibrate.manifest.json").read_text())
    assert calibrate["input_paths"]["calibration"].endswith("calib-images/cleaned.c3d")  # on its own corners
    solve = json.loads((made / "results/images1/solve.manifest.json").read_text())
    assert solve["input_paths"]["attachment"].endswith("calib-images/attachment.npz")  # calibrated once
    assert (made / "results/take2/report.html").stat().st_size > 1_000_000
    # an edited setting reruns its stage and what depends on it, not calibrate
    text = (made / "session.toml").read_text().replace("filter_cutoff = 8.0", "filter_cutoff = 5.0")
    (made / "session.toml").write_text(text)
    runs = process(load_session(made / "session.toml"), workers=1)
    assert {(r.take, r.stage) for r in runs if r.status == "done"} == {
        (t, s) for t in ("take1", "take2") for s in ("solve", "metrics", "report")}  # the image takes filter none
    # two cameras -> three: the image takes triangulate again and what follows, but do not detect again
    text = text.replace("min_views = 2", "min_views = 3")
    (made / "session.toml").write_text(text)
    runs = process(load_session(made / "session.toml"), workers=1)
    assert {(r.take, r.stage) for r in runs if r.status == "done"} == {
        *(("calib-images", s) for s in IMAGE_STAGES[1:]), *(("images1", s) for s in CALIBRATED[1:])}
    capsys.readouterr()
    assert main(["process", str(made / "session.toml"), "--dry-run"]) == 0
    assert "planned" not in capsys.readouterr().out


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('stages = ["detect"', 'stages = ["align", "detect"'), "unknown stage 'align'"),
    (lambda t: re.sub(r"filter_cutoff = [0-9.]+", 'filter_cutoff = "fast"', t),
     "stages.solve.filter_cutoff must be a number"),
    (lambda t: t.replace("method = \"lm\"", "speed = 3"), "stages.solve.speed is not a setting of solve"),
    (lambda t: t.replace("take1/markers.c3d", "take9/markers.c3d"), "takes[0].markers: no such file"),
    (lambda t: t.replace('kind = "markers"', 'kind = "video"', 1), "takes[0].kind 'video'"),
    (lambda t: t.replace('keypoints = "hands1/keypoints.c3d"', 'markers = "take1/markers.c3d"'),
     "takes[2].markers is not an input of a keypoints take"),
    (lambda t: t.replace('name = "take2"', 'name = "take1"'), "unique name"),
    (lambda t: t + "\n[extra]\nx = 1\n", "unknown table 'extra'"),
    (lambda t: t.replace('images = "images1/images"', 'images = "images1/pictures"'),
     "takes[4].images: no such folder"),
    (lambda t: t.replace('calibration_take = "calib-images"', 'calibration_take = "hands1"'),
     "takes[4].calibration_take 'hands1': name another markers or images take"),
    (lambda t: t.replace("filter_cutoff = 0 ", "filter_cutoff = false "),
     "takes[3].settings.solve.filter_cutoff must be"),
    (lambda t: t.replace("[takes.settings.solve]", "[takes.settings.align]", 1),
     "takes[3].settings.align: unknown stage"),
    (lambda t: t.replace("[session]", "[session"), "not TOML"),
    (lambda t: t.replace('layout = "dense-patches"', 'layout = "mine.toml"', 1),
     ".layout 'mine.toml': neither a shipped layout"),
    (lambda t: t.replace('layout = "glove-13"', 'layout = "glove-13"\ndrop_misfit_mm = "yes"', 1),
     "stages.calibrate.drop_misfit_mm must be a number"),
    (lambda t: re.sub(r"min_views = (\d)", 'min_views = \\1\nsync = "cam_1 12"', t, count=1),
     'stages.triangulate.sync is "auto" or offsets; an offset is CAMERA=FRAMES'),
    (lambda t: t.replace("rate = 4.0", 'rate = 4.0\nsync = "cam_1"', 1),
     'stages.detect.sync is "auto" or offsets; an offset is CAMERA=FRAMES'),
    (lambda t: t.replace('response = "linear"', 'response = "gamma"', 1),
     "stages.detect.response is one of auto, linear, srgb, got 'gamma'"),
    (lambda t: t.replace('name = "cylinder"', 'name = "cylinder"\narticulated = "cube2x2"', 1),
     "takes[0].settings.object has both markers and articulated"),
    (lambda t: t.replace('name = "cylinder"', 'name = "cylinder"\ncanonical = "none.npz"', 1),
     "takes[0].settings.object.canonical: no such file"),
    (lambda t: t.replace('markers = "cylinder_*"', 'articulated = "cube3x3"', 1),
     "takes[0].settings.object.articulated 'cube3x3': neither a shipped articulated object"),
    (lambda t: t.replace('truth = "hands1/truth.npz"', 'truth = "hands1/truth.npz"\n[takes.settings.object]\n'
                                                       'markers = "mug_*"'),
     "takes[2].settings.object: a keypoints take has no object markers to track"),
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


def test_a_folder_hash_sees_every_file_its_name_and_bytes(tmp_path):
    from handcap.session.runner import file_hash

    (tmp_path / "cam_0").mkdir()
    (tmp_path / "cam_0" / "0000.png").write_bytes(b"a")
    (tmp_path / "cam_0" / "0001.png").write_bytes(b"b")
    first = file_hash(tmp_path)
    assert file_hash(tmp_path) == first
    (tmp_path / "cam_0" / "0001.png").write_bytes(b"c")
    changed = file_hash(tmp_path)
    (tmp_path / "cam_0" / "0001.png").rename(tmp_path / "cam_0" / "0002.png")
    assert len({first, changed, file_hash(tmp_path)}) == 3


def test_a_calibration_takes_own_attachment_solves_the_takes_naming_it(tmp_path):
    from handcap.synth.scene import SynthConfig, synthesize, write_capture

    capture = synthesize(SynthConfig(motion="grasp", frames=260, seed=3), progress=False)
    write_capture(capture, tmp_path / "a")
    capture.attachment.save(tmp_path / "a" / "attachment.npz")
    (tmp_path / "session.toml").write_text(
        '[session]\nstages = ["solve"]\n\n'
        '[[takes]]\nname = "a"\nmarkers = "a/markers.c3d"\nattachment = "a/attachment.npz"\n\n'
        '[[takes]]\nname = "b"\nmarkers = "a/markers.c3d"\ncalibration_take = "a"\n')
    runs = process(load_session(tmp_path / "session.toml"), workers=1)
    assert [(r.take, r.stage, r.status) for r in runs] == [("a", "solve", "done"), ("b", "solve", "done")]
    manifest = json.loads((tmp_path / "results/b/solve.manifest.json").read_text())
    assert manifest["input_paths"]["attachment"] == str(tmp_path / "a" / "attachment.npz")


def test_a_layout_file_is_found_beside_the_session_file(made, tmp_path):
    """A take's own layout (handcap layout new writes one) is a file relative to the session file, wherever the
    command runs from; its calibration settings reach the stage."""
    text = (made / "session.toml").read_text()
    assert main(["layout", "new", "--like", "dense-patches", "--no-positions", "--out", str(made / "mine.toml")]) == 0
    edited = made / "mine-session.toml"
    edited.write_text(text.replace('layout = "dense-patches"', 'layout = "mine.toml"', 1)
                      .replace('layout = "glove-13"', 'layout = "glove-13"\ndrop_misfit_mm = 3.0', 1))
    try:
        session = load_session(edited)
        assert str(made / "mine.toml") in {t.layout for t in session.takes}
        assert session.settings["calibrate"]["drop_misfit_mm"] == 3.0
    finally:
        edited.unlink()
        (made / "mine.toml").unlink()


def test_an_edited_layout_file_reruns_the_stages_that_read_it(made, tmp_path):
    """A layout file is an input of calibrate: its manifest holds the file's hash, so editing the file reruns it."""
    assert main(["layout", "new", "--like", "glove-13", "--out", str(made / "glove.toml")]) == 0
    session_file = made / "glove-session.toml"
    session_file.write_text('[session]\nname = "g"\nresults = "glove-results"\nstages = ["calibrate"]\n'
                            '[stages.calibrate]\nlayout = "glove.toml"\n'
                            '[[takes]]\nname = "take1"\nkind = "markers"\nmarkers = "take1/markers.c3d"\n'
                            'calibration = "calibration/markers.c3d"\n')
    try:
        states = []
        for edit in (False, False, True):
            if edit:
                (made / "glove.toml").write_text((made / "glove.toml").read_text() + "\n# edited\n")
            runs = process(load_session(session_file), workers=1)
            states.append([r.status for r in runs])
        assert states == [["done"], ["skipped"], ["done"]]
    finally:
        session_file.unlink()
        (made / "glove.toml").unlink()


def test_detect_names_unread_squares_on_the_clocks_triangulate_is_given(made):
    from handcap.session.runner import stage_settings

    text = (made / "session.toml").read_text()
    synced = re.sub(r"min_views = (\d)", 'min_views = \\1\nsync = "auto"\nmax_offset_s = 1.5', text, count=1)
    path = made / "synced.toml"
    for edit, want in ((synced, {"sync": "auto", "max_offset_s": 1.5}),
                       (synced.replace("rate = 4.0", 'rate = 4.0\nsync = "cam_1=2"'), {"sync": "cam_1=2"}),
                       (synced.replace("rate = 4.0", "rate = 4.0\nviews = false"), {}),
                       (text, {})):
        path.write_text(edit)
        try:
            session = load_session(path)
        finally:
            path.unlink()
        take = next(t for t in session.takes if t.kind == "images")
        got = stage_settings(session, take, "detect")
        assert {k: got[k] for k in ("sync", "max_offset_s") if k in got} == want


def test_objects_tracked_in_camera_and_cube_takes(made, tmp_path):
    """The object stage of a take of 2D detections reads its cleaned markers; a 2x2x2 cube's description tracks
    its moves, which the metrics report (with the hand's penetration of the cubies); an object whose markers the
    take lacks stops the run in one line naming the take and the stage."""
    from handcap.synth.scene import SynthConfig, synthesize, write_capture

    cube = synthesize(SynthConfig(motion="turn-cube", moves="R U'", rate=60.0, seed=3, subject_seed=7),
                      progress=False)
    write_capture(cube, tmp_path / "cube")
    take1 = made / "take1"
    text = ('[session]\nstages = ["triangulate", "clean", "calibrate", "solve", "object", "fit", "metrics"]\n'
            f'[stages.calibrate]\nlayout = "glove-13"\n[stages.object]\nmarkers = "cylinder_*"\n'
            f'[[takes]]\nname = "seen"\nkind = "detections"\ndetections = "{take1}/detections.npz"\n'
            f'cameras = "{take1}/cameras.toml"\ncalibration = "{made}/calibration/markers.c3d"\n'
            f'truth = "{take1}/truth.npz"\n'
            f'[[takes]]\nname = "cube"\nmarkers = "cube/markers.c3d"\ncalibration = "{made}/calibration/markers.c3d"\n'
            f'truth = "cube/truth.npz"\n[takes.settings.object]\narticulated = "cube2x2"\n'
            f'[[takes]]\nname = "hands"\nkind = "keypoints"\nkeypoints = "{made}/hands1/keypoints.c3d"\n')
    (tmp_path / "session.toml").write_text(text)
    runs = process(load_session(tmp_path / "session.toml"), workers=1)
    assert [(r.take, r.stage) for r in runs if r.stage in ("object", "metrics")] == [
        ("seen", "object"), ("seen", "metrics"), ("cube", "object"), ("cube", "metrics"), ("hands", "metrics")]
    seen = json.loads((tmp_path / "results/seen/object.manifest.json").read_text())
    assert seen["input_paths"]["markers"].endswith("seen/cleaned.c3d")
    figures = json.loads((tmp_path / "results/seen/metrics.json").read_text())
    assert figures["object_error_mm"][0] < 1
    figures = json.loads((tmp_path / "results/cube/metrics.json").read_text())
    assert figures["cube_moves"] == "R U'" == str(np.load(tmp_path / "cube/truth.npz")["cube_moves"])
    assert "penetration_mm" in figures and "object_error_mm" not in figures
    (tmp_path / "session.toml").write_text(text.replace('"cylinder_*"', '"mug_*"'))
    with pytest.raises(HandcapError, match=r"^take seen, stage object: no marker matches 'mug_\*'"):
        process(load_session(tmp_path / "session.toml"), workers=1)


def test_each_warning_is_said_once_per_take(made, monkeypatch, capsys):
    """A warning a take's later stages carry on (the calibration's, stored in the attachment, read by solve and
    metrics) is printed once, with the stage that first said it; the library's own issue of it is not repeated."""
    import warnings

    from handcap.core.errors import HandcapWarning
    from handcap.session import commands
    from handcap.session.runner import StageRun

    def fake(session, **kw):
        warnings.warn("calibration MRE of 1 marker(s) above 5 mm: index_middle (8.1 mm)", HandcapWarning, stacklevel=2)
        said = ("calibration MRE of 1 marker(s) above 5 mm: index_middle (8.1 mm)",)
        return [StageRun(take, stage, "done", 1.0, said, f"{take}/{stage}")
                for take, stage in (("take1", "calibrate"), ("take1", "solve"), ("take2", "solve"))]

    monkeypatch.setattr(commands, "process", fake)
    assert main(["process", str(made / "session.toml")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["handcap process: warning: take1 calibrate: calibration MRE of 1 marker(s) above 5 mm: "
                   "index_middle (8.1 mm)",
                   "handcap process: warning: take2 solve: calibration MRE of 1 marker(s) above 5 mm: "
                   "index_middle (8.1 mm)"]


def test_an_object_mesh_needs_the_markers_in_its_frame(made, tmp_path):
    """With the object's mesh, the metrics' penetration needs the motion in the mesh's frame: tracked with the
    markers' positions in that frame (``canonical``) it is; with the frame learnt from the take a warning says
    the penetration means little."""
    import trimesh

    from handcap.synth.objects import make_object

    truth = np.load(made / "take1/truth.npz")
    np.savez(tmp_path / "cylinder.npz", canonical=truth["object_canonical"])
    obj = make_object("cylinder", seed=1)  # take1's seed
    (tmp_path / "cylinder.ply").write_bytes(trimesh.Trimesh(obj.vertices, obj.faces, process=False).export(
        file_type="ply"))
    text = ('[session]\nstages = ["calibrate", "solve", "object", "metrics"]\n[stages.calibrate]\nlayout = "glove-13"\n'
            f'[[takes]]\nname = "held"\nmarkers = "{made}/take1/markers.c3d"\n'
            f'calibration = "{made}/calibration/markers.c3d"\nobject_mesh = "cylinder.ply"\n'
            '[takes.settings.object]\nmarkers = "cylinder_*"\nname = "cylinder"\n')
    said = {}
    for canonical in (True, False):
        (tmp_path / "session.toml").write_text(text + ('canonical = "cylinder.npz"\n' if canonical else ""))
        runs = process(load_session(tmp_path / "session.toml"), workers=1)
        said[canonical] = [w for r in runs if r.stage == "metrics" for w in r.warnings if "surface of" in w]
    assert said[True] == [] and len(said[False]) == 1
    manifest = json.loads((tmp_path / "results/held/object.manifest.json").read_text())
    assert "canonical" not in manifest["inputs"]  # the last run learnt the frame
