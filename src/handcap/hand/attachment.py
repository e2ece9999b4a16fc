"""Where markers sit on the hand surface: ``MarkerAttachment`` (Eq. 1 of DexterCap).

A marker is fixed to one triangle of the hand mesh by barycentric coordinates
and lifted off the skin by an offset along the triangle's normal (the marker's
radius plus whatever it is mounted on):

    x_i = b_i1 v_i1 + b_i2 v_i2 + b_i3 v_i3 + offset_i n_i

so it follows the skin through any pose and shape of the hand model.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from array_api_compat import array_namespace

from handcap.core.errors import HandcapError, merge_warnings
from handcap.core.geometry import closest_points_on_mesh
from handcap.core.files import load_npz, read_warnings, save_npz, warnings_entry


@dataclass(frozen=True, eq=False)
class MarkerAttachment:
    """Triangle, barycentric coordinates and normal offset of every marker.

    Attributes
    ----------
    marker_names : tuple of str, length M
    triangles : ndarray (M,) int
        Face index into the hand model's ``faces``.
    barycentric : ndarray (M, 3)
    offset : ndarray (M,)
        Metres along the outward triangle normal.
    betas : ndarray (10,)
        Shape the attachment was made for.
    model : str
        ``"openhand"`` or ``"mano"``.
    side : str
    warnings : tuple of str
        One-line warnings from the calibration that made it (residuals, shape at its bounds).
    """

    marker_names: tuple[str, ...]
    triangles: np.ndarray
    barycentric: np.ndarray
    offset: np.ndarray
    betas: np.ndarray
    model: str = "openhand"
    side: str = "right"
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self):
        m = len(self.marker_names)
        raw = {"triangles": self.triangles, "barycentric": self.barycentric, "offset": self.offset,
               "betas": self.betas}
        arrays = {key: np.asarray(value) for key, value in raw.items()}
        not_real = [key for key, a in arrays.items() if a.dtype.kind not in "biuf"]
        if not_real:
            raise HandcapError(f"attachment entries {', '.join(not_real)} must hold real numbers")
        tri = arrays["triangles"].astype(np.int64)
        bary, offset, betas = (arrays[key].astype(np.float64) for key in ("barycentric", "offset", "betas"))
        if tri.shape != (m,) or bary.shape != (m, 3) or offset.shape != (m,) or betas.shape != (10,):
            raise HandcapError(f"attachment arrays do not match {m} markers: triangles {tri.shape}, "
                               f"barycentric {bary.shape}, offset {offset.shape}, betas {betas.shape}")
        # Issue 14: NaN here used to surface as a LinAlgError deep in the solver.
        bad = [name for name, a in (("barycentric", bary), ("offset", offset), ("betas", betas))
               if not np.isfinite(a).all()]
        if bad:
            raise HandcapError(f"the attachment has NaN or infinite values in {', '.join(bad)}; "
                               f"calibrate it again (handcap calibrate-markers)")
        if m and tri.min() < 0:
            raise HandcapError(f"the attachment has a negative triangle number ({tri.min()}); "
                               f"calibrate it again (handcap calibrate-markers)")
        object.__setattr__(self, "marker_names", tuple(str(n) for n in self.marker_names))
        object.__setattr__(self, "triangles", tri)
        object.__setattr__(self, "barycentric", bary)
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "betas", betas)
        object.__setattr__(self, "warnings", merge_warnings(self.warnings))

    def with_warnings(self, *messages) -> "MarkerAttachment":
        """The same attachment with ``messages`` (one-line strings) added to its warnings."""
        return replace(self, warnings=merge_warnings(self.warnings, messages))

    def __len__(self) -> int:
        return len(self.marker_names)

    @classmethod
    def from_layout(cls, layout, model, betas=None, *, offset: float | None = None) -> "MarkerAttachment":
        """Attach a layout's hand markers at their nominal positions.

        Each marker goes to the closest point of its own segment's triangles
        (segment-restricted closest point, as in DexterCap's calibration) on
        the model's flat average hand (``betas = 0``, where layout positions
        are given); the barycentric coordinates then carry the marker to the
        same spot of any shape. ``betas`` is recorded as the subject's shape.
        Object markers are skipped.

        Parameters
        ----------
        layout : MarkerLayout
            Positions are needed for every hand marker; mirrored to the model's side.
        model : HandModel
        betas : array (10,), optional
        offset : float, optional
            Skin-to-marker distance; the layout's ``marker_radius`` by default.
        """
        layout = layout.for_side(model.side)
        betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64)
        markers = layout.hand_markers
        missing = [m.name for m in markers if m.position is None]
        if missing:
            raise HandcapError(f"layout {layout.name!r} gives no position for {', '.join(missing[:5])}"
                               f"{' ...' if len(missing) > 5 else ''}; calibrate the attachment from a capture")
        faces = model.faces
        triangles = np.zeros(len(markers), int)
        bary = np.zeros((len(markers), 3))
        # Layout positions are made with the average hand; scale them with this shape.
        template = model.forward(np.zeros(10)).vertices
        for segment in sorted({m.segment for m in markers}):
            idx = [i for i, m in enumerate(markers) if m.segment == segment]
            seg_faces = model.segment_faces(segment)
            points = np.array([markers[i].position for i in idx])
            _, face0, bary0 = closest_points_on_mesh(points, template, faces[seg_faces])
            # The same barycentric spot on any other shape (exact at betas = 0).
            triangles[idx] = seg_faces[face0]
            bary[idx] = bary0
        radius = layout.marker_radius if offset is None else float(offset)
        return cls(tuple(m.name for m in markers), triangles, bary, np.full(len(markers), radius),
                   betas, model.name, model.side)

    def positions(self, vertices, faces):
        """Marker positions on a posed mesh.

        Parameters
        ----------
        vertices : array (..., V, 3)
            numpy or torch (differentiable).
        faces : ndarray (F, 3)

        Returns
        -------
        positions : array (..., M, 3)
        """
        xp = array_namespace(vertices)
        tri_idx = np.asarray(faces)[self.triangles]  # (M, 3)
        device = getattr(vertices, "device", None)
        corners = [xp.take(vertices, xp.asarray(tri_idx[:, k], device=device), axis=-2) for k in range(3)]
        bary = xp.asarray(self.barycentric, dtype=vertices.dtype, device=device)
        offset = xp.asarray(self.offset, dtype=vertices.dtype, device=device)
        on_skin = corners[0] * bary[:, 0:1] + corners[1] * bary[:, 1:2] + corners[2] * bary[:, 2:3]
        normal = xp.linalg.cross(corners[1] - corners[0], corners[2] - corners[0])
        normal = normal / xp.sqrt(xp.sum(normal * normal, axis=-1, keepdims=True))
        return on_skin + offset[:, None] * normal

    def normals(self, vertices, faces) -> np.ndarray:
        """Outward unit normals (..., M, 3) of the markers' triangles (numpy).

        Parameters
        ----------
        vertices : array_like of shape (..., V, 3)
            Posed mesh vertices, metres.
        faces : array_like of shape (F, 3) int
            The hand model's faces (their winding makes the normal outward).

        Returns
        -------
        ndarray of shape (..., M, 3)
            Unit vectors (no unit), one per marker, in the attachment's marker order.
        """
        tri = np.asarray(vertices)[..., np.asarray(faces)[self.triangles], :]
        n = np.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def subset(self, names) -> "MarkerAttachment":
        """The attachment of the markers ``names`` only, in that order (shape, model, side and warnings kept).

        Parameters
        ----------
        names : sequence of str
            Marker names, each one of ``marker_names``.

        Returns
        -------
        MarkerAttachment

        Raises
        ------
        HandcapError
            A name the attachment does not hold (all of them named).
        """
        unknown = [n for n in names if n not in self.marker_names]
        if unknown:
            raise HandcapError(f"the attachment has no marker {', '.join(map(repr, unknown))}; it holds "
                               f"{', '.join(self.marker_names)}")
        idx = [self.marker_names.index(n) for n in names]
        return MarkerAttachment(tuple(names), self.triangles[idx], self.barycentric[idx], self.offset[idx],
                                self.betas, self.model, self.side, self.warnings)

    def save(self, path) -> None:
        """Write ``attachment.npz`` (File contract of DESIGN.md)."""
        save_npz(path, {"kind": np.array("attachment"), "marker_names": np.array(self.marker_names, dtype=str),
                        "triangles": self.triangles, "barycentric": self.barycentric, "offset": self.offset,
                        "betas": self.betas, "model": np.array(self.model), "side": np.array(self.side),
                        **warnings_entry(self.warnings)})

    @classmethod
    def load(cls, path) -> "MarkerAttachment":
        """Read an ``attachment.npz`` written by :meth:`save` (File contract of DESIGN.md).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        MarkerAttachment
            Offsets in metres; ``model`` and ``side`` default to ``"openhand"`` and ``"right"`` when absent.

        Raises
        ------
        HandcapError
            The file is unreadable, lacks an entry, or its arrays do not match.
        """
        arrays = load_npz(path, ("marker_names", "triangles", "barycentric", "offset", "betas"), "attachment .npz")
        try:
            names = tuple(str(n) for n in np.atleast_1d(arrays["marker_names"]))
            return cls(names, arrays["triangles"], arrays["barycentric"], arrays["offset"], arrays["betas"],
                       str(arrays.get("model", "openhand")), str(arrays.get("side", "right")), read_warnings(arrays))
        except HandcapError as err:
            raise HandcapError(f"{path}: {err}") from None

