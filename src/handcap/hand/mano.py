"""ManoHand: a user's own MANO model files, read without chumpy.

MANO (Romero et al. 2017, doi:10.1145/3130800.3130883) is licensed: handcap
never ships or downloads ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl``; the user
points :meth:`ManoHand.load` at the files they downloaded from
https://mano.is.tue.mpg.de.

Reading the files
-----------------
The files are Python-2 pickles that name ``chumpy`` and old ``scipy.sparse``
classes. A pickle can run any function it names, so they are read with
:func:`handcap.hand.mano_pickle.read_pickle`, which builds only numpy arrays,
plain chumpy arrays (their state holds the array in key ``x``) and CSC/CSR
sparse matrices (rebuilt as dense arrays), and refuses every other name
(``os.system``, ``builtins.eval``, ...) with a
:class:`~handcap.core.errors.HandcapError`. Neither chumpy nor the pickled scipy
module paths need to be importable. This module checks the arrays and builds
the model.

Conventions
-----------
``hand_pose`` is relative to the flat hand, as MANO with
``flat_hand_mean=True``: the file's ``hands_mean`` is not added. Tips are
MANO's usual fingertip vertices 745, 317, 444, 556, 673 (thumb, index,
middle, ring, pinky) of the rest mesh; like every handcap model's tips they
then move rigidly with their distal segment, so a posed tip may differ by a
fraction of a millimetre from the skinned vertex when that vertex is not
weighted wholly to the distal joint or has pose blend offsets.

The left model's shape blend shapes
-----------------------------------
``MANO_LEFT.pkl`` is the right model mirrored in x, but its
``shapedirs[:, 0, :]`` (the x components) were left unmirrored, so equal
``betas`` give left and right hands of different shapes (smplx issue #48,
https://github.com/vchoutas/smplx/issues/48). :meth:`ManoHand.load` negates
them when the file has the error:

* with ``MANO_RIGHT.pkl`` beside the left file: the error is present when
  ``sum(abs(left.shapedirs[:, 0, :] - right.shapedirs[:, 0, :])) < 1`` (the
  x components were copied instead of negated);
* with the left file alone: MANO's first shape component is dominated by
  overall hand size, a displacement along ``v - centroid`` of one sign in x,
  y and z. Let ``r_d`` be the correlation over the vertices of
  ``shapedirs[:, d, 0]`` with the centred ``v_template[:, d]``. Mirroring
  keeps each ``r_d`` (both factors change sign in x), so in a correct left
  file, as in the right one, ``r_x``, ``r_y``, ``r_z`` share one sign; the
  unmirrored x components turn ``r_x`` around. The error is present when
  ``r_y`` and ``r_z`` agree in sign and ``r_x`` has the other sign. When the
  test cannot decide (``r_y``, ``r_z`` of different signs or any ``|r_d|``
  below 0.3) loading fails and asks for the right file or for
  ``fix_left_shapedirs=True/False``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from array_api_compat import array_namespace

from handcap.core.errors import HandcapError
from handcap.core.motion import check_side
from handcap.hand.anatomy import PARENTS, joint_frames
from handcap.hand.mano_pickle import plain_value, read_pickle
from handcap.hand.model import HandModel

#: Vertex ids of the fingertips in MANO's mesh: thumb, index, middle, ring, pinky.
TIP_VERTICES = np.array([745, 317, 444, 556, 673])
N_VERTICES = 778
FILE_NAMES = {"right": "MANO_RIGHT.pkl", "left": "MANO_LEFT.pkl"}
#: Smallest |correlation| the left-file test of the module docstring trusts.
_MIN_CORRELATION = 0.3


# -- the model -------------------------------------------------------------------------
def _model_array(params: Mapping, key: str, shape: tuple, source: str) -> np.ndarray:
    """``params[key]`` as a read-only array of ``shape`` (None: any length), checked."""
    if key not in params:
        raise HandcapError(f"{source} has no {key!r}; is it a MANO model file (MANO_RIGHT.pkl/MANO_LEFT.pkl)?")
    # Converted only when needed, so an unused chumpy expression does no harm.
    value = plain_value(params[key], f"{source}: {key}")
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise HandcapError(f"{source}: {key} is not a numeric array (got {type(value).__name__})") from None
    want = "(" + ", ".join("N" if n is None else str(n) for n in shape) + ")"
    if array.ndim != len(shape) or any(n is not None and n != m for n, m in zip(shape, array.shape)):
        raise HandcapError(f"{source}: {key} must have shape {want}, got {array.shape}")
    if not np.isfinite(array).all():
        raise HandcapError(f"{source}: {key} has NaN or infinite values")
    array.setflags(write=False)
    return array


def _integer_array(params: Mapping, key: str, shape: tuple, source: str) -> np.ndarray:
    array = _model_array(params, key, shape, source)
    if not np.array_equal(array, np.round(array)):
        raise HandcapError(f"{source}: {key} must hold integers")
    array = array.astype(np.int64)
    array.setflags(write=False)
    return array


class ManoHand(HandModel):
    """A MANO hand from the user's own model file.

    Most users call :meth:`ManoHand.load`. The constructor takes the model's
    arrays under MANO's key names, e.g. from a file converted to ``.npz``.

    Parameters
    ----------
    params : mapping
        MANO keys: ``v_template`` (778, 3) metres, ``f`` (F, 3) vertex ids,
        ``weights`` (778, 16), ``J_regressor`` (16, 778), ``shapedirs``
        (778, 3, 10), ``posedirs`` (778, 3, 135), ``kintree_table`` (2, 16).
        Other keys are ignored. Arrays are copied; for a left model,
        ``shapedirs`` must already be free of the error described in the
        module docstring (:meth:`load` repairs it).
    side : {"right", "left"}
    source : str
        Name used in error messages.

    Attributes
    ----------
    template_vertices : ndarray (778, 3)
    faces : ndarray (F, 3)
    weights : ndarray (778, 16)
    joint_regressor : ndarray (16, 778)
    shapedirs : ndarray (778, 3, 10)
    posedirs : ndarray (778, 3, 135)
    frames : ndarray (15, 3, 3)
        Anatomical joint frames of the average (``betas = 0``) flat hand.
    fixed_left_shapedirs : bool
        Whether :meth:`load` negated ``shapedirs[:, 0, :]`` of a left file.

    Notes
    -----
    ``hand_pose`` is relative to the flat hand (MANO's ``flat_hand_mean=True``):
    ``hand_pose = 0`` is the file's template, and the file's ``hands_mean`` is
    not added. Add ``hands_mean`` yourself to use parameters fitted with
    ``flat_hand_mean=False``.

    Raises
    ------
    HandcapError
        If a key is missing, an array has the wrong shape or non-finite values,
        a face names a vertex that does not exist, a weight row does not sum to
        one or ``kintree_table`` is not MANO's hand tree.
    """

    name = "mano"

    def __init__(self, params: Mapping, side: str = "right", *, source: str = "MANO model"):
        self.side = check_side(side)
        v = N_VERTICES
        self.template_vertices = _model_array(params, "v_template", (v, 3), source)
        self.faces = _integer_array(params, "f", (None, 3), source)
        self.weights = _model_array(params, "weights", (v, 16), source)
        self.joint_regressor = _model_array(params, "J_regressor", (16, v), source)
        self.shapedirs = _model_array(params, "shapedirs", (v, 3, 10), source)
        self.posedirs = _model_array(params, "posedirs", (v, 3, 135), source)
        kintree = _integer_array(params, "kintree_table", (2, 16), source)
        if len(self.faces) == 0 or self.faces.min() < 0 or self.faces.max() >= v:
            raise HandcapError(f"{source}: f must index the {v} vertices, got values "
                               f"{self.faces.min(initial=0)}..{self.faces.max(initial=0)}")
        sums = self.weights.sum(axis=1)
        off = np.flatnonzero(np.abs(sums - 1.0) > 1e-3)
        if off.size:
            bad = int(off[0])
            raise HandcapError(f"{source}: weights of vertex {bad} sum to {sums[bad]:.4g}, not 1")
        # Column i is joint kintree[1, i], its parent the joint kintree[0, i] (root: any value).
        if not (np.array_equal(kintree[1], np.arange(16)) and np.array_equal(kintree[0, 1:], PARENTS[1:])):
            raise HandcapError(f"{source}: kintree_table parents {kintree[0, 1:].tolist()} are not "
                               f"MANO's hand tree {PARENTS[1:].tolist()}")
        self.fixed_left_shapedirs = False
        # Flattened blend shapes: (V*3, 10) and (V*3, 135), rows vertex-major as in MANO.
        self._shape_basis = self.shapedirs.reshape(v * 3, 10)
        self._pose_basis = self.posedirs.reshape(v * 3, 135)
        _, joints, tips = self.rest(np.zeros(10))
        self.frames = joint_frames(joints, tips, self.is_right)
        self.frames.setflags(write=False)

    def __repr__(self) -> str:
        return f"ManoHand(side={self.side!r}, {self.n_vertices} vertices)"

    @classmethod
    def load(cls, path, side: str = "right", *, fix_left_shapedirs: bool | None = None) -> ManoHand:
        """Load ``MANO_RIGHT.pkl`` or ``MANO_LEFT.pkl``.

        Parameters
        ----------
        path : str or Path
            A ``.pkl`` file, or a folder holding ``MANO_RIGHT.pkl`` /
            ``MANO_LEFT.pkl`` (``mano_v1_2/models`` of the MANO download).
        side : {"right", "left"}
        fix_left_shapedirs : bool, optional
            Left hand only: negate ``shapedirs[:, 0, :]`` (True) or keep it
            (False). By default the file is tested as described in the module
            docstring, against ``MANO_RIGHT.pkl`` when it lies beside the left
            file.

        Returns
        -------
        ManoHand

        Raises
        ------
        HandcapError
            If the file is missing or unreadable, names a side other than
            ``side``, or is not a MANO model (see :class:`ManoHand`).
        """
        side = check_side(side)
        path = Path(path).expanduser()
        if path.is_dir():
            folder, file = path, path / FILE_NAMES[side]
            if not file.is_file():
                raise HandcapError(f"no {FILE_NAMES[side]} in {path}; download MANO from "
                                   "https://mano.is.tue.mpg.de and give its models folder")
        elif path.is_file():
            folder, file = path.parent, path
            other_side = "left" if side == "right" else "right"
            if path.name.upper() == FILE_NAMES[other_side].upper():
                raise HandcapError(f"{path.name} is the {other_side} hand but side={side!r}; "
                                   f"pass side={other_side!r}")
        else:
            raise HandcapError(f"MANO model {path} does not exist; give MANO_RIGHT.pkl/MANO_LEFT.pkl "
                               "or the folder holding them")
        if fix_left_shapedirs is not None and side == "right":
            raise HandcapError("fix_left_shapedirs applies to the left hand only; leave it out for side='right'")
        params = read_pickle(file)
        fixed = False
        if side == "left":
            # Checked here so that the messages name the file before the shapedirs test reads it.
            shapedirs = _model_array(params, "shapedirs", (N_VERTICES, 3, 10), file.name)
            if fix_left_shapedirs is None:
                fix_left_shapedirs = _left_shapedirs_have_error(
                    shapedirs, _model_array(params, "v_template", (N_VERTICES, 3), file.name),
                    folder / FILE_NAMES["right"], file.name)
            if fix_left_shapedirs:
                shapedirs = shapedirs.copy()
                shapedirs[:, 0, :] *= -1.0
                params = {**params, "shapedirs": shapedirs}
                fixed = True
        hand = cls(params, side, source=file.name)
        hand.fixed_left_shapedirs = fixed
        return hand

    # -- HandModel ---------------------------------------------------------------------
    def _shape_rest(self, betas):
        """Flat hand for shape ``betas`` (MANO's shape blend shapes and joint regressor).

        Parameters
        ----------
        betas : array (..., 10)

        Returns
        -------
        vertices : array (..., 778, 3)
            ``v_template + shapedirs @ betas``, metres.
        joints : array (..., 16, 3)
            ``J_regressor @ vertices``.
        tips : array (..., 5, 3)
            Vertices :data:`TIP_VERTICES` (thumb, index, middle, ring, pinky).
        """
        xp = array_namespace(betas)
        c = lambda a: self.constant(a, betas)  # noqa: E731
        offsets = xp.matmul(betas, c(self._shape_basis).T)  # (..., V*3)
        vertices = c(self.template_vertices) + xp.reshape(offsets, betas.shape[:-1] + (N_VERTICES, 3))
        joints = xp.matmul(c(self.joint_regressor), vertices)
        tips = xp.take(vertices, xp.asarray(TIP_VERTICES, device=getattr(betas, "device", None)), axis=-2)
        return vertices, joints, tips

    def pose_corrective(self, rotations):
        """MANO's pose blend shapes: ``posedirs @ vec(R_j - I)`` over joints 1..15.

        Parameters
        ----------
        rotations : array (..., 16, 3, 3)
            Local joint rotations (joint 0, the global orientation, is not used).

        Returns
        -------
        offsets : array (..., 778, 3)
            Metres, added to the rest vertices before skinning.
        """
        xp = array_namespace(rotations)
        eye = self.constant(np.eye(3), rotations)
        # Row-major (joint, row, column) flattening of R - I, MANO's "lrotmin" feature.
        feature = xp.reshape(rotations[..., 1:, :, :] - eye, rotations.shape[:-3] + (135,))
        offsets = xp.matmul(feature, self.constant(self._pose_basis, rotations).T)
        return xp.reshape(offsets, rotations.shape[:-3] + (N_VERTICES, 3))


def _left_shapedirs_have_error(shapedirs: np.ndarray, v_template: np.ndarray, right_file: Path,
                               source: str) -> bool:
    """Whether a left model's ``shapedirs[:, 0, :]`` needs negating (module docstring)."""
    if right_file.is_file():
        right = read_pickle(right_file)
        right_dirs = _model_array(right, "shapedirs", (N_VERTICES, 3, 10), right_file.name)
        # smplx issue #48: the x components were copied from the right model.
        return float(np.abs(shapedirs[:, 0, :] - right_dirs[:, 0, :]).sum()) < 1.0
    centred = v_template - v_template.mean(axis=0)
    size = shapedirs[:, :, 0]
    r = np.array([_correlation(centred[:, d], size[:, d]) for d in range(3)])
    if np.sign(r[1]) != np.sign(r[2]) or np.abs(r).min() < _MIN_CORRELATION:
        rounded = ", ".join(f"{x:.2f}" for x in r)
        raise HandcapError(f"{source}: cannot tell whether shapedirs[:, 0, :] has the known sign error "
                           f"(smplx issue #48; size correlations x, y, z: {rounded}); put MANO_RIGHT.pkl "
                           "beside it or pass fix_left_shapedirs=True/False")
    return bool(np.sign(r[0]) != np.sign(r[1]))


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two vectors (0 when either is constant)."""
    a, b = a - a.mean(), b - b.mean()
    norm = np.linalg.norm(a) * np.linalg.norm(b)
    return float(a @ b / norm) if norm > 0 else 0.0
