"""Meshes and point clouds of scans and objects (any format trimesh reads: PLY, OBJ, STL, OFF, GLB, ...)."""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import existing_file, load_npz


def read_mesh(path, what: str = "mesh"):
    """A ``trimesh.Trimesh`` read from ``path`` as it stands (not processed), with one clear line on failure.

    Parameters
    ----------
    path : str or Path
        Any mesh format trimesh reads.
    what : str
        What the file should be, for the message.

    Returns
    -------
    trimesh.Trimesh
        Vertices (V, 3) in the file's own unit (no conversion here), faces (F, 3).

    Raises
    ------
    HandcapError
        A missing file, or one trimesh cannot read.
    """
    import trimesh  # heavy: loaded only when a mesh is read

    path = existing_file(path)
    try:
        return trimesh.load(path, force="mesh", process=False)
    except Exception as err:  # trimesh's loaders raise many types (ValueError, KeyError, struct.error, ...)
        raise HandcapError(f"{path}: not a readable {what} ({' '.join(str(err).split())[:120]})") from None


def read_scan_points(path) -> np.ndarray:
    """The points (N, 3) of a scan, metres: ``points`` of an ``.npz``, or the vertices of a mesh or point cloud.

    Raises
    ------
    HandcapError
        A missing or unreadable file, or one that holds no points.
    """
    path = existing_file(path)
    if path.suffix.lower() == ".npz":
        return load_npz(path, ("points",), "scan .npz (points)")["points"]
    vertices = np.asarray(getattr(read_mesh(path, "mesh or point cloud"), "vertices", []), dtype=float)
    if vertices.ndim != 2 or len(vertices) == 0:
        raise HandcapError(f"{path}: holds no points")
    return vertices


__all__ = ["read_mesh", "read_scan_points"]
