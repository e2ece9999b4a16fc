"""Printed patches on the standard objects: where each face's patch of the session template lies.

``handcap pattern`` gives every standard object one patch per face (:data:`handcap.patterns.session.OBJECT_PATCHES`):
a 4 x 4 patch on each face of the cuboid, a 3 x 8 band around the cylinder and a 3 x 3 patch on each of its
ends, four 3 x 3 caps on the sphere. Here each is laid on its object as a printed sheet is taped on: centred on
its face, at the printed pitch, flat on a flat face, wrapped around the cylinder (the band's columns run
around it, each square keeping its printed width along the surface), and on the sphere mapped so that
distances from the patch's centre keep their printed length (a flat sheet cannot lie on a sphere without
creases; the squares there stretch across by at most 0.5 % at the caps' corners). A patch floats
:data:`LIFT` over the surface (paper and tape), which also keeps it in front of the object's own mesh when
both are drawn.

The 2x2x2 cube's 24 facelet patches (:func:`cube_patch_grids`) lie where the tracker's description
``cube2x2-patches`` puts their corners (:mod:`handcap.objects.cube_patches`), each on its cubie, and turn with it.

Rows and columns are placed as the renderer reads them (:mod:`handcap.synth.images`): seen from outside,
columns run right and rows down, so the outward normal is row x column.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.objects.cube import HOME
from handcap.objects.cube_patches import facelet_frame

#: Height of a printed patch over its object's surface, metres.
LIFT = 0.0002
#: Objects whose patches :func:`object_patch_grids` places.
PATCHED = ("cuboid", "cylinder", "sphere")
#: Sample steps per square of a patch's grid: a curved patch is drawn as a mesh this fine.
SUBDIVISION = 4
#: The sphere's four caps point to the corners of a regular tetrahedron.
_CAPS = np.array([(1.0, 1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0)]) / np.sqrt(3.0)


def patch_coords(patch, subdivision: int = SUBDIVISION) -> tuple[np.ndarray, np.ndarray]:
    """Grid coordinates of the samples of a patch: its printed margin (half a square) and ``subdivision`` steps
    per square, every integer among them.

    Parameters
    ----------
    patch : Patch
    subdivision : int

    Returns
    -------
    rows : ndarray (rows * subdivision + 3,)
    cols : ndarray (cols * subdivision + 3,)
    """
    def axis(n: int) -> np.ndarray:
        return np.r_[-0.5, np.arange(n * subdivision + 1) / subdivision, n + 0.5]
    return axis(patch.rows), axis(patch.cols)


def _face_frame(obj, face: str) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """How a face's patch lies: its shape (``flat``, ``band`` or ``cap``), its centre on the surface, its
    outward normal and its columns' direction (object frame)."""
    size = np.asarray(obj.size, dtype=np.float64)
    if obj.kind == "cuboid" and len(face) == 2 and face[0] in "xyz" and face[1] in "pn":
        axis, sign = "xyz".index(face[0]), 1.0 if face[1] == "p" else -1.0
        normal, across = np.zeros(3), np.zeros(3)
        normal[axis], across[(axis + 1) % 3] = sign, 1.0
        return "flat", normal * size[axis], normal, across
    if obj.kind == "cylinder" and face in ("band", "top", "bottom"):
        if face == "band":
            return "band", np.array([size[0], 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
        sign = 1.0 if face == "top" else -1.0
        return "flat", np.array([0.0, 0.0, sign * size[2]]), np.array([0.0, 0.0, sign]), np.array([1.0, 0.0, 0.0])
    if obj.kind == "sphere" and face.startswith("cap") and face[3:].isdigit() and int(face[3:]) < len(_CAPS):
        normal = _CAPS[int(face[3:])]
        across = np.cross([0.0, 0.0, 1.0], normal)
        return "cap", normal * size[0], normal, across / np.linalg.norm(across)
    raise HandcapError(f"object {obj.name!r} ({obj.kind}) has no face {face!r} to tape a patch on; the standard "
                       f"objects' faces are those of handcap pattern ({', '.join(PATCHED)})")


def object_patch_grids(obj, patches, pitch: float, coords=None) -> list[np.ndarray]:
    """Where the printed patches of an object lie on it (see the module docstring).

    Parameters
    ----------
    obj : SynthObject
        A cuboid, cylinder or sphere (:data:`PATCHED`).
    patches : sequence of Patch
        The object's patches; each patch's name is its face (``xp``, ``band``, ``cap0``...).
    pitch : float
        Printed side of a square, metres.
    coords : sequence of (ndarray, ndarray), optional
        Per patch, the grid coordinates of its sample rows and columns (default :func:`patch_coords`).

    Returns
    -------
    list of ndarray (n_rows, n_cols, 3)
        The samples in the object's frame, metres, :data:`LIFT` over the surface.

    Raises
    ------
    HandcapError
        An object that is not patched here, a face it does not have, or a patch larger than its face.
    """
    if obj.kind not in PATCHED:
        raise HandcapError(f"object {obj.name!r}: patches are placed on {', '.join(PATCHED)}, not on a {obj.kind}")
    size = np.asarray(obj.size, dtype=np.float64)
    out = []
    for k, patch in enumerate(patches):
        shape, centre, normal, across = _face_frame(obj, patch.name)
        down = np.cross(across, normal)  # rows: row x column is the outward normal
        r, c = patch_coords(patch) if coords is None else (np.asarray(v, dtype=np.float64) for v in coords[k])
        rr, cc = np.meshgrid((r - patch.rows / 2) * pitch, (c - patch.cols / 2) * pitch, indexing="ij")
        if shape == "flat":
            reach = np.abs(rr[..., None] * down + cc[..., None] * across).max(axis=(0, 1))
            room = np.where(np.abs(normal) > 0.5, np.inf, size)
            if obj.kind == "cylinder":
                room = np.where(np.abs(normal) > 0.5, np.inf, size[0] / np.sqrt(2.0))
            if (reach > room + 1e-9).any():
                raise HandcapError(f"patch {patch.owner}:{patch.name} ({patch.rows} x {patch.cols} squares of "
                                   f"{1000 * pitch:g} mm) is larger than the {obj.kind}'s face")
            grid = centre + rr[..., None] * down + cc[..., None] * across + LIFT * normal
        elif shape == "band":
            radius = size[0]
            if patch.cols * pitch >= 2 * np.pi * radius or patch.rows * pitch > 2 * size[2]:
                raise HandcapError(f"patch {patch.owner}:{patch.name} does not fit around the {obj.kind}")
            angle = cc / radius  # each square keeps its printed width along the surface
            grid = np.stack([(radius + LIFT) * np.cos(angle), (radius + LIFT) * np.sin(angle), -rr], axis=-1)
        else:
            radius = size[0]
            offset = rr[..., None] * down + cc[..., None] * across
            far = np.linalg.norm(offset, axis=-1, keepdims=True)
            if far.max() >= 0.5 * np.pi * radius:
                raise HandcapError(f"patch {patch.owner}:{patch.name} does not fit on a cap of the {obj.kind}")
            toward = offset / np.maximum(far, 1e-12)
            grid = (radius + LIFT) * (np.cos(far / radius) * normal + np.sin(far / radius) * toward)
        out.append(grid)
    return out


def cube_patch_grids(patches, pitch: float, coords=None) -> tuple[list[np.ndarray], np.ndarray]:
    """Where the 2x2x2 cube's facelet patches lie on it at home, and the cubie each is on.

    Parameters
    ----------
    patches : sequence of Patch
        The cube's patches (``U0`` ... ``B3``: face, then the facelet in reading order).
    pitch : float
        Printed side of a square, metres.
    coords : sequence of (ndarray, ndarray), optional
        Per patch, the grid coordinates of its sample rows and columns (default :func:`patch_coords`).

    Returns
    -------
    grids : list of ndarray (n_rows, n_cols, 3)
        The samples in the cube's frame at home, metres; the printed corners where ``cube2x2-patches`` puts them.
    cubies : ndarray (P,) int
        Index of each patch's cubie in :data:`handcap.objects.cube.HOME`.

    Raises
    ------
    HandcapError
        A patch that is not a facelet, or one larger than its facelet.
    """
    grids, cubies = [], []
    for k, patch in enumerate(patches):
        face, index = patch.name[:1], patch.name[1:]
        if face not in "URFDLB" or len(face) != 1 or index not in ("0", "1", "2", "3"):
            raise HandcapError(f"patch {patch.owner}:{patch.name} is not a facelet of the 2x2x2 cube (U0 ... B3)")
        centre, right, up = facelet_frame(face, int(index))
        if (max(patch.rows, patch.cols) + 1) * pitch > 2 * abs(centre).min():
            raise HandcapError(f"patch {patch.owner}:{patch.name} ({patch.rows} x {patch.cols} squares of "
                               f"{1000 * pitch:g} mm) is larger than a facelet of the cube")
        r, c = patch_coords(patch) if coords is None else (np.asarray(v, dtype=np.float64) for v in coords[k])
        rr, cc = np.meshgrid(patch.rows / 2 - r, c - patch.cols / 2, indexing="ij")
        grids.append(centre + pitch * (cc[..., None] * right + rr[..., None] * up))
        cubies.append(int(np.flatnonzero((HOME == np.sign(centre)).all(axis=1))[0]))
    return grids, np.array(cubies, dtype=int)
