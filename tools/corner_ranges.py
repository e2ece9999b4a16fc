"""Measure the activation ranges of the corner network, or of the corner refiner, on rendered scenes and save them
with its weights.

The ranges let the detector run the network's 8-bit integer twin (:mod:`handcap.detect.int8`). ``make
detect-weights`` runs this after training each network (the refiner's after the corner network's: it measures
the refiner on the crops at that network's candidates, as the detector gives them):

    .venv/bin/python tools/corner_ranges.py [--what corners|refiner] [--weights FILE] [--corners FILE]
        [--out FILE] [--scenes 20] [--seed 5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from handcap import HandcapError
from handcap.detect.int8 import activation_ranges, refiner_ranges
from handcap.detect.networks import WEIGHTS, load_corner_net, load_refiner, net_info, save_net
from handcap.detect.train import FONTS, corner_scenes


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--what", choices=("corners", "refiner"), default="corners", help="the network (default corners)")
    p.add_argument("--weights", help="its weights (default: the shipped corners.npz or refiner.npz)")
    p.add_argument("--corners", help="the refiner: the corner network whose candidates it refines (default: the "
                                     "shipped, in 8-bit integers as handcap detect runs it)")
    p.add_argument("--out", help="weights file to write (default: --weights, replaced atomically)")
    p.add_argument("--scenes", type=int, default=20, help="rendered scenes to measure on (default %(default)s)")
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("--pages", type=float, default=0.3, help="share of photographed sheets (default %(default)s)")
    a = p.parse_args(argv)
    weights = a.weights or str(WEIGHTS / f"{a.what}.npz")
    try:
        net = load_corner_net(weights) if a.what == "corners" else load_refiner(weights)
        corner_net = load_corner_net(a.corners, int8=True) if a.what == "refiner" else None
        fonts = [None] + [f for f in FONTS if Path(f).is_file()]
        scenes = corner_scenes(a.scenes, a.seed, pages=a.pages, fonts=fonts)
        images = [s.image for s in scenes]
        net.ranges = activation_ranges(net, images) if corner_net is None else refiner_ranges(net, corner_net, images)
    except HandcapError as err:
        print(f"corner_ranges: {err}", file=sys.stderr)
        return 2
    note = (f"activation ranges from {a.scenes} rendered scenes (seed {a.seed}, pages {a.pages:g}): "
            f"tools/corner_ranges.py --what {a.what}")
    save_net(net, a.out or weights, {**net_info(weights), "int8": note})
    print(f"wrote {a.out or weights}: {len(net.ranges)} activation ranges from {len(scenes)} scenes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
