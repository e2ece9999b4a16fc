"""The 10 shape values of a subject's hand: from a 3D scan or from measured lengths.

(The third way, jointly with the marker attachment from a calibration take,
is ``calibrate_attachment(..., fit_shape=True)``.)
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from handcap.core.errors import HandcapError
from handcap.core.geometry import closest_points_on_mesh
from handcap.core.rotations import axis_angle_from_matrix
from handcap.objects.rigid import kabsch

MEASUREMENTS = ("hand_length", "palm_length", "hand_breadth", "thumb_length", "index_length", "middle_length",
                "ring_length", "pinky_length")
_TIPS = {"thumb": (14, 16), "index": (1, 17), "middle": (4, 18), "ring": (10, 19), "pinky": (7, 20)}


def hand_measurements(hand, betas=None) -> dict:
    """Lengths of the flat hand (metres), defined on the model so anyone can measure them too.

    * ``hand_length``: wrist joint to the tip of the middle finger (the
      anthropometric hand length: wrist crease to fingertip);
    * ``palm_length``: wrist joint to the middle finger's MCP joint;
    * ``hand_breadth``: width of the palm skin across the MCP joints (the
      anthropometric breadth at the metacarpal heads), measured on the mesh
      (thumb excluded) within 4 mm of the mean MCP line;
    * ``<finger>_length``: MCP joint to fingertip (for the thumb, its MCP
      joint to its tip).

    Parameters
    ----------
    hand : HandModel
    betas : ndarray (10,), optional
        Shape values; zeros (the average hand) by default.

    Returns
    -------
    dict of str to float
        The lengths of :data:`MEASUREMENTS`, metres (``hand_breadth`` NaN when no skin lies in the band).
    """
    betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64)
    vertices, joints, tips = hand.rest(betas)
    j = np.concatenate([joints, tips])
    distal = j[4] - j[0]
    distal /= np.linalg.norm(distal)
    radial = j[1] - j[7]
    radial -= distal * (radial @ distal)
    radial /= np.linalg.norm(radial)
    thumb = [hand.segment_id(f"thumb_{s}") for s in ("proximal", "middle", "distal")]
    skin = vertices[~np.isin(hand.segment_of_vertex, thumb)]
    mcp_line = ((j[[1, 4, 7, 10]] - j[0]) @ distal).mean()
    band = skin[np.abs((skin - j[0]) @ distal - mcp_line) < 0.004]
    across = (band - j[0]) @ radial
    out = {"hand_length": float(np.linalg.norm(j[18] - j[0])), "palm_length": float(np.linalg.norm(j[4] - j[0])),
           "hand_breadth": float(across.max() - across.min()) if len(band) else float("nan")}
    for finger, (base, tip) in _TIPS.items():
        out[f"{finger}_length"] = float(np.linalg.norm(j[tip] - j[base]))
    return out


def betas_from_measurements(hand, prior: float = 0.01, **lengths) -> np.ndarray:
    """Shape values that reproduce measured lengths (metres; names from :data:`MEASUREMENTS`).

    Least squares on the relative length errors, with a pull of ``prior`` per
    unit towards the average hand, so values the measurements do not
    determine stay at zero.

    Parameters
    ----------
    hand : HandModel
    prior : float
        Weight of each shape value's residual against the relative length errors (no unit).
    **lengths : float
        Measured lengths, metres, each between 5 mm and 0.5 m, named as in :data:`MEASUREMENTS`
        (see :func:`hand_measurements` for their definitions).

    Returns
    -------
    ndarray (10,)
        Shape values, bounded to [-4, 4].

    Raises
    ------
    HandcapError
        An unknown name, no length, or a length that is not a hand length in metres.

    Examples
    --------
    >>> betas_from_measurements(OpenHand(), hand_length=0.195, hand_breadth=0.088)  # doctest: +SKIP
    """
    unknown = sorted(set(lengths) - set(MEASUREMENTS))
    if unknown:
        raise HandcapError(f"unknown measurement {', '.join(unknown)}; use {', '.join(MEASUREMENTS)}")
    if not lengths:
        raise HandcapError("give at least one measured length")
    for name, value in lengths.items():
        if not (np.isfinite(value) and 0.005 < value < 0.5):
            raise HandcapError(f"{name} = {value} m is not a hand length in metres")
    names = sorted(lengths)
    goal = np.array([lengths[n] for n in names])

    def residual(betas):
        m = hand_measurements(hand, betas)
        return np.concatenate([(np.array([m[n] for n in names]) - goal) / goal, prior * betas])

    return least_squares(residual, np.zeros(10), bounds=(-4, 4), diff_step=1e-4).x


def betas_from_scan(hand, scan_points, *, fit_pose: bool = True, iterations: int = 20, max_points: int = 4000,
                    seed: int = 0, prior: float = 0.0001) -> tuple[np.ndarray, float]:
    """Shape values from a 3D scan of the hand, by minimising the Chamfer distance.

    The scan (points, or the vertices of a scan mesh, metres) is matched to
    the model's surface in alternation: correspondences both ways (every scan
    point to the closest point of the model's surface; every model vertex to
    its nearest scan point, measured along the vertex normal so the spacing of
    scan points does not bias the size: a symmetric Chamfer distance), then
    the shape values, the
    rigid placement and (``fit_pose``) the finger angles are refined by least
    squares with those correspondences fixed, and again. The scan should show
    an open, roughly flat hand, as scanning apps ask for.

    Parameters
    ----------
    hand : HandModel
    scan_points : ndarray (N, 3)
    fit_pose : bool
        Also fit the 27 finger angles (a scan's fingers are never exactly flat).
    iterations : int
        Correspondence rounds.
    max_points : int
        Scan points kept (random subset) for speed.
    prior : float
        Pull towards the average hand, metres per unit of shape value.

    Returns
    -------
    betas : ndarray (10,)
    chamfer : float
        Final mean symmetric Chamfer distance, metres.
    """
    scan = np.asarray(scan_points, dtype=np.float64).reshape(-1, 3)
    scan = scan[np.isfinite(scan).all(axis=1)]
    if len(scan) < 100:
        raise HandcapError(f"a scan needs at least 100 points, got {len(scan)}")
    rng = np.random.default_rng(seed)
    if len(scan) > max_points:
        scan = scan[rng.choice(len(scan), max_points, replace=False)]
    tree = cKDTree(scan)
    # Start: the average flat hand placed on the scan by its principal axes (then refined).
    template = hand.forward().vertices
    rot0, trans0 = _principal_alignment(template, scan)
    params = np.concatenate([np.zeros(10), _rotvec(rot0), trans0, np.zeros(27 if fit_pose else 0)])

    def unpack(p):
        return p[:10], p[10:13], p[13:16], (p[16:] if fit_pose else None)

    def model_vertices(p):
        betas, orient, transl, phi = unpack(p)
        return hand.forward(betas, orient, phi=phi, transl=transl).vertices

    chamfer = np.inf
    for _ in range(iterations):
        verts = model_vertices(params)
        _, to_scan = tree.query(verts)  # model vertex -> nearest scan point, measured along the vertex normal
        normals = _vertex_normals(verts, hand.faces)
        # scan point -> closest point of the model's surface (triangle and barycentric coordinates)
        _, face, bary = closest_points_on_mesh(scan, verts, hand.faces)
        corners = hand.faces[face]
        w_model, w_scan = 1.0 / np.sqrt(len(verts)), 1.0 / np.sqrt(len(scan))

        def residual(p):
            v = model_vertices(p)
            # This round's correspondences; the function is used within this round only.
            r_model = ((v - scan[to_scan]) * normals).sum(axis=1, keepdims=True) * w_model  # noqa: B023
            r_scan = (np.einsum("nk,nki->ni", bary, v[corners]) - scan) * w_scan  # noqa: B023
            r = np.concatenate([r_model.ravel(), r_scan.ravel()])
            extra = [prior * p[:10]]
            if fit_pose:
                extra.append(0.002 * p[16:])
            return np.concatenate([r.ravel(), *extra])

        params = least_squares(residual, params, diff_step=1e-4, max_nfev=30).x
        verts = model_vertices(params)
        surface, _, _ = closest_points_on_mesh(scan, verts, hand.faces)
        new = 0.5 * (tree.query(verts)[0].mean() + np.linalg.norm(surface - scan, axis=1).mean())
        if chamfer - new < 1e-5:
            chamfer = min(chamfer, new)
            break
        chamfer = new
    return params[:10], float(chamfer)


def _vertex_normals(vertices, faces) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3)."""
    tri = vertices[faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, faces[:, k], face_n)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-15)


