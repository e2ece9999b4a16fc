"""C3D reading and writing, against the real files in ../shared/data/markers."""

import struct

import ezc3d
import numpy as np
import pytest

from handcap import HandcapError, MarkerSequence
from handcap.io import read_c3d, read_markers, write_c3d, write_markers

KTK = "markers/kineticstoolkit"
SUITE = "markers/kineticstoolkit/c3d_test_suite"

# (file, frames, rate Hz, points): counts from the headers, checked against ezc3d.
REAL_C3D = [
    ("markers/ezc3d/Vicon.c3d", 580, 100.0, 51),
    ("markers/ezc3d/Qualisys.c3d", 340, 200.0, 55),
    (f"{KTK}/kinematics_racing_probing_acromion_R.c3d", 140, 69.5, 41),
    (f"{KTK}/kinematics_racing_probing_radial_styloid_R.c3d", 140, 69.5, 41),
    (f"{KTK}/kinematics_racing_probing_ulnar_styloid_R.c3d", 140, 69.5, 41),
    (f"{KTK}/kinematics_racing_propulsion.c3d", 700, 69.992615, 41),
    (f"{KTK}/kinematics_racing_static.c3d", 700, 69.9, 41),
    ("markers/auto_marker_label/S09_KneeltoRun02.c3d", 1479, 240.0, 75),
    ("markers/auto_marker_label/KneeltoProne01.c3d", 1745, 240.0, 62),
    (f"{SUITE}/Sample01/Eb015pi.c3d", 450, 50.0, 26),
    (f"{SUITE}/Sample01/Eb015pr.c3d", 450, 50.0, 26),
    *[(f"{SUITE}/Sample02/{order}_{kind}.c3d", 89, 50.0, 36)
      for order in ("dec", "pc", "sgi") for kind in ("int", "real")],
]


@pytest.mark.parametrize("name, frames, rate, points", REAL_C3D)
def test_real_file_sizes(shared_data, name, frames, rate, points):
    markers = read_c3d(shared_data / name)
    assert markers.positions.shape == (frames, points, 3)
    assert markers.rate == pytest.approx(rate, rel=1e-6)
    assert markers.residuals.shape == (frames, points)
    assert len(set(markers.names)) == points


@pytest.mark.parametrize("name", [row[0] for row in REAL_C3D])
def test_real_files_are_body_sized_in_metres(shared_data, name):
    # Metre files (kineticstoolkit) and millimetre files (the rest, some with
    # an empty POINT:UNITS) must both come out as a human in a lab: O(1) m.
    positions = read_c3d(shared_data / name).positions
    extent = np.nanmax(np.abs(positions))
    assert 0.5 < extent < 5.0


def test_metre_and_millimetre_files_agree_in_scale(shared_data):
    metres = read_c3d(shared_data / KTK / "kinematics_racing_static.c3d")
    millimetres = read_c3d(shared_data / "markers/ezc3d/Vicon.c3d")
    spread = [np.nanmax(np.nanstd(m.positions, axis=(0, 1))) for m in (metres, millimetres)]
    assert 0.05 < spread[0] < 1.0 and 0.05 < spread[1] < 1.0


def test_empty_units_mean_millimetres(shared_data):
    path = shared_data / "markers/auto_marker_label/KneeltoProne01.c3d"
    raw = ezc3d.c3d(str(path))
    assert raw["parameters"]["POINT"]["UNITS"]["value"] == []
    np.testing.assert_allclose(read_c3d(path).positions, raw["data"]["points"][:3].T * 1e-3)


def test_vicon_labels_keep_the_subject_prefix(shared_data):
    markers = read_c3d(shared_data / "markers/ezc3d/Vicon.c3d")
    box = [n for n in markers.names if n.startswith("boite:")]
    assert len(box) == 8
    assert markers.names[0] == "boite:gauche_ext"
    assert markers.index("gauche_ext") == 0


def test_unlabeled_trajectories_keep_their_names(shared_data):
    markers = read_c3d(shared_data / "markers/auto_marker_label/S09_KneeltoRun02.c3d")
    assert markers.names == tuple(f"*{i}" for i in range(75))


