"""Every reader, fed mutated files, either reads them or raises HandcapError: nothing else escapes (issue 14).

Each reader gets a small valid file of its format, written here, and hypothesis mutates its bytes: bytes
overwritten, truncation, garbage inserted, ranges deleted or repeated, numbers replaced by tokens that
readers trip on (``nan``, ``inf``, ``1e308``, ``-1``, text), lines deleted or repeated. The ``.npz``
readers also get structural mutations: entries removed, or replaced by arrays of other shapes and types.
The examples are derandomised (the same ones every run) and bounded so that the whole file runs in well
under a minute on two cores.
"""

from __future__ import annotations

import io
import re
import shutil
import struct
import tempfile
import zipfile
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from handcap import HandcapError, MarkerSequence
from handcap.core.cameras import Camera, CameraRig
from handcap.core.geometry import signed_distance
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.core.points import PointCloudSequence
from handcap.detect.sources import read_image
from handcap.hand.attachment import MarkerAttachment
from handcap.occlusion.model import OcclusionModel
from handcap.io import (
    read_hand_motion,
    read_markers,
    read_mesh,
    read_object_motion,
    read_points,
    read_rig,
    read_uci_postures,
    write_c3d,
    write_hand_motion,
    write_markers_npz,
    write_object_motion,
    write_points_npz,
    write_trc,
)
from handcap.io.camera_formats import write_cameras_caliscope, write_cameras_opencv
from handcap.io.cameras import write_cameras_toml
from handcap.layouts import load_layout
from handcap.multiview import Detections, read_detections, write_detections

EXAMPLES = 100  # per reader: about 25 s for all of them on a loaded two-core machine

TOKENS = ["", "nan", "inf", "-inf", "1e308", "-1", "0", "1e30", "abc", "\x00", "99999999999999999999", "-0",
          "1.5", "true", "[", "]", "\"", "=", "<", "/>", ",", "\t", "\n"]
