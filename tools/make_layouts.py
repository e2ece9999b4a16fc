"""Write the shipped marker layouts (src/handcap/layouts/*.toml) from the OpenHand template.

Every nominal position is a point of the flat right OpenHand (betas = 0) skin,
found by casting a ray from inside a segment towards its back (or palm) and
keeping the hit on that segment. Rerun after changing the hand asset::

    .venv/bin/python tools/make_layouts.py

Placement rules (all distances in metres):

* glove-13: the back-of-hand triad of the Qualisys glove in
  ``../shared/data/markers/hand_embodiment_glove`` (its measured inter-marker
  distances are 55.2, 44.8 and 32.4 mm: hand_left/right 32 mm apart, 20 mm
  distal of the wrist, hand_top 65 mm distal and 16 mm ulnar), a marker 60 %
  along the back of each proximal phalanx and one on each nail, 7 mm off the
  skin (sphere radius plus glove, as in that project).
* joints-19: a 3 mm marker over the distal end of every metacarpal (MCP),
  proximal and middle phalanx (PIP, DIP) and on every nail, plus the glove triad.
* tips-5: the nail markers and the triad.
* active-9: wrist, index base, pinky base (the alignment triad of the active
  glove), one on the middle of the back of the hand, five nails; 5 mm LEDs.
* dense-patches: every corner of the 19 coded patches of one hand of
  ``handcap pattern`` (``handcap.patterns.session.HAND_PATCHES``, 5 mm squares):
  a strip three squares wide on the back of every phalanx (rows along the
  bone, centred between joints kept 3-4 mm clear, the tape wrapped around the
  finger: the columns are arcs along the skin), two patches on the dorsum and
  two on the palm. 0.5 mm off the skin (a printed transfer on tape). Each
  patch reads unmirrored from outside the skin (its corner names follow the
  pattern template: PATCH_rRcC). A corner is listed only where the skin moves
  rigidly with its segment (skinning weight of that segment >= 0.8).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from handcap.hand import OpenHand  # noqa: E402
from handcap.hand.anatomy import hand_axes  # noqa: E402
from handcap.patterns.pattern import PITCH, Patch, checker_tags  # noqa: E402
from handcap.patterns.session import HAND_PATCHES  # noqa: E402
from handcap.layouts import LayoutMarker, MarkerLayout  # noqa: E402

OUT = ROOT / "src" / "handcap" / "layouts"
RIGID = 0.8  # least skinning weight of a patch corner's own segment
FINGERS = {"index": (1, 2, 3, 17), "middle": (4, 5, 6, 18), "ring": (10, 11, 12, 19), "pinky": (7, 8, 9, 20),
           "thumb": (13, 14, 15, 16)}
SEGMENTS = ("proximal", "middle", "distal")


class Surface:
    def __init__(self):
        self.hand = OpenHand("right")
        out = self.hand.forward()
        self.vertices, self.joints = out.vertices, out.joints
        self.mesh = trimesh.Trimesh(self.vertices, self.hand.faces, process=False)
        self.face_segment = self.hand.segment_of_vertex[self.hand.faces]
        self.face_rigid = self.hand.weights[self.hand.faces].max(axis=2).min(axis=1)
        _, self.palmar, self.ulnar = hand_axes(self.joints[:16], True)
        self.dorsal = -self.palmar

    def hit(self, origin, direction, segment: str, rigid: float = 0.0):
        """First skin point along the ray that lies on ``segment`` (or None); any segment when it is None."""
        locs, _, faces = self.mesh.ray.intersects_location(origin[None], direction[None] / np.linalg.norm(direction))
        if len(locs) == 0:
            return None
        order = np.argsort(np.linalg.norm(locs - origin, axis=1))
        if segment is None:
            return locs[order[0]]
        seg = self.hand.segment_id(segment)
        first = faces[order[0]]
        # Most of the triangle on the segment (all of it where rigidity is asked for).
        if (self.face_segment[first] == seg).sum() < (3 if rigid else 2) or self.face_rigid[first] < rigid:
            return None
        return locs[order[0]]

    def bone(self, finger: str, k: int):
        chain = self.joints[list(FINGERS[finger])]
        return chain[k], chain[k + 1]

    def back_direction(self, finger: str, k: int):
        """Direction from the bone to its back (nail side)."""
        if finger != "thumb":
            return self.dorsal
        frame = self.hand.frames[13]  # thumb MCP frame: y is the oblique flexion direction
        return -frame[:, 1]

    def on_bone(self, finger: str, k: int, fraction: float, across: float = 0.0, rigid: float = 0.0):
        a, b = self.bone(finger, k)
        axis = (b - a) / np.linalg.norm(b - a)
        back = self.back_direction(finger, k)
        back = back - axis * (back @ axis)
        back /= np.linalg.norm(back)
        side = np.cross(axis, back)
        origin = a + fraction * (b - a) + across * side
        return self.hit(origin, back, f"{finger}_{SEGMENTS[k]}", rigid)

    def around_bone(self, finger: str, k: int, fraction: float, arc: float):
        """Skin point of a tape wrapped around the phalanx: ``arc`` metres along the skin from the back's midline."""
        a, b = self.bone(finger, k)
        axis = (b - a) / np.linalg.norm(b - a)
        back = self.back_direction(finger, k)
        back = back - axis * (back @ axis)
        back /= np.linalg.norm(back)
        side = np.cross(axis, back)
        origin = a + fraction * (b - a)
        top = self.hit(origin, back, f"{finger}_{SEGMENTS[k]}")
        if top is None:
            return None
        angle = arc / np.linalg.norm(top - origin)
        return self.hit(origin, np.cos(angle) * back + np.sin(angle) * side, f"{finger}_{SEGMENTS[k]}", RIGID)

    def on_palm(self, x: float, z: float, palmar: bool = False, rigid: float = 0.0):
        origin = np.array([x, 0.0, z])
        return self.hit(origin, self.palmar if palmar else self.dorsal, "palm", rigid)