def test_only_the_first_labels_name_the_points(shared_data):
    # Sample01 holds 48 labels for 26 points.
    params = ezc3d.c3d(str(shared_data / SUITE / "Sample01/Eb015pr.c3d"))["parameters"]["POINT"]
    labels = params["LABELS"]["value"]
    assert len(labels) == 48
    assert read_c3d(shared_data / SUITE / "Sample01/Eb015pr.c3d").names == tuple(labels[:26])


@pytest.mark.parametrize("integer, real, step_mm", [
    ("Sample01/Eb015pi.c3d", "Sample01/Eb015pr.c3d", 0.0833334),
    ("Sample02/pc_int.c3d", "Sample02/pc_real.c3d", 0.2811819),
    ("Sample02/dec_int.c3d", "Sample02/dec_real.c3d", 0.2811819),
    ("Sample02/sgi_int.c3d", "Sample02/sgi_real.c3d", 0.2811819),
])
def test_integer_and_float_storage_agree(shared_data, integer, real, step_mm):
    a, b = read_c3d(shared_data / SUITE / integer), read_c3d(shared_data / SUITE / real)
    assert a.names == b.names
    np.testing.assert_array_equal(a.missing, b.missing)
    # Integer storage is quantised to one POINT:SCALE step (the writers truncate).
    np.testing.assert_allclose(a.positions, b.positions, atol=step_mm * 1e-3 + 1e-9)


@pytest.mark.parametrize("order", ["dec", "sgi"])
@pytest.mark.parametrize("kind", ["int", "real"])
def test_byte_orders_agree(shared_data, order, kind):
    # DEC floats and big-endian SGI files (which ezc3d refuses; handcap swaps
    # them) must give what the Intel copy of the same take gives: exactly for
    # floats, to one POINT:SCALE step (0.28 mm) for the integer exports.
    pc = read_c3d(shared_data / SUITE / f"Sample02/pc_{kind}.c3d")
    other = read_c3d(shared_data / SUITE / f"Sample02/{order}_{kind}.c3d")
    assert other.names == pc.names
    np.testing.assert_array_equal(other.missing, pc.missing)
    np.testing.assert_allclose(other.positions, pc.positions, atol=2.8119e-4 if kind == "int" else 1e-12)


def test_missing_samples_follow_negative_residuals(shared_data):
    path = shared_data / "markers/ezc3d/Vicon.c3d"
    raw = ezc3d.c3d(str(path))
    negative = raw["data"]["meta_points"]["residuals"][0].T < 0
    markers = read_c3d(path)
    np.testing.assert_array_equal(markers.missing, negative)
    assert 0.005 < markers.missing.mean() < 0.02
    assert np.isnan(markers.residuals[markers.missing]).all()
    assert (markers.residuals[~markers.missing] >= 0).all()


def test_nan_coordinates_are_missing(shared_data):
    # kineticstoolkit stores NaN with residual 0; some probe markers are never seen.
    markers = read_c3d(shared_data / KTK / "kinematics_racing_static.c3d")
    assert markers.gap_summary()["never_seen"] == [f"Probe{i}" for i in range(1, 7)]


def test_residuals_are_in_metres(shared_data):
    # Eb015pr stores residuals in steps of |POINT:SCALE| = 1/12 mm.
    markers = read_c3d(shared_data / SUITE / "Sample01/Eb015pr.c3d")
    residuals = markers.residuals[~markers.missing]
    assert 0 < np.max(residuals) < 0.01
    np.testing.assert_allclose(residuals / (1e-3 / 12), np.round(residuals / (1e-3 / 12)), atol=1e-3)


def test_optotrak_file_is_shorter_than_its_header(shared_data):
    # Its header and POINT:FRAMES promise 1149 frames; the file holds 29.
    path = shared_data / "markers/ezc3d/Optotrak.c3d"
    with pytest.raises(HandcapError, match=r"truncated C3D file .*1149 frames.*only 29 complete.*partial=True"):
        read_c3d(path)
    markers = read_c3d(path, partial=True)
    assert markers.positions.shape == (29, 54, 3)
    assert markers.rate == 30.0
    assert markers.gap_summary()["never_seen"] == ["Marker_52", "Marker_53"]


# -- hand-made files ---------------------------------------------------------------------