_NUMBER = re.compile(rb"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


# -- valid seed files ---------------------------------------------------------------------------------------

def _markers(frames=12, count=4, seed=0) -> MarkerSequence:
    rng = np.random.default_rng(seed)
    positions = rng.normal(0.0, 0.05, (frames, count, 3)) + [0.1, 0.2, 1.0]
    positions[3, 1] = np.nan
    return MarkerSequence(positions, [f"hand:m{k}" for k in range(count)], 100.0,
                          rng.uniform(0, 1e-3, (frames, count)))


def _rig() -> CameraRig:
    cameras = []
    for k in range(3):
        angle = 2 * np.pi * k / 3
        cameras.append(Camera(f"cam_{k}", (640, 480), [[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]],
                              [0.01 * k, -0.001, 0.0, 0.0, 0.0], [0.0, angle, 0.0], [0.1 * k, 0.0, 2.0]))
    return CameraRig(cameras)


def _qca() -> bytes:
    camera = ('<camera active="1" serial="c{k}" viewrotation="0"><fov_video bottom="479" left="0" right="639" '
              'top="0"/><transform r11="1" r12="0" r13="0" r21="0" r22="1" r23="0" r31="0" r32="0" r33="1" '
              'x="{x}" y="0" z="2000"/><intrinsic centerPointU="20480" centerPointV="15360" focalLengthU="38400" '
              'focalLengthV="38400" radialDistortion1="-0.04" radialDistortion2="0.1" radialDistortion3="0" '
              'sensorMaxU="40896" sensorMaxV="30656" sensorMinU="0" sensorMinV="0" skew="0" '
              'tangentalDistortion1="0.0006" tangentalDistortion2="0.0007"/></camera>')
    cameras = "".join(camera.format(k=k, x=500 * k) for k in range(2))
    return f"<?xml version='1.0'?>\n<calibration><cameras>{cameras}</cameras></calibration>\n".encode()


def _tsv() -> bytes:
    m = _markers()
    names = "\t".join(m.names)
    lines = [f"NO_OF_FRAMES\t{m.n_frames}", "NO_OF_CAMERAS\t7", f"NO_OF_MARKERS\t{m.n_markers}", "FREQUENCY\t100",
             "DATA_INCLUDED\t3D", f"MARKER_NAMES\t{names}",
             "\t".join(["Frame", "Time"] + [f"{n} {a}" for n in m.names for a in "XYZ"])]
    for t in range(m.n_frames):
        values = ["" if np.isnan(v) else f"{1000 * v:.3f}" for v in m.positions[t].ravel()]
        lines.append("\t".join([str(t + 1), f"{t / 100:.5f}"] + values))
    return ("\n".join(lines) + "\n").encode()


def _motive() -> bytes:
    m = _markers()
    types = ["Marker"] * 3 * m.n_markers
    lines = [f"Format Version,1.23,Take Name,t,Capture Frame Rate,100.0,Export Frame Rate,100.0,"
             f"Total Exported Frames,{m.n_frames},Rotation Type,Quaternion,Length Units,Millimeters", "",
             ",".join(["", "Type"] + types), ",".join(["", "Name"] + [n for n in m.names for _ in range(3)]),
             ",".join(["", "ID"] + ["1"] * len(types)), ",".join(["", ""] + ["Position"] * len(types)),
             ",".join(["Frame", "Time (Seconds)"] + ["X", "Y", "Z"] * m.n_markers)]
    for t in range(m.n_frames):
        values = ["" if np.isnan(v) else f"{1000 * v:.4f}" for v in m.positions[t].ravel()]
        lines.append(",".join([str(t), f"{t / 100:.6f}"] + values))
    return ("\r\n".join(lines) + "\r\n").encode()


def _vicon() -> bytes:
    """A Vicon Nexus CSV export: a Devices section, then the Trajectories (missing samples empty)."""
    m = _markers()
    lines = ["", "", "Devices", "1000", ",,Plate - Force,,", "Frame,Sub Frame,Fx,Fy,Fz", ",,N,N,N"]
    lines += [f"{t + 1},{s},1.0,2.0,700.0" for t in range(2) for s in range(10)]
    lines += ["", "Trajectories", "100", ",".join(["", ""] + [c for n in m.names for c in (n, "", "")]),
              ",".join(["Frame", "Sub Frame"] + ["X", "Y", "Z"] * m.n_markers),
              ",".join(["", ""] + ["mm"] * 3 * m.n_markers)]
    for t in range(m.n_frames):
        lines.append(",".join([str(t + 1), "0"] + ["" if np.isnan(v) else f"{1000 * v:.5f}"
                                                   for v in m.positions[t].ravel()]))
    return ("\r\n".join(lines) + "\r\n").encode()


def _uci() -> bytes:
    """Rows of the UCI hand-postures table: class, user, 12 points (X, Y, Z mm), '?' for absent points."""
    rng = np.random.default_rng(2)
    header = ",".join(["Class", "User"] + [f"{a}{k}" for k in range(12) for a in "XYZ"])
    rows = []
    for r in range(8):
        present = 3 + r % 6
        cells = [f"{v:.8f}" for v in rng.normal(0, 60, 3 * present)] + ["?"] * (3 * (12 - present))
        rows.append(",".join([str(1 + r % 5), str(r % 3)] + cells))
    return ("\n".join([header] + rows) + "\n").encode()


def _detections() -> Detections:
    rng = np.random.default_rng(1)
    n = 30
    return Detections(("cam_0", "cam_1"), ("a", "b", "c"), rng.integers(0, 10, n), rng.integers(0, 2, n),
                      rng.integers(0, 3, n), rng.uniform(0, 640, (n, 2)), rng.uniform(0.5, 1, n), 100.0, 10)


def _written(writer, suffix: str) -> bytes:
    folder = Path(tempfile.mkdtemp(prefix="handcap-seed-"))
    try:
        path = folder / f"seed{suffix}"
        writer(path)
        return path.read_bytes()
    finally:
        shutil.rmtree(folder)


def _layout() -> bytes:
    from importlib.resources import files
    return files("handcap.layouts").joinpath("glove-13.toml").read_bytes()


def _image(suffix: str) -> bytes:
    """A small grey photograph (PNG, or JPEG with an EXIF orientation) as the detector's frames are read."""
    import cv2
    pixels = np.random.default_rng(0).integers(0, 255, (24, 32), dtype=np.uint8)
    code = cv2.imencode(suffix, pixels)[1].tobytes()
    if suffix != ".jpg":
        return code
    tiff = b"MM\x00\x2a" + struct.pack(">IH", 8, 1) + struct.pack(">HHIHH", 0x0112, 3, 1, 6, 0) + bytes(4)
    app1 = b"Exif\x00\x00" + tiff
    return code[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + code[2:]


# name: (seed bytes builder, file name, reader, kind of mutation)
def _mesh(suffix: str) -> bytes:
    """A small closed mesh (an icosphere) as an object's surface file: PLY (binary) or OBJ (text)."""
    import trimesh

    return trimesh.creation.icosphere(subdivisions=1, radius=0.03).export(file_type=suffix)


def _object_mesh(path):
    """The mesh as ``handcap metrics --object-mesh`` reads and measures it: read, then the penetration's signed
    distance (libigl, which reads wherever a bad face index points: a crash is what this looks for)."""
    mesh = read_mesh(path)
    return signed_distance(np.zeros((2, 3)), getattr(mesh, "vertices", np.zeros((0, 3))),
                           getattr(mesh, "faces", np.zeros((0, 3), int)))


READERS = {
    "png-image": (lambda: _image(".png"), "frame.png", read_image, "binary"),
    "jpeg-image": (lambda: _image(".jpg"), "frame.jpg", read_image, "binary"),
    "c3d": (lambda: _written(lambda p: write_c3d(_markers(), p), ".c3d"), "take.c3d", read_markers, "binary"),
    "trc": (lambda: _written(lambda p: write_trc(_markers(), p), ".trc"), "take.trc", read_markers, "text"),
    "qualisys-tsv": (_tsv, "take.tsv", read_markers, "text"),
    "motive-csv": (_motive, "take.csv", read_markers, "text"),
    "vicon-csv": (_vicon, "trial.csv", read_markers, "text"),
    "vicon-txt": (lambda: _vicon().replace(b",", b"\t"), "trial.txt", read_markers, "text"),
    "markers-npz": (lambda: _written(lambda p: write_markers_npz(_markers(), p), ".npz"), "take.npz",
                    read_markers, "npz"),
    "points-npz": (lambda: _written(lambda p: write_points_npz(PointCloudSequence.from_markers(_markers()), p),
                                    ".npz"), "points.npz", read_points, "npz"),
    "hand-motion-npz": (lambda: _written(lambda p: write_hand_motion(HandMotion(
        np.zeros(10), np.zeros((5, 3)), np.zeros((5, 45)), np.zeros((5, 3)), 100.0), p), ".npz"),
        "motion.npz", read_hand_motion, "npz"),
    "object-motion-npz": (lambda: _written(lambda p: write_object_motion(ObjectMotion(
        np.zeros((5, 3)), np.ones((5, 3)), 100.0, "box", ("a", "b", "c"), np.eye(3)), p), ".npz"),
        "object.npz", read_object_motion, "npz"),
    "detections-npz": (lambda: _written(lambda p: write_detections(_detections(), p), ".npz"), "det.npz",
                       read_detections, "npz"),
    "anipose-toml": (lambda: _written(lambda p: write_cameras_toml(_rig(), p), ".toml"), "rig.toml", read_rig,
                     "text"),
    "caliscope-toml": (lambda: _written(lambda p: write_cameras_caliscope(_rig(), p), ".toml"), "array.toml",
                       read_rig, "text"),
    "opencv-yaml": (lambda: _written(lambda p: write_cameras_opencv(_rig(), p), ".yml"), "rig.yml", read_rig,
                    "text"),
    "opencv-xml": (lambda: _written(lambda p: write_cameras_opencv(_rig(), p), ".xml"), "rig.xml", read_rig,
                   "text"),
    "qualisys-qca": (_qca, "rig.qca.txt", read_rig, "text"),
    "attachment-npz": (lambda: _written(lambda p: MarkerAttachment(
        ("a", "b", "c"), np.array([1, 2, 3]), np.full((3, 3), 1 / 3), np.full(3, 0.005), np.zeros(10)).save(p),
        ".npz"), "attachment.npz", MarkerAttachment.load, "npz"),
    "occlusion-model-npz": (lambda: files("handcap.occlusion").joinpath("weights", "glove-13.npz").read_bytes(),
                            "model.npz", OcclusionModel.load, "npz"),
    "layout-toml": (_layout, "layout.toml", load_layout, "text"),
    "uci-postures-csv": (_uci, "Postures.csv", read_uci_postures, "text"),
    "object-mesh-ply": (lambda: _mesh("ply"), "object.ply", _object_mesh, "binary"),
    "object-mesh-obj": (lambda: _mesh("obj").encode(), "object.obj", _object_mesh, "text"),
}


# -- mutations ----------------------------------------------------------------------------------------------

@st.composite
def byte_mutations(draw, seed: bytes, text: bool) -> bytes:
    """``seed`` with one to four random edits; text files also get token and line edits."""
    data = bytearray(seed)
    ops = ["overwrite", "truncate", "insert", "delete", "repeat"] + (["token", "token", "line"] if text else [])
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(ops))
        n = len(data)
        if n == 0:
            data += draw(st.binary(min_size=1, max_size=32))
            continue
        at = draw(st.integers(0, n - 1))
        if op == "overwrite":
            width = draw(st.integers(1, 8))
            data[at:at + width] = draw(st.binary(min_size=width, max_size=width))
        elif op == "truncate":
            del data[at:]
        elif op == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=32))
        elif op == "delete":
            del data[at:at + draw(st.integers(1, 64))]
        elif op == "repeat":
            width = draw(st.integers(1, 256))
            data[at:at] = data[at:at + width]
        elif op == "token":
            numbers = list(_NUMBER.finditer(bytes(data)))
            if numbers:
                found = numbers[draw(st.integers(0, len(numbers) - 1))]
                data[found.start():found.end()] = draw(st.sampled_from(TOKENS)).encode()
        else:
            lines = bytes(data).splitlines(keepends=True)
            k = draw(st.integers(0, len(lines) - 1))
            lines[k:k + 1] = [] if draw(st.booleans()) else [lines[k], lines[k]]
            data = bytearray(b"".join(lines))
    return bytes(data)