def triad(s: Surface):
    return [LayoutMarker("hand_top", "palm", s.on_palm(0.065, 0.0156)),
            LayoutMarker("hand_left", "palm", s.on_palm(0.020, -0.016)),
            LayoutMarker("hand_right", "palm", s.on_palm(0.020, 0.016))]


def nail(s: Surface, finger: str, name: str):
    return LayoutMarker(name, f"{finger}_distal", s.on_bone(finger, 2, 0.55))


def glove_13(s: Surface) -> MarkerLayout:
    markers = triad(s)
    for finger in ("thumb", "index", "middle", "ring", "pinky"):
        label = "little" if finger == "pinky" else finger
        k, frac = (1, 0.5) if finger == "thumb" else (0, 0.6)
        markers.append(LayoutMarker(f"{label}_middle", f"{finger}_{SEGMENTS[k]}", s.on_bone(finger, k, frac)))
        markers.append(nail(s, finger, f"{label}_tip"))
    return MarkerLayout("glove-13", "right", tuple(markers), ("hand_top", "hand_left", "hand_right"), 0.007,
                        "sphere", "Qualisys glove of hand_embodiment: back triad, proximal phalanx and nail markers")


def joints_19(s: Surface) -> MarkerLayout:
    markers = triad(s)
    for finger in ("index", "middle", "ring", "pinky"):
        mcp = s.joints[FINGERS[finger][0]]
        markers.append(LayoutMarker(f"{finger}_mcp", "palm", s.on_palm(mcp[0] - 0.004, mcp[2])))
        markers.append(LayoutMarker(f"{finger}_pip", f"{finger}_proximal", s.on_bone(finger, 0, 0.85)))
        markers.append(LayoutMarker(f"{finger}_dip", f"{finger}_middle", s.on_bone(finger, 1, 0.85)))
        markers.append(nail(s, finger, f"{finger}_tip"))
    markers.append(LayoutMarker("thumb_mcp", "thumb_proximal", s.on_bone("thumb", 0, 0.85)))
    markers.append(LayoutMarker("thumb_ip", "thumb_middle", s.on_bone("thumb", 1, 0.85)))
    markers.append(nail(s, "thumb", "thumb_tip"))
    return MarkerLayout("joints-19", "right", tuple(markers), ("hand_top", "hand_left", "hand_right"), 0.003,
                        "sphere", "a marker over every finger joint and nail (19) plus the back-of-hand triad")


def tips_5(s: Surface) -> MarkerLayout:
    markers = triad(s) + [nail(s, f, f"{f}_tip") for f in ("thumb", "index", "middle", "ring", "pinky")]
    return MarkerLayout("tips-5", "right", tuple(markers), ("hand_top", "hand_left", "hand_right"), 0.003,
                        "sphere", "the five nails plus the back-of-hand triad")


