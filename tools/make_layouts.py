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
* dense-patches: 19 patches of inner checkerboard corners at 5 mm pitch, one on
  the back of every phalanx (3 columns across the finger, rows along it, kept
  3-4 mm clear of the joints), two on the dorsum and two on the palm; a corner
  is kept only where the skin moves rigidly with its segment (skinning weight
  of that segment >= 0.8). 0.5 mm off the skin (a printed transfer on tape).
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
        """First skin point along the ray that lies on ``segment`` (or None)."""
        seg = self.hand.segment_id(segment)
        locs, _, faces = self.mesh.ray.intersects_location(origin[None], direction[None] / np.linalg.norm(direction))
        if len(locs) == 0:
            return None
        order = np.argsort(np.linalg.norm(locs - origin, axis=1))
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


def dense_patches(s: Surface) -> MarkerLayout:
    pitch = 0.005
    markers = []
    for finger in ("thumb", "index", "middle", "ring", "pinky"):
        for k in range(3):
            a, b = s.bone(finger, k)
            length = np.linalg.norm(b - a)
            lo, hi = (0.004, length - 0.004) if k < 2 else (0.003, length - 0.005)
            rows = np.arange(lo + (hi - lo) % pitch / 2, hi + 1e-9, pitch)
            patch = f"{finger}_{SEGMENTS[k]}"
            for r, along in enumerate(rows):
                for c, across in enumerate((-pitch, 0.0, pitch)):
                    p = s.on_bone(finger, k, along / length, across, rigid=RIGID)
                    if p is not None:
                        markers.append(LayoutMarker(f"{patch}_r{r}c{c}", patch, p, patch))
    grids = {"dorsum_proximal": (np.arange(0.012, 0.043, pitch), False),
             "dorsum_distal": (np.arange(0.047, 0.078, pitch), False),
             "palm_proximal": (np.arange(0.020, 0.046, pitch), True),
             "palm_distal": (np.arange(0.050, 0.071, pitch), True)}
    for patch, (xs, palmar) in grids.items():
        zs = np.arange(-0.020, 0.0251, pitch) if not palmar else np.arange(-0.015, 0.0251, pitch)
        for r, x in enumerate(xs):
            for c, z in enumerate(zs):
                p = s.on_palm(x, z, palmar, rigid=RIGID)
                if p is not None:
                    markers.append(LayoutMarker(f"{patch}_r{r}c{c}", "palm", p, patch))
    return MarkerLayout("dense-patches", "right", tuple(markers), (), 0.0005, "patch",
                        "19 checkerboard patches (DexterCap), inner corners at 5 mm pitch")


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