_ODD_VALUES = [
    np.array(np.nan), np.array(np.inf), np.array(-1.0), np.array(0), np.array(1e300), np.array("text"),
    np.array([]), np.zeros((0, 3)), np.zeros((2, 2)), np.zeros((3, 0, 3)), np.full((4, 2, 3), np.nan),
    np.array(["a", "a", "a"]), np.arange(5), np.array([True, False]), np.zeros((2, 3, 4, 5)),
    np.array([1e30, -1e30, 1e30]), np.array(10 ** 12), np.array(-5), np.array(["2020-01-01"], dtype="datetime64[D]"),
    np.zeros(3, dtype=np.complex128), np.array(b"bytes"),
]


@st.composite
def npz_mutations(draw, seed: bytes) -> bytes:
    """An archive of ``seed``'s entries with some removed or replaced by odd arrays; or a byte mutation."""
    if draw(st.booleans()):
        return draw(byte_mutations(seed, False))
    with np.load(io.BytesIO(seed), allow_pickle=False) as data:
        arrays = {key: data[key] for key in data.files}
    keys = sorted(arrays)
    for _ in range(draw(st.integers(1, 3))):
        key = draw(st.sampled_from(keys + ["kind", "warnings", "extra"]))
        if draw(st.integers(0, 4)) == 0:
            arrays.pop(key, None)
        else:
            arrays[key] = draw(st.sampled_from(_ODD_VALUES))
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        for key, value in arrays.items():
            entry = io.BytesIO()
            np.lib.format.write_array(entry, np.asanyarray(value), allow_pickle=False)
            zf.writestr(f"{key}.npy", entry.getvalue())
    return buffer.getvalue()


# -- the test -----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def seeds():
    return {name: build() for name, (build, *_rest) in READERS.items()}


@pytest.fixture(scope="module")
def folder():
    path = Path(tempfile.mkdtemp(prefix="handcap-fuzz-"))
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.mark.parametrize("name", sorted(READERS))
def test_seed_files_are_read(seeds, folder, name):
    """The unmutated seeds are valid, so the mutations start from a file the reader accepts."""
    _, file_name, reader, _ = READERS[name]
    path = folder / f"seed-{file_name}"
    path.write_bytes(seeds[name])
    reader(path)


@pytest.mark.parametrize("name", sorted(READERS))
@settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                 HealthCheck.data_too_large])
@given(data=st.data())
def test_mutated_files_raise_only_handcap_error(seeds, folder, name, data):
    _, file_name, reader, kind = READERS[name]
    seed = seeds[name]
    mutated = data.draw(npz_mutations(seed) if kind == "npz" else byte_mutations(seed, kind == "text"))
    path = folder / file_name
    path.write_bytes(mutated)
    try:
        reader(path)
    except HandcapError as err:
        assert "\n" not in str(err), str(err)
