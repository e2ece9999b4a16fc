"""handcap's own .npz marker files and the dispatcher by extension."""

import zipfile

import numpy as np
import pytest

from handcap import HandcapError, MarkerSequence
from handcap.io import read_markers, read_markers_npz, write_markers, write_markers_npz


def _markers(seed=0, residuals=True):
    rng = np.random.default_rng(seed)
    positions = rng.normal(0.0, 0.3, size=(25, 6, 3))
    positions[rng.random((25, 6)) < 0.2] = np.nan
    res = rng.uniform(0, 1e-3, size=(25, 6)) if residuals else None
    return MarkerSequence(positions, [f"glove:m{i}" for i in range(6)], 90.0, res)


@pytest.mark.parametrize("residuals", [True, False])
def test_round_trip_is_exact(tmp_path, residuals):
    markers = _markers(residuals=residuals)
    write_markers(markers, tmp_path / "m.npz")
    back = read_markers(tmp_path / "m.npz")
    assert back.names == markers.names and back.rate == markers.rate
    np.testing.assert_array_equal(back.positions, markers.positions)
    if residuals:
        np.testing.assert_array_equal(back.residuals, markers.residuals)
    else:
        assert back.residuals is None


def test_file_contract_keys(tmp_path):
    write_markers_npz(_markers(), tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as data:
        assert {"positions", "names", "rate"} <= set(data.files)
        assert data["positions"].shape == (25, 6, 3) and data["names"].shape == (6,)


def test_same_data_same_bytes(tmp_path):
    write_markers(_markers(), tmp_path / "a.npz")
    write_markers(_markers(), tmp_path / "b.npz")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def test_foreign_npz_without_kind_is_read(tmp_path):
    np.savez(tmp_path / "f.npz", positions=np.zeros((2, 1, 3)), names=np.array(["a"]), rate=50.0)
    assert read_markers(tmp_path / "f.npz").rate == 50.0


@pytest.mark.parametrize("arrays, match", [
    ({"positions": np.zeros((2, 1, 3)), "rate": 50.0}, "missing names"),
    ({"positions": np.zeros((2, 3)), "names": np.array(["a"]), "rate": 50.0}, r"shape \(T, M, 3\)"),
    ({"positions": np.zeros((2, 1, 3)), "names": np.array(["a"]), "rate": -1.0}, "positive"),
])
def test_bad_npz_is_refused(tmp_path, arrays, match):
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(HandcapError, match=match):
        read_markers_npz(tmp_path / "bad.npz")


def test_truncated_npz_is_refused(tmp_path):
    write_markers(_markers(), tmp_path / "m.npz")
    data = (tmp_path / "m.npz").read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(HandcapError, match="not a readable marker .npz file"):
        read_markers(tmp_path / "cut.npz")


@pytest.mark.parametrize("suffix", [".c3d", ".tsv", ".csv", ".trc", ".npz"])
def test_empty_files_are_refused(tmp_path, suffix):
    path = tmp_path / f"empty{suffix}"
    path.write_bytes(b"")
    with pytest.raises(HandcapError, match="empty|not a readable|shorter than a C3D header"):
        read_markers(path)


@pytest.mark.parametrize("suffix", [".c3d", ".tsv", ".csv", ".trc", ".npz"])
def test_missing_files_and_folders_are_refused(tmp_path, suffix):
    with pytest.raises(HandcapError, match="no such file"):
        read_markers(tmp_path / f"absent{suffix}")
    (tmp_path / f"folder{suffix}").mkdir()
    with pytest.raises(HandcapError, match="is a folder, expected a file"):
        read_markers(tmp_path / f"folder{suffix}")


@pytest.mark.parametrize("name, verb", [("m.xyz", "read"), ("m", "read"), ("m.tsv", "write"), ("m.csv", "write")])
def test_unknown_extension_is_refused(tmp_path, name, verb):
    (tmp_path / name).write_text("x")
    with pytest.raises(HandcapError, match=f"cannot {verb} '.*' marker files; use one of"):
        if verb == "read":
            read_markers(tmp_path / name)
        else:
            write_markers(_markers(), tmp_path / name)


def test_failed_write_leaves_no_partial_file_and_keeps_the_old_one(tmp_path):
    path = tmp_path / "out.c3d"
    path.write_bytes(b"previous")
    bad = MarkerSequence(np.zeros((2, 1, 3)), ["trailing "], 100.0)
    with pytest.raises(HandcapError):
        write_markers(bad, path)
    assert path.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.c3d"]


def test_write_into_a_missing_folder_is_refused(tmp_path):
    with pytest.raises(HandcapError, match="does not exist"):
        write_markers(_markers(), tmp_path / "nowhere" / "m.npz")


def test_npz_is_a_zip_with_fixed_timestamps(tmp_path):
    write_markers(_markers(), tmp_path / "m.npz")
    with zipfile.ZipFile(tmp_path / "m.npz") as zf:
        assert {info.date_time for info in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}
