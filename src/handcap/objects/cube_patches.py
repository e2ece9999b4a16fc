"""The 2x2x2 cube dressed in coded patches, as in DexterCap (Appendix B): a 4 x 4 patch of 5 mm squares on
each of its 24 facelets, every patch corner a named marker (issue 18).

The patches and their corner names are the session template's (:func:`handcap.patterns.session.
session_pattern`, object ``cube2x2``: patches ``U0`` ... ``B3``, corners ``cube2x2:U0_r0c0`` ...), so the
corners that ``handcap detect`` names and ``triangulate`` places are the cube's markers as they come. Facelet
``k`` of a face is the ``k``-th in reading order as the face is seen from outside, with the usual net (``U``
seen with ``F`` below it, ``D`` with ``F`` above, the side faces upright); a patch's row 0 is at the top of its
facelet, its column 0 at the left. :func:`patch_cube_table` gives the description; the shipped
``cube2x2-patches`` (:file:`objects/data/cube2x2-patches.toml`) is its output, written by
``tools/make_cube_patches.py``.
"""

from __future__ import annotations

import numpy as np

from handcap.objects.cube import FACES, HOME
from handcap.patterns.pattern import PITCH
from handcap.patterns.session import session_pattern

#: Right and up of each face as seen from outside (right x up = the outward normal).
FACE_AXES = {"F": ((1, 0, 0), (0, 1, 0)), "B": ((-1, 0, 0), (0, 1, 0)), "R": ((0, 0, -1), (0, 1, 0)),
             "L": ((0, 0, 1), (0, 1, 0)), "U": ((1, 0, 0), (0, 0, -1)), "D": ((1, 0, 0), (0, 0, 1))}
#: Half the cube's edge (metres): where the facelets lie.
HALF = 0.028
_CUBIE_NAMES = {tuple(h): "".join(pair[0] if h[axis] > 0 else pair[1]
                                   for pair, axis in (("UD", 1), ("FB", 2), ("RL", 0))) for h in HOME}


def cubie_name(place) -> str:
    """The shipped cube's name of the cubie at ``place`` (3,) signs, e.g. ``(1, 1, 1)`` -> ``UFR``."""
    return _CUBIE_NAMES[tuple(int(v) for v in place)]


def facelet_frame(face: str, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where facelet ``k`` of ``face`` lies on the cube at home (see the module docstring).

    Parameters
    ----------
    face : str
        One of ``URFDLB``.
    k : int
        0 to 3, in reading order as the face is seen from outside.

    Returns
    -------
    centre : ndarray (3,)
        The facelet's centre on the cube's surface (:data:`HALF` out), cube frame, metres.
    right, up : ndarray (3,)
        Its directions as seen from outside (a patch's columns run right, its rows down).
    """
    right, up = (np.array(v, dtype=float) for v in FACE_AXES[face])
    row, col = divmod(k, 2)
    return HALF * (np.array(FACES[face], dtype=float) + (col - 0.5) * right + (0.5 - row) * up), right, up


def patch_cube_table(*, pitch: float = PITCH) -> dict:
    """The description (as parsed TOML, metres) of the cube with a coded patch on every facelet.

    Parameters
    ----------
    pitch : float
        Side of a printed square, metres.

    Returns
    -------
    dict
        ``name``, ``units``, eight ``parts`` (named like ``cube2x2``'s cubies, in its order) with their
        patch corners, and the ``layers`` joint.
    """
    patches = {p.name: p for p in session_pattern(hands=(), objects=("cube2x2",), pitch=pitch).patches}
    markers = {cubie_name(h): {} for h in HOME}
    for face in FACES:
        for k in range(4):
            centre, right, up = facelet_frame(face, k)
            cubie = cubie_name(np.sign(centre))
            patch = patches[f"{face}{k}"]
            for (r, c), name in zip(patch.vertices(), patch.corner_names()):
                spot = centre + (c - patch.cols / 2) * pitch * right + (patch.rows / 2 - r) * pitch * up
                markers[cubie][name] = [round(float(v), 6) for v in spot]
    return {"name": "cube2x2-patches", "units": "m",
            "parts": [{"name": cubie_name(h), "markers": markers[cubie_name(h)]} for h in HOME],
            "joints": [{"type": "layers", "axes": {f: list(v) for f, v in FACES.items()}}]}
