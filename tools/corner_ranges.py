"""Measure the corner network's activation ranges on rendered scenes and save them with its weights.

The ranges let the detector run the network's 8-bit integer twin (:mod:`handcap.detect.int8`). ``make
detect-weights`` runs this after training the corner network:

    .venv/bin/python tools/corner_ranges.py [--weights FILE] [--out FILE] [--scenes 20] [--seed 5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from handcap import HandcapError
from handcap.detect.int8 import activation_ranges
from handcap.detect.networks import WEIGHTS, load_corner_net, net_info, save_net
from handcap.detect.train import FONTS, corner_scenes


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--weights", default=str(WEIGHTS / "corners.npz"), help="corner network (default: the shipped)")
    p.add_argument("--out", help="weights file to write (default: --weights, replaced atomically)")
    p.add_argument("--scenes", type=int, default=20, help="rendered scenes to measure on (default %(default)s)")
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("--pages", type=float, default=0.3, help="share of photographed sheets (default %(default)s)")
    a = p.parse_args(argv)
    try:
        net = load_corner_net(a.weights)
        fonts = [None] + [f for f in FONTS if Path(f).is_file()]
        scenes = corner_scenes(a.scenes, a.seed, pages=a.pages, fonts=fonts)
        net.ranges = activation_ranges(net, [s.image for s in scenes])
    except HandcapError as err:
        print(f"corner_ranges: {err}", file=sys.stderr)
        return 2
    note = (f"activation ranges from {a.scenes} rendered scenes (seed {a.seed}, pages {a.pages:g}): "
            "tools/corner_ranges.py")
    save_net(net, a.out or a.weights, {**net_info(a.weights), "int8": note})
    print(f"wrote {a.out or a.weights}: {len(net.ranges)} activation ranges from {len(scenes)} scenes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
