"""Write the shipped description of the 2x2x2 cube in coded patches (src/handcap/objects/data/cube2x2-patches.toml)
from handcap.objects.cube_patches; a test checks that the file and the generator agree.

    .venv/bin/python tools/make_cube_patches.py
"""

from pathlib import Path

import tomli_w

from handcap.core.files import atomic_output
from handcap.objects.cube_patches import patch_cube_table

OUT = Path(__file__).resolve().parents[1] / "src" / "handcap" / "objects" / "data" / "cube2x2-patches.toml"
HEADER = (b"# The 2x2x2 cube with a 4 x 4 coded patch (5 mm squares) on each of its 24 facelets; every patch corner\n"
          b"# is a marker named as the session template names it. Written by tools/make_cube_patches.py from\n"
          b"# handcap.objects.cube_patches; see there for the layout of the facelets.\n")

if __name__ == "__main__":
    with atomic_output(OUT) as fh:
        fh.write(HEADER + tomli_w.dumps(patch_cube_table()).encode())
    print(f"wrote {OUT}")
