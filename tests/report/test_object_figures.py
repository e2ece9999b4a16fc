"""Object figures of the metrics against a synthetic grasp's truth: the tracked object's markers against the
true ones, and a mesh whose frame is not the motion's object frame said in a warning (its penetration means
little)."""

import pytest
import trimesh

from handcap.io import write_object_motion
from handcap.objects import track_rigid
from handcap.report import motion_metrics
from handcap.steps import metrics as metrics_step
from handcap.synth.objects import make_object
from handcap.synth.scene import SynthConfig, synthesize, write_capture


@pytest.fixture(scope="module")
def grasp(tmp_path_factory):
    folder = tmp_path_factory.mktemp("grasp")
    config = SynthConfig(motion="grasp", frames=130, rate=50.0, seed=4, subject_seed=7)
    capture = synthesize(config, progress=False)
    paths = write_capture(capture, folder)
    obj = make_object(config.object_kind, seed=config.seed)
    (folder / "object.ply").write_bytes(trimesh.Trimesh(obj.vertices, obj.faces, process=False).export(
        file_type="ply"))
    write_object_motion(capture.object_motion, folder / "true_object.npz")  # the mesh's own frame
    names = [n for n in capture.markers.names if n.startswith(f"{capture.object_motion.name}_")]
    write_object_motion(track_rigid(capture.markers, names, name="cylinder").motion, folder / "tracked.npz")
    return folder, paths["truth.npz"]


def test_the_tracked_object_against_the_truth(grasp):
    folder, truth = grasp
    figures = motion_metrics(truth, truth=truth, obj=folder / "tracked.npz")
    error, spread, frames = figures["object_error_mm"]
    assert error < 1.0 and frames == 130  # its markers where the truth has them, in every frame
    assert motion_metrics(truth, truth=truth, obj=folder / "true_object.npz")["object_error_mm"][0] < 1e-6


def test_a_mesh_in_another_frame_is_said(grasp):
    folder, truth = grasp
    aligned = metrics_step.metrics(truth, obj=folder / "true_object.npz", object_mesh=folder / "object.ply")
    assert not any("surface of" in w for w in aligned.warnings)
    learnt = metrics_step.metrics(truth, obj=folder / "tracked.npz", object_mesh=folder / "object.ply")
    said = [w for w in learnt.warnings if "surface of" in w]
    assert len(said) == 1 and "--canonical" in said[0], learnt.warnings


def test_a_mesh_in_millimetres_is_read_so_and_said(grasp, tmp_path):
    folder, truth = grasp
    mesh = trimesh.load(folder / "object.ply", force="mesh", process=False)
    mesh.vertices = mesh.vertices * 1000.0  # a CAD export in millimetres
    (tmp_path / "mm.ply").write_bytes(mesh.export(file_type="ply"))
    metres = metrics_step.metrics(truth, obj=folder / "true_object.npz", object_mesh=folder / "object.ply")
    millimetres = metrics_step.metrics(truth, obj=folder / "true_object.npz", object_mesh=tmp_path / "mm.ply")
    # To 0.1 um: the PLY file holds float32 vertices, and 1000 times larger ones round elsewhere.
    assert millimetres.result["penetration_mm"] == pytest.approx(metres.result["penetration_mm"], abs=1e-4)
    said = [w for w in millimetres.warnings if "read in mm" in w]
    assert len(said) == 1 and not any("surface of" in w for w in millimetres.warnings), millimetres.warnings


def test_a_damaged_mesh_is_one_line_and_exit_2(grasp, tmp_path, capsys):
    # A face that names a vertex the file does not have, or a vertex that is NaN: libigl, which measures the
    # penetration, would read memory outside the mesh (a crash, not an error), so the mesh is checked first.
    from handcap.cli import main

    folder, truth = grasp
    ply = (folder / "object.ply").read_bytes()
    mesh = trimesh.load(folder / "object.ply", force="mesh", process=False)
    faces = mesh.faces.copy()
    faces[5, 1] = len(mesh.vertices) + 7
    trimesh.Trimesh(mesh.vertices, faces, process=False).export(tmp_path / "faces.ply")
    vertices = mesh.vertices.copy()
    vertices[3] = float("nan")
    trimesh.Trimesh(vertices, mesh.faces, process=False).export(tmp_path / "nan.ply")
    for name, said in (("faces.ply", f"faces index vertices 0 to {len(mesh.vertices) + 7}"),
                       ("nan.ply", "1 of the mesh's")):
        before = (tmp_path / name).read_bytes()
        assert main(["metrics", str(truth), "--object", str(folder / "true_object.npz"), "--object-mesh",
                     str(tmp_path / name)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and name in err and said in err, err
        assert (tmp_path / name).read_bytes() == before  # the input untouched
    assert (folder / "object.ply").read_bytes() == ply