def _ezc3d_file(path, points_mm, residuals, labels, rate=100.0, units="mm"):
    """A C3D written by ezc3d directly, bypassing handcap's writer."""
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = list(labels)
    if units is not None:
        c3d.add_parameter("POINT", "UNITS", units)
    c3d.add_parameter("POINT", "SCALE", -0.01)
    data = np.ones((4,) + points_mm.shape[1:])
    data[:3] = points_mm
    c3d["data"]["points"] = data
    c3d["data"]["meta_points"] = {"residuals": residuals}
    c3d.write(str(path))
    return path


def test_exact_origin_with_zero_residual_is_missing(tmp_path):
    points = np.full((3, 3, 2), 100.0)
    points[:, 0, 1] = 0.0          # (0, 0, 0), residual 0: a writer's "missing"
    points[:, 1, 1] = 0.0          # (0, 0, 0), residual 0.5 mm: measured there
    residuals = np.zeros((1, 3, 2))
    residuals[0, 1, 1] = 0.5
    markers = read_c3d(_ezc3d_file(tmp_path / "zeros.c3d", points, residuals, ["a", "b", "c"]))
    np.testing.assert_array_equal(markers.missing, [[False, False, False], [True, False, False]])
    np.testing.assert_allclose(markers.positions[1, 1], 0.0)


@pytest.mark.parametrize("units, scale", [("mm", 1e-3), ("cm", 1e-2), ("m", 1.0), ("", 1e-3), (None, 1e-3)])
def test_point_units_are_honoured(tmp_path, units, scale):
    points = np.arange(1, 7, dtype=float).reshape(3, 2, 1)
    markers = read_c3d(_ezc3d_file(tmp_path / "u.c3d", points, np.zeros((1, 2, 1)), ["a", "b"], units=units))
    np.testing.assert_allclose(markers.positions[0], points[:, :, 0].T * scale, rtol=1e-6)


def test_unknown_units_are_refused(tmp_path):
    path = _ezc3d_file(tmp_path / "u.c3d", np.ones((3, 1, 1)), np.zeros((1, 1, 1)), ["a"], units="furlong")
    with pytest.raises(HandcapError, match="unknown length unit 'furlong'"):
        read_c3d(path)


def _random_markers(seed, frames, count, name_length=12, residuals=True):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(-2.0, 2.0, size=(frames, count, 3))
    positions[rng.random((frames, count)) < 0.1] = np.nan
    names = [f"Subject{m % 3}:patch{m // 25:02d}_corner{m % 25:02d}_".ljust(name_length, "x") for m in range(count)]
    names[-1] = "L" * 255 if name_length > 40 else names[-1]       # the longest label C3D holds
    res = rng.uniform(0.0, 1.0e-3, size=(frames, count)) if residuals else None
    return MarkerSequence(positions, names, 120.0, res)


def test_round_trip_600_markers_with_long_names(tmp_path):
    markers = _random_markers(3, 40, 600, name_length=80)
    path = tmp_path / "dense.c3d"
    write_c3d(markers, path)
    point = ezc3d.c3d(str(path))["parameters"]["POINT"]
    assert [len(point[k]["value"]) for k in ("LABELS", "LABELS2", "LABELS3")] == [255, 255, 90]
    back = read_c3d(path)
    assert back.names == markers.names
    assert back.rate == markers.rate
    np.testing.assert_array_equal(back.missing, markers.missing)
    # float32 millimetres: about 1e-7 relative.
    np.testing.assert_allclose(back.positions, markers.positions, atol=1e-6)
    # Residuals are kept to the POINT:SCALE step, 0.01 mm.
    np.testing.assert_allclose(back.residuals, markers.residuals, atol=0.5e-5 + 1e-9)


def test_round_trip_of_a_real_file(shared_data, tmp_path):
    original = read_c3d(shared_data / "markers/ezc3d/Vicon.c3d")
    write_markers(original, tmp_path / "copy.c3d")
    back = read_markers(tmp_path / "copy.c3d")
    assert back.names == original.names and back.rate == original.rate
    np.testing.assert_allclose(back.positions, original.positions, atol=1e-7)
    np.testing.assert_allclose(back.residuals, original.residuals, atol=1e-8)


def test_large_residuals_get_a_coarser_step(tmp_path):
    markers = _random_markers(4, 5, 3)
    markers = MarkerSequence(markers.positions, markers.names, markers.rate,
                             np.where(markers.missing, np.nan, 0.02))     # 20 mm
    write_c3d(markers, tmp_path / "r.c3d")
    np.testing.assert_allclose(read_c3d(tmp_path / "r.c3d").residuals, markers.residuals, atol=1e-4)