def active_9(s: Surface) -> MarkerLayout:
    index_mcp, pinky_mcp = s.joints[1], s.joints[7]
    markers = [LayoutMarker("wrist", "palm", s.on_palm(0.008, 0.0)),
               LayoutMarker("index_base", "palm", s.on_palm(index_mcp[0] - 0.006, index_mcp[2])),
               LayoutMarker("pinky_base", "palm", s.on_palm(pinky_mcp[0] - 0.006, pinky_mcp[2])),
               LayoutMarker("hand_back", "palm", s.on_palm(0.045, 0.004))]
    markers += [nail(s, f, f"{f}_tip") for f in ("thumb", "index", "middle", "ring", "pinky")]
    return MarkerLayout("active-9", "right", tuple(markers), ("wrist", "index_base", "pinky_base"), 0.005,
                        "sphere", "active LED glove: alignment triad, back of hand, five fingertips")


def _unmirrored(grid: list, outward: np.ndarray) -> list:
    """``grid`` (rows of points or None) with its columns reversed if needed, so the patch reads unmirrored.

    Seen from outside the skin, columns run to the right and rows downwards, so column x row points into the skin.
    """
    found = [(r, c, np.asarray(p)) for r, row in enumerate(grid) for c, p in enumerate(row) if p is not None]
    points = np.array([p for _, _, p in found])
    rc = np.array([(r, c) for r, c, _ in found], dtype=float)
    # Least-squares affine map (r, c) -> point: its columns are the row and column directions.
    coef = np.linalg.lstsq(np.c_[rc, np.ones(len(rc))], points, rcond=None)[0]
    dr, dc = coef[0], coef[1]
    return [row[::-1] for row in grid] if np.cross(dc, dr) @ outward > 0 else grid


def dense_patches(s: Surface) -> MarkerLayout:
    """Every corner of the hand patches of ``handcap.patterns.session.HAND_PATCHES`` on the template hand."""
    pitch = PITCH
    markers = []
    for finger in ("thumb", "index", "middle", "ring", "pinky"):
        for k in range(3):
            a, b = s.bone(finger, k)
            length = np.linalg.norm(b - a)
            rows, cols, segment = HAND_PATCHES[f"{finger}_{SEGMENTS[k]}"]
            lo, hi = (0.004, length - 0.004) if k < 2 else (0.003, length - 0.005)
            start = (lo + hi) / 2 - rows * pitch / 2
            grid = [[s.around_bone(finger, k, (start + r * pitch) / length, (c - cols / 2) * pitch)
                     for c in range(cols + 1)] for r in range(rows + 1)]
            markers += _patch_markers(f"{finger}_{SEGMENTS[k]}", segment, _unmirrored(grid, s.back_direction(
                finger, k)))
    # Dorsum and palm: rows from the wrist towards the fingers (x), columns across the hand (z).
    grids = {"dorsum_proximal": (0.012, -0.020, False), "dorsum_distal": (0.047, -0.020, False),
             "palm_proximal": (0.020, -0.010, True), "palm_distal": (0.050, -0.015, True)}
    for patch, (x0, z0, palmar) in grids.items():
        rows, cols, segment = HAND_PATCHES[patch]
        grid = [[s.on_palm(x0 + r * pitch, z0 + c * pitch, palmar, rigid=RIGID) for c in range(cols + 1)]
                for r in range(rows + 1)]
        markers += _patch_markers(patch, segment, _unmirrored(grid, s.palmar if palmar else s.dorsal))
    return MarkerLayout("dense-patches", "right", tuple(markers), (), 0.0005, "patch",
                        "19 coded checkerboard patches (DexterCap), every corner of handcap pattern's hand "
                        "patches, 5 mm squares")


def _patch_markers(name: str, segment: str, grid: list) -> list:
    """Layout markers for the corners of one patch (vertices touching a white square) that lie on rigid skin."""
    rows, cols = len(grid) - 1, len(grid[0]) - 1
    patch = Patch(name, "right", segment, checker_tags(rows, cols, lambda: "00"))
    return [LayoutMarker(patch.corner_name(int(r), int(c), owner=False), segment, grid[r][c], name)
            for r, c in patch.vertices() if grid[r][c] is not None]


def main() -> None:
    s = Surface()
    for make in (glove_13, joints_19, tips_5, active_9, dense_patches):
        layout = make(s)
        missing = [m.name for m in layout.markers if m.position is None]
        if missing:
            raise SystemExit(f"{layout.name}: no skin hit for {missing}")
        layout.save(OUT / f"{layout.name}.toml")
        patches = sorted({m.patch for m in layout.markers if m.patch})
        print(f"{layout.name}: {len(layout)} markers" + (f" on {len(patches)} patches" if patches else ""))


if __name__ == "__main__":
    main()