def _principal_alignment(template, scan):
    """Rotation and translation putting the template's principal axes on the scan's (best of the sign choices)."""
    def axes(x):
        centred = x - x.mean(axis=0)
        _, _, vt = np.linalg.svd(centred, full_matrices=False)
        vt[2] = np.cross(vt[0], vt[1])  # right-handed
        return vt
    a, b = axes(template), axes(scan)
    best, best_err = None, np.inf
    tree = cKDTree(scan)
    for signs in np.array(np.meshgrid([1, -1], [1, -1])).reshape(2, -1).T:
        sa = np.diag([signs[0], signs[1], signs[0] * signs[1]]) @ a
        rot = b.T @ sa
        if np.linalg.det(rot) < 0:
            continue
        trans = scan.mean(axis=0) - rot @ template.mean(axis=0)
        err = tree.query(template @ rot.T + trans)[0].mean()
        if err < best_err:
            best, best_err = (rot, trans), err
    rot, trans = best
    # Polish with one round of rigid ICP.
    moved = template @ rot.T + trans
    _, idx = tree.query(moved)
    r2, t2 = kabsch(moved, scan[idx])
    return r2 @ rot, r2 @ trans + t2


def _rotvec(rot) -> np.ndarray:
    return axis_angle_from_matrix(rot)


__all__ = ["MEASUREMENTS", "betas_from_measurements", "betas_from_scan", "hand_measurements"]