def test_upper_case_extension_is_written(tmp_path):
    markers = _random_markers(5, 4, 2, residuals=False)
    write_markers(markers, tmp_path / "UP.C3D")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["UP.C3D"]
    np.testing.assert_allclose(read_markers(tmp_path / "UP.C3D").positions, markers.positions, atol=1e-6)


@pytest.mark.parametrize("names, match", [
    (["a" * 256, "b"], "longer than the 255 bytes"),
    (["a ", "b"], "trailing space"),
])
def test_names_c3d_cannot_store_are_refused(tmp_path, names, match):
    markers = MarkerSequence(np.zeros((2, 2, 3)), names, 100.0)
    with pytest.raises(HandcapError, match=match):
        write_c3d(markers, tmp_path / "bad.c3d")
    assert list(tmp_path.iterdir()) == []


def test_empty_sequence_is_not_written(tmp_path):
    with pytest.raises(HandcapError, match="nothing to write"):
        write_c3d(MarkerSequence(np.zeros((0, 2, 3)), ["a", "b"], 100.0), tmp_path / "e.c3d")


# -- broken files --------------------------------------------------------------------------

@pytest.fixture
def vicon_bytes(shared_data):
    return (shared_data / "markers/ezc3d/Vicon.c3d").read_bytes()


def _parameter_offsets(data: bytes, group: str, name: str):
    """File offsets of (name length byte, offset word, type byte, value bytes) of a parameter."""
    start = (data[0] - 1) * 512
    pos, groups, found = start + 4, {}, {}
    while True:
        length, gid = struct.unpack_from("bb", data, pos)
        if length == 0:
            break
        label = data[pos + 2:pos + 2 + abs(length)].decode()
        word = pos + 2 + abs(length)
        (offset,) = struct.unpack_from("<H", data, word)
        if gid < 0:
            groups[-gid] = label
        else:
            found[(gid, label)] = (pos, word, word + 2, word + 4 + data[word + 3])
        if offset == 0:
            break
        pos = word + offset
    gid = next(k for k, v in groups.items() if v == group)
    return found[(gid, name)]


@pytest.mark.parametrize("cut, match", [
    (0, "empty|shorter than a C3D header"),
    (100, "truncated C3D file .*shorter than its header"),
    (3000, "truncated C3D file .*ends inside its parameter section"),
    (14000, "truncated C3D file .*ends inside its parameter section"),
    (20000, r"truncated C3D file .*only 1 complete"),
    (200000, r"truncated C3D file .*580 frames.*only 48 complete"),
    (2250815, r"truncated C3D file .*only 579 complete"),
])
def test_truncated_c3d_is_refused(tmp_path, vicon_bytes, cut, match):
    path = tmp_path / "cut.c3d"
    path.write_bytes(vicon_bytes[:cut])
    with pytest.raises(HandcapError, match=match):
        read_c3d(path)


def test_partial_keeps_the_complete_frames(tmp_path, shared_data, vicon_bytes):
    path = tmp_path / "cut.c3d"
    path.write_bytes(vicon_bytes[:200000])
    whole = read_c3d(shared_data / "markers/ezc3d/Vicon.c3d")
    part = read_c3d(path, partial=True)
    assert part.n_frames == 48
    np.testing.assert_array_equal(part.positions, whole.positions[:48])


def _corrupt(data, edits):
    data = bytearray(data)
    for at, value in edits:
        data[at] = value
    return bytes(data)


