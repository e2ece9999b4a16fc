"""``handcap export``: a solved hand motion to glTF, USD, BVH, CSV, C3D/TRC or MANO ``.npz``."""

from __future__ import annotations

from handcap.cli.common import add_hand_model
from handcap.export import FORMATS
from handcap.steps import export


def _cmd_export(a):
    return export.export(a.motion, a.to, units=a.units, hand_model=a.hand_model, mano_dir=a.mano_dir,
                         objects=a.object, meshes=a.object_mesh)


def add_export(verbs) -> None:
    formats = "; ".join(f"{suffix} {what}" for suffix, what in FORMATS.items())
    p = verbs.add_parser("export",
                         help="write a solved hand motion for other tools (glTF, USD, BVH, CSV, C3D/TRC, MANO .npz)",
                         description=f"The suffix of --to chooses the format: {formats}.")
    p.add_argument("motion", help="hand motion .npz (handcap solve)")
    p.add_argument("--to", required=True, help="the file to write (.glb .usda .usdc .usd .bvh .csv .c3d .trc .npz)")
    p.add_argument("--units", choices=("cm", "mm", "m"), default="cm",
                   help="length unit of a BVH file (default %(default)s, as Blender and MotionBuilder take it)")
    p.add_argument("--object", action="append", metavar="MOTION",
                   help="an object motion .npz (track-object) to animate in a .glb or USD; repeat for several")
    p.add_argument("--object-mesh", action="append", metavar="MESH",
                   help="its mesh in its own frame (.obj .stl .ply ...), one per --object, in the same order")
    add_hand_model(p, default="the motion's")
    p.set_defaults(run=_cmd_export)
