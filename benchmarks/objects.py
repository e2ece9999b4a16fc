"""Articulated objects (issue 18): the 2x2x2 cube turned by a hand, and a user's hinge, each measured in this run.

1. Cube under hand occlusion: ``--scrambles`` random 10-move scrambles (default 20), each a synthetic take of
   the hand turning the cube (``synth --motion turn-cube``, 120 Hz, 12 cameras, 0.5 mm noise; no dropouts,
   swaps or ghosts, so that what hides markers is the hand and the cube itself), tracked from its labelled
   markers: move sequences exact (target 20 / 20), the cube's pose (target 1 mm / 1 deg) and the layers'
   angles (target 2 deg; the largest error of any cubie's rotation in the cube's frame) as mean, 99th
   percentile and worst frame, hidden markers filled from the track against their true places, and tracking
   speed (target >= 500 frames/s).
2. The same with the capture faults ``synth`` adds by default (1 % dropouts in bursts, label swaps 0.1/s,
   ghosts 1/s).
3. Speed on a long take: 200 moves of the cube alone (``cube_take``), frames/s.
4. A two-part hinge from its TOML: 2000 frames at 100 Hz, 0.5 mm noise, 10 % of markers hidden; angle and
   pose error, frames/s.
5. Labeling the cube's markers in the unlabelled points (ghosts and the hand's markers among them) from one
   labelled frame, over ``--scrambles // 2`` takes of section 2's kind: labels correct, wrong and missed
   against the truth, moves exact from those labels, frames/s.

6. The cube in coded patches (``cube2x2-patches``: 552 corners), 60 moves, 0.5 mm noise, half of the corners
   hidden: moves exact, pose error, frames/s.

7. With the hand: ``(R U R' U') x 6`` (the tracker's cubie permutation at the end must be the identity) and
   all 18 face turns in one take (each face clockwise, counter-clockwise and half).

    .venv/bin/python benchmarks/objects.py [--scrambles 20] [--sections 1,3,4,5,6,7]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

HINGE = {"name": "hinge", "units": "mm",
         "parts": [{"name": "base", "markers": {"b1": [0, 0, 0], "b2": [60, 0, 0], "b3": [0, 40, 5],
                                                "b4": [55, 35, 0]}},
                   {"name": "lid", "markers": {"l1": [5, 0, 30], "l2": [60, -5, 30], "l3": [0, -40, 35]}}],
         "joints": [{"type": "revolute", "parent": "base", "child": "lid", "axis": [1, 0, 0], "origin": [0, 0, 15],
                     "limits_deg": [-5, 185]}]}


def _pose(capture):
    om = capture.object_motion
    pose = np.tile(np.eye(4), (len(om.translation), 1, 1))
    pose[:, :3, :3], pose[:, :3, 3] = Rotation.from_rotvec(om.rotation).as_matrix(), om.translation
    return pose


def cube_section(scrambles: int, faults: bool) -> None:
    from handcap.objects import load_articulated
    from handcap.objects.cube import format_moves, random_moves
    from handcap.objects.cube_output import cube_errors, fitted_markers
    from handcap.objects.cube_track import track_cube
    from handcap.synth.scene import SynthConfig, synthesize

    cube = load_articulated("cube2x2")
    exact, frames, seconds, seen = 0, 0, 0.0, []
    position, rotation, layer, filled = [], [], [], []
    for k in range(scrambles):
        moves = format_moves(random_moves(10, np.random.default_rng(100 + k)))
        config = SynthConfig(motion="turn-cube", moves=moves, seed=k, noise_mm=0.5, rate=120.0)
        if not faults:
            config = replace(config, dropout=0.0, swap_rate=0.0, ghost_rate=0.0)
        capture = synthesize(config, progress=False)
        markers = capture.markers.select(list(cube.marker_names)).positions
        start = time.perf_counter()
        track = track_cube(markers, cube, window=9)
        seconds += time.perf_counter() - start
        frames += len(markers)
        seen.append(np.isfinite(markers).all(axis=2).mean())
        exact += track.moves == moves
        if track.moves != moves:
            print(f"  scramble {k}: tracked {track.moves!r}, made {moves!r}")
        e = cube_errors(track, _pose(capture), capture.truth["cube_cubie_rotation"])
        position.append(e["position_mm"])
        rotation.append(e["rotation_deg"])
        layer.append(e["layer_deg"])
        true = capture.truth["positions"][:, [list(map(str, capture.truth["names"])).index(n)
                                              for n in cube.marker_names]]
        hidden = ~np.isfinite(markers).all(axis=2)
        filled.append(np.linalg.norm(fitted_markers(track, cube)[hidden] - true[hidden], axis=-1) * 1000)
    p, r, a = (np.concatenate(x) for x in (position, rotation, layer))
    label = "with capture faults" if faults else "hand occlusion, 0.5 mm noise"
    print(f"cube, {label}: {scrambles} scrambles of 10 moves, {frames} frames, cube markers seen "
          f"{100 * np.mean(seen):.1f} %")
    print(f"  move sequences exact   {exact} / {scrambles}")
    for name, x, unit in (("pose position", p, "mm"), ("pose rotation", r, "deg"), ("layer angle", a, "deg")):
        print(f"  {name:<22} mean {np.nanmean(x):.2f}  p99 {np.nanpercentile(x, 99):.2f}  worst "
              f"{np.nanmax(x):.2f} {unit}  ({100 * np.isnan(x).mean():.1f} % frames without a pose)")
    f = np.concatenate(filled)
    print(f"  hidden markers filled  {len(f)} samples, mean {np.nanmean(f):.2f}  p99 {np.nanpercentile(f, 99):.2f} "
          f"worst {np.nanmax(f):.2f} mm from their true places")
    print(f"  tracking speed         {frames / seconds:.0f} frames/s (target >= 500)")


def long_section() -> None:
    from handcap.objects.cube import format_moves, random_moves
    from handcap.objects.cube_track import track_cube
    from handcap.synth.cube import cube_take

    moves = format_moves(random_moves(200, np.random.default_rng(7)))
    take = cube_take(moves, np.random.default_rng(7), rate=120.0)
    markers = take.markers + np.random.default_rng(8).normal(0, 0.0005, take.markers.shape)
    from handcap.objects import load_articulated

    cube = load_articulated("cube2x2")
    start = time.perf_counter()
    track = track_cube(markers, cube)
    seconds = time.perf_counter() - start
    print(f"cube alone, 200 moves: {len(markers)} frames in {seconds:.2f} s = {len(markers) / seconds:.0f} frames/s; "
          f"sequence {'exact' if track.moves == moves else 'WRONG'}")


def hinge_section() -> None:
    from handcap.core.transforms import homogeneous
    from handcap.objects import articulated_from_table
    from handcap.objects.jointed import part_markers, pose_parts, track_jointed

    hinge = articulated_from_table(HINGE, "hinge")
    rng = np.random.default_rng(0)
    n = 2000
    t = np.arange(n) / 100.0
    truth = np.deg2rad(90 + 85 * np.sin(2 * np.pi * 0.2 * t))[:, None]
    turn = Rotation.from_rotvec(0.5 * np.sin(2 * np.pi * np.outer(t, [0.11, 0.07, 0.13])))
    pose = homogeneous(turn.as_matrix(), np.array([0, 0, 1.0]) + 0.1 * np.sin(np.outer(t, [0.5, 0.3, 0.4])))
    markers = part_markers(hinge, pose_parts(hinge, pose, truth)) + rng.normal(0, 0.0005, (n, 7, 3))
    markers[rng.random((n, 7)) < 0.1] = np.nan
    start = time.perf_counter()
    track = track_jointed(markers, hinge)
    seconds = time.perf_counter() - start
    ok = np.isfinite(track.angles[:, 0])
    angle = np.rad2deg(np.abs(track.angles[ok, 0] - truth[ok, 0]))
    position = np.linalg.norm(track.translation[ok] - pose[ok, :3, 3], axis=1) * 1000
    print(f"hinge from its TOML: {n} frames, 10 % of markers hidden, 0.5 mm noise; angle measured in "
          f"{100 * ok.mean():.1f} % of frames")
    print(f"  angle error  median {np.median(angle):.2f}  p99 {np.percentile(angle, 99):.2f}  worst {angle.max():.2f} "
          f"deg; position {np.median(position):.2f} mm median; {n / seconds:.0f} frames/s")


def label_section(takes: int) -> None:
    from handcap.objects import load_articulated
    from handcap.objects.cube import format_moves, random_moves
    from handcap.objects.cube_label import label_cube
    from handcap.objects.cube_track import track_cube
    from handcap.synth.scene import SynthConfig, synthesize

    cube = load_articulated("cube2x2")
    names = list(cube.marker_names)
    correct, wrong, missed, exact, frames, seconds = [], [], [], 0, 0, 0.0
    for k in range(takes):
        moves = format_moves(random_moves(10, np.random.default_rng(200 + k)))
        capture = synthesize(SynthConfig(motion="turn-cube", moves=moves, seed=50 + k, noise_mm=0.5, rate=120.0),
                             progress=False)
        given = capture.markers.select(names).positions
        start = int(np.argmax((np.isfinite(given).all(axis=2).reshape(len(given), 8, -1).sum(axis=2) >= 2)
                              .all(axis=1)))
        clock = time.perf_counter()
        labels = label_cube(capture.points.frames, cube, given[start], start)
        seconds += time.perf_counter() - clock
        truth = capture.labeled_points(names).positions[start:]
        got = labels.positions[start:]
        frames += len(got)
        have, real = np.isfinite(got).all(axis=2), np.isfinite(truth).all(axis=2)
        same = have & real & (np.linalg.norm(np.nan_to_num(got - truth), axis=-1) < 1e-9)
        correct.append((same | (~have & ~real)).mean())
        wrong.append((have & ~same).mean())
        missed.append((real & ~have).mean())
        exact += track_cube(labels.positions, cube).moves == moves
    print(f"cube labeling from one labelled frame: {takes} takes, {frames} frames (ghosts 1/s, the hand's markers "
          f"in the points)")
    print(f"  correct {100 * np.mean(correct):.2f} % (worst take {100 * np.min(correct):.2f} %), wrong "
          f"{100 * np.mean(wrong):.3f} %, missed {100 * np.mean(missed):.3f} %; moves exact from the labels "
          f"{exact} / {takes}; {frames / seconds:.0f} frames/s")


def patches_section() -> None:
    from handcap.objects import load_articulated
    from handcap.objects.cube import format_moves, random_moves
    from handcap.objects.cube_output import cube_errors
    from handcap.objects.cube_track import track_cube
    from handcap.synth.cube import cube_take

    cube = load_articulated("cube2x2-patches")
    moves = format_moves(random_moves(60, np.random.default_rng(9)))
    take = cube_take(moves, np.random.default_rng(9), rate=120.0, cube=cube)
    rng = np.random.default_rng(10)
    markers = take.markers + rng.normal(0, 0.0005, take.markers.shape)
    markers[rng.random(markers.shape[:2]) < 0.5] = np.nan
    start = time.perf_counter()
    track = track_cube(markers, cube)
    seconds = time.perf_counter() - start
    e = cube_errors(track, take.global_pose, take.cubie_rotation)
    print(f"cube in coded patches: {len(cube.marker_names)} corners, half hidden, 60 moves, {len(markers)} frames: "
          f"sequence {'exact' if track.moves == moves else 'WRONG'}; pose {np.nanmean(e['position_mm']):.2f} mm / "
          f"{np.nanmean(e['rotation_deg']):.2f} deg, layers {np.nanmean(e['layer_deg']):.2f} deg (worst "
          f"{np.nanmax(e['layer_deg']):.2f}); {len(markers) / seconds:.0f} frames/s")


def sequences_section() -> None:
    from handcap.objects import load_articulated
    from handcap.objects.cube_track import track_cube
    from handcap.synth.scene import SynthConfig, synthesize

    cube = load_articulated("cube2x2")
    every = " ".join(face + turn for turn in ("", "'", "2") for face in "UDLRFB")
    for label, moves, expect in (("(R U R' U') x 6", "R U R' U' " * 6, None), ("all 18 face turns", every, every)):
        capture = synthesize(replace(SynthConfig(motion="turn-cube", moves=moves.strip(), seed=11, noise_mm=0.5,
                                                 rate=120.0), dropout=0.0, swap_rate=0.0, ghost_rate=0.0),
                             progress=False)
        track = track_cube(capture.markers.select(list(cube.marker_names)).positions, cube)
        if expect is None:
            result = (f"permutation {track.permutation.tolist()}, "
                      f"{'identity' if (track.state == np.eye(3, dtype=int)).all() else 'NOT the identity'}")
        else:
            result = "exact" if track.moves == expect else f"WRONG: {track.moves}"
        print(f"{label} with the hand ({len(capture.markers.positions)} frames): {result}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scrambles", type=int, default=20)
    parser.add_argument("--sections", default="1,2,3,4,5,6,7")
    a = parser.parse_args()
    sections = {int(s) for s in a.sections.split(",")}
    if 1 in sections:
        cube_section(a.scrambles, faults=False)
    if 2 in sections:
        cube_section(max(a.scrambles // 4, 1), faults=True)
    if 3 in sections:
        long_section()
    if 4 in sections:
        hinge_section()
    if 5 in sections:
        label_section(max(a.scrambles // 2, 1))
    if 6 in sections:
        patches_section()
    if 7 in sections:
        sequences_section()


if __name__ == "__main__":
    main()