@pytest.mark.parametrize("edit, match", [
    ("type", "parameter 'LABELS' has type 7"),
    ("offset", "does not end where the next one begins"),
    ("group", "group id 0"),
    ("used", "truncated C3D file"),
    ("frames", r"inconsistent C3D file \(its header holds frames 1 to 580, POINT:FRAMES says 16964"),
    ("fewer frames", r"inconsistent C3D file \(.*POINT:FRAMES says 324 frames"),
    ("signature", "not a C3D file"),
    ("processor", "unknown processor type"),
    ("blocks", "data start block 29 lies inside the header or parameter section"),
])
def test_corrupted_parameter_section_is_refused(tmp_path, vicon_bytes, edit, match):
    length_at, word_at, type_at, value_at = _parameter_offsets(vicon_bytes, "POINT", "LABELS")
    used_at = _parameter_offsets(vicon_bytes, "POINT", "USED")[3]
    frames_at = _parameter_offsets(vicon_bytes, "POINT", "FRAMES")[3]
    param_start = (vicon_bytes[0] - 1) * 512
    edits = {
        "type": [(type_at, 7)],
        "offset": [(word_at, vicon_bytes[word_at] ^ 0x10)],
        "group": [(length_at + 1, 0)],
        "used": [(used_at + 1, 0x40)],          # POINT:USED 51 -> 16435
        "frames": [(frames_at + 1, 0x42)],      # POINT:FRAMES 580 -> 16964
        "fewer frames": [(frames_at + 1, 0x01)],  # POINT:FRAMES 580 -> 324
        "signature": [(1, 0x51)],
        "processor": [(param_start + 3, 99)],
        "blocks": [(param_start + 2, 255)],
    }[edit]
    path = tmp_path / "bad.c3d"
    path.write_bytes(_corrupt(vicon_bytes, edits))
    with pytest.raises(HandcapError, match=match):
        read_c3d(path)


def test_garbage_coordinates_are_refused(tmp_path, vicon_bytes):
    # A float of 1e30 in the first coordinate of the data section.
    start = (struct.unpack_from("<H", vicon_bytes, 16)[0] - 1) * 512
    data = bytearray(vicon_bytes)
    struct.pack_into("<f", data, start, 1e30)
    path = tmp_path / "garbage.c3d"
    path.write_bytes(bytes(data))
    with pytest.raises(HandcapError, match="corrupt C3D data"):
        read_c3d(path)


@pytest.mark.parametrize("content, match", [
    (b"", "empty|shorter than a C3D header"),
    (b"Frame,Time,X,Y,Z\n" * 100, "not a C3D file"),
    (bytes(2048), "not a C3D file"),
])
def test_files_that_are_not_c3d_are_refused(tmp_path, content, match):
    path = tmp_path / "not.c3d"
    path.write_bytes(content)
    with pytest.raises(HandcapError, match=match):
        read_markers(path)


def test_ezc3d_write_failure_leaves_nothing(tmp_path, monkeypatch):
    def fail(self, path, **options):
        open(path, "wb").write(b"half a file")
        raise RuntimeError("disk full\nsecond line")
    monkeypatch.setattr(ezc3d.c3d, "write", fail)
    (tmp_path / "old.c3d").write_bytes(b"old")
    with pytest.raises(HandcapError, match="could not write the C3D file \\(disk full second line\\)"):
        write_c3d(_random_markers(7, 3, 2), tmp_path / "old.c3d")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.c3d"]
    assert (tmp_path / "old.c3d").read_bytes() == b"old"


def test_long_and_many_warnings_are_written_whole_and_read_back(tmp_path):
    # A C3D string is at most 255 bytes and a parameter holds at most 255 of them; ezc3d wrote longer ones without
    # a word and the file could not be read again (a jerk-spike warning of 300 characters on a synthetic take).
    take = MarkerSequence(np.random.default_rng(0).normal(0, 0.1, (10, 3, 3)), ["a", "b", "c"], 100.0)
    long = "marker jerk spikes " + "é, ünd " * 60 + "end"  # 440 characters, more bytes in UTF-8
    texts = ("short", long, "x" * 254 + "\\y", "z" * 255, "ends in a backslash\\")
    write_c3d(take.with_warnings(*texts), tmp_path / "long.c3d")
    assert read_c3d(tmp_path / "long.c3d").warnings == texts
    # Read by another reader, every string is within the format's bounds.
    values = ezc3d.c3d(str(tmp_path / "long.c3d"))["parameters"]["HANDCAP"]["WARNINGS"]["value"]
    assert all(len(v.encode()) <= 255 for v in values) and len(values) == 1 + 3 + 2 + 1 + 2
    many = tuple(f"warning {k}" for k in range(300))
    write_c3d(take.with_warnings(*many), tmp_path / "many.c3d")
    back = read_c3d(tmp_path / "many.c3d").warnings
    assert back[:254] == many[:254] and back[-1] == "46 more warning(s) left out: a C3D file holds 255 lines"
