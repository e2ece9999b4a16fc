"""Importers of 2D hand keypoints: MediaPipe arrays, OpenPose JSON folders, COCO files (issue 17)."""

import json

import numpy as np
import pytest

from handcap import HandcapError
from handcap.markerless import import_keypoints, merge_keypoints
from handcap.markerless.importers import read_coco_json, read_mediapipe_npy, read_openpose_folder


def _hand(rng, shift=0.0):
    return np.c_[rng.uniform(10, 600, (21, 2)) + shift, rng.uniform(0.5, 1.0, 21)]


def _rows(det):
    """{(camera, frame, name): (x, y)} of detections."""
    return {(det.camera_names[c], int(f), det.marker_names[m]): tuple(xy)
            for c, f, m, xy in zip(det.camera, det.frame, det.marker, det.xy)}


def test_mediapipe_arrays(tmp_path):
    rng = np.random.default_rng(0)
    left = rng.uniform(0, 500, (2, 5, 21, 2))
    left[0, 1, 3] = -1.0  # missing
    left[1, 4] = np.nan
    np.save(tmp_path / "cam_left.npy", left)
    np.save(tmp_path / "Right_hand.npy", rng.uniform(0, 500, (2, 5, 21, 2)))
    det = import_keypoints([tmp_path / "cam_left.npy", tmp_path / "Right_hand.npy"], "mediapipe-npy", rate=30.0,
                           cameras=["a", "b"])
    rows = _rows(det)
    assert det.camera_names == ("a", "b") and det.n_frames == 5 and det.rate == 30.0
    assert rows[("b", 2, "left:index_mcp")] == tuple(left[1, 2, 5])
    assert ("a", 1, "left:thumb_ip") not in rows and ("b", 4, "left:wrist") not in rows
    assert len(det) == 2 * 2 * 5 * 21 - 1 - 21
    one = read_mediapipe_npy(tmp_path / "cam_left.npy", rate=30.0)
    assert one.camera_names == ("cam0", "cam1")
    single = rng.uniform(0, 500, (4, 21, 3))
    np.save(tmp_path / "video.npy", single)
    det = read_mediapipe_npy(tmp_path / "video.npy", rate=25.0)
    assert det.marker_names[0] == "hand:wrist" and np.allclose(det.score, single[..., 2].reshape(-1))


def test_openpose_folder(tmp_path):
    rng = np.random.default_rng(1)
    folder = tmp_path / "cam3"
    folder.mkdir()
    truth = {}
    for t in (0, 1, 3):
        person = {"pose_keypoints_2d": [0.0] * 75}
        a, b = _hand(rng), _hand(rng, 50)
        b[2, 2] = 0.0  # confidence 0: missing
        person["hand_left_keypoints_2d"] = a.reshape(-1).tolist()
        person["hand_right_keypoints_2d"] = b.reshape(-1).tolist()
        people = [person]
        if t == 3:
            people.append({"hand_left_keypoints_2d": _hand(rng).reshape(-1).tolist(), "hand_right_keypoints_2d": []})
        (folder / f"video_{t:012d}_keypoints.json").write_text(json.dumps({"version": 1.3, "people": people}))
        truth[t] = (a, b)
    det = read_openpose_folder(folder, rate=30.0)
    rows = _rows(det)
    assert det.camera_names == ("cam3",) and det.n_frames == 4
    assert rows[("cam3", 3, "left:pinky_tip")] == tuple(truth[3][0][20, :2])
    assert ("cam3", 1, "right:thumb_cmc") in rows and ("cam3", 1, "right:thumb_mcp") not in rows
    assert ("cam3", 3, "left1:wrist") in rows and not any(k[1] == 2 for k in rows)


def test_coco_files(tmp_path):
    rng = np.random.default_rng(2)
    a, b = _hand(rng), _hand(rng, 80)
    a[5, 2] = 0  # v = 0: not labelled
    coco = {"images": [{"id": 7, "file_name": "f7.jpg"}, {"id": 3, "file_name": "f3.jpg"}],
            "annotations": [{"image_id": 7, "keypoints": a.reshape(-1).tolist(), "handedness": "Right"},
                            {"image_id": 3, "keypoints": b.reshape(-1).tolist()},
                            {"image_id": 3, "keypoints": a.reshape(-1).tolist()}]}
    (tmp_path / "camA.json").write_text(json.dumps(coco))
    det = read_coco_json(tmp_path / "camA.json", rate=10.0)
    rows = _rows(det)
    assert det.n_frames == 2 and rows[("camA", 1, "right:wrist")] == tuple(a[0, :2])
    assert ("camA", 1, "right:index_mcp") not in rows
    assert rows[("camA", 0, "hand:wrist")] == tuple(b[0, :2]) and ("camA", 0, "hand1:wrist") in rows
    whole = {"images": [{"id": 1}], "annotations": [{"image_id": 1, "keypoints": [0] * 399,
                                                     "lefthand_kpts": a.reshape(-1).tolist(),
                                                     "righthand_kpts": [0.0] * 63}]}
    (tmp_path / "whole.json").write_text(json.dumps(whole))
    det = read_coco_json(tmp_path / "whole.json", rate=10.0)
    assert {n.split(":")[0] for n in det.marker_names} == {"left"} and len(det) == 20
    results = [{"image_id": 5, "category_id": 1, "keypoints": b.reshape(-1).tolist(), "score": 0.7}]
    (tmp_path / "res.json").write_text(json.dumps(results))
    det = read_coco_json(tmp_path / "res.json", rate=10.0)
    assert len(det) == 21 and np.allclose(det.score, 0.7)


def test_merge_numbers_repeated_labels(tmp_path):
    rng = np.random.default_rng(3)
    for name in ("x.npy", "y.npy"):
        np.save(tmp_path / name, rng.uniform(0, 500, (3, 21, 2)))
    det = import_keypoints([tmp_path / "x.npy", tmp_path / "y.npy"], "mediapipe-npy", rate=30.0)
    assert {n.split(":")[0] for n in det.marker_names} == {"hand", "hand1"} and det.camera_names == ("cam0",)
    assert len(merge_keypoints([det])) == len(det)


@pytest.mark.parametrize("content, fmt, message", [
    (np.zeros((5, 20, 2)), "mediapipe-npy", "shape"),
    (np.array(["a", "b"]), "mediapipe-npy", "numbers"),
    (np.full((2, 21, 2), 1e9), "mediapipe-npy", "million"),
    ("{not json", "coco-json", "JSON"),
    ('{"images": []}', "coco-json", "annotations"),
    ('{"annotations": [{"image_id": 1, "keypoints": [1, 2]}]}', "coco-json", "21 x 3"),
    ('{"images": [{"id": 2}], "annotations": [{"image_id": 1, "keypoints": []}]}', "coco-json", "lacks"),
    ('[{"keypoints": []}]', "coco-json", "image_id"),
    ('{"annotations": [{"image_id": 1, "keypoints": [1, "x", 3]}]}', "coco-json", "numbers"),
])
def test_bad_files(tmp_path, content, fmt, message):
    path = tmp_path / ("bad.npy" if fmt == "mediapipe-npy" else "bad.json")
    if isinstance(content, str):
        path.write_text(content)
    else:
        np.save(path, content)
    before = path.read_bytes()
    with pytest.raises(HandcapError, match=message):
        import_keypoints([path], fmt, rate=30.0)
    assert path.read_bytes() == before


def test_bad_arguments_and_folders(tmp_path):
    with pytest.raises(HandcapError, match="unknown keypoint format"):
        import_keypoints([tmp_path], "dlc", rate=30.0)
    with pytest.raises(HandcapError, match="no such"):
        import_keypoints([tmp_path / "none.npy"], "mediapipe-npy", rate=30.0)
    with pytest.raises(HandcapError, match="no .json"):
        import_keypoints([tmp_path], "openpose-json", rate=30.0)
    (tmp_path / "f_0_keypoints.json").write_text('{"people": {"a": 1}}')
    with pytest.raises(HandcapError, match="people"):
        import_keypoints([tmp_path], "openpose-json", rate=30.0)
    with pytest.raises(HandcapError, match="rate"):
        import_keypoints([tmp_path], "openpose-json", rate=0.0)


def test_fuzzed_files_raise_only_handcap_errors(tmp_path):
    rng = np.random.default_rng(4)
    pieces = ['{"people": [', '"hand_left_keypoints_2d"', '[1, 2, 3]', '{"images"', '"annotations": [',
              '{"image_id": 1', ', "keypoints": [', '0.5', 'null', '"x"', ']', '}', ',', ':', '[]', '{}', '1e400']
    for k in range(300):
        text = "".join(rng.choice(pieces, rng.integers(1, 14)))
        for fmt in ("coco-json", "openpose-json"):
            folder = tmp_path / f"{fmt}{k}"
            folder.mkdir()
            path = folder / "a_1_keypoints.json"
            path.write_text(text)
            try:
                import_keypoints([path if fmt == "coco-json" else folder], fmt, rate=30.0)
            except HandcapError:
                pass
        raw = tmp_path / f"r{k}.npy"
        raw.write_bytes(rng.bytes(int(rng.integers(0, 200))))
        try:
            import_keypoints([raw], "mediapipe-npy", rate=30.0)
        except HandcapError:
            pass


@pytest.mark.parametrize("content", [
    {"annotations": [{"image_id": [1], "keypoints": []}]},
    {"images": [{"id": {"a": 1}}], "annotations": [{"image_id": 1, "keypoints": []}]},
    {"annotations": [{"image_id": 1, "keypoints": [1] * 63, "score": "high"}]},
    {"annotations": [{"image_id": None, "keypoints": [1] * 63}]},
    {"annotations": [{"image_id": True, "keypoints": [1] * 63}]},
])
def test_odd_json_structures(tmp_path, content):
    path = tmp_path / "odd.json"
    path.write_text(json.dumps(content))
    with pytest.raises(HandcapError):
        import_keypoints([path], "coco-json", rate=30.0)
