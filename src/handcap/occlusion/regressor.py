"""The joint regressor (section 3.2.3): complete markers -> hand pose, no solver.

The markers (all of them, the occluded ones already predicted) are registered
to the template (on the measured ones, as the marker predictor registers them:
the regressor is trained on such registrations, so the filler needs no second
fit), and an MLP ``3M -> 200 -> 200 -> 200 -> 36`` (ReLU, dropout
0.1) predicts the hand model's 27 anatomical angles (``phi``, radians, the
hand pose of :mod:`handcap.hand.anatomy`) and the wrist's pose in the template
frame: its rotation as the first two columns of the matrix (6 numbers, which
unlike Euler angles or axis-angle has no jump) and its position. The wrist
pose is carried back to the world with the registration, so the output is a
full :class:`~handcap.core.motion.HandMotion` frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.rotations import axis_angle_from_matrix, matrix_from_axis_angle
from handcap.hand import OpenHand
from handcap.occlusion.network import Mlp, mlp_from_torch, torch_mlp, train_network
from handcap.occlusion.predictor import knock_out
from handcap.occlusion.register import apply_registration, fit_registration

HIDDEN = (200, 200, 200)
DROPOUT = 0.1
N_PHI = 27
N_OUT = N_PHI + 6 + 3


def matrix_from_6d(six) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from two columns (..., 6) (Gram-Schmidt; Zhou et al. 2019)."""
    a, b = six[..., :3], six[..., 3:]
    x = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b - (x * b).sum(axis=-1, keepdims=True) * x
    y = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


@dataclass(frozen=True, eq=False)
class JointRegressor:
    """A trained joint regressor.

    Attributes
    ----------
    names : tuple of str (M,)
    template : ndarray (M, 3)
        Registration target, metres.
    weights : ndarray (M,)
        Registration weights.
    mean, scale : ndarray (M, 3)
        Standardisation of the registered markers, metres.
    out_mean, out_scale : ndarray (36,)
        Standardisation of the outputs (phi radians, rotation columns, wrist metres).
    net : Mlp
    """

    names: tuple
    template: np.ndarray
    weights: np.ndarray
    mean: np.ndarray
    scale: np.ndarray
    out_mean: np.ndarray
    out_scale: np.ndarray
    net: Mlp

    def predict_local(self, local) -> np.ndarray:
        """Raw outputs (..., 36) for registered complete markers (..., M, 3)."""
        x = ((local - self.mean) / self.scale).reshape(local.shape[:-2] + (-1,))
        return self.net(x) * self.out_scale + self.out_mean

    def predict(self, positions, visible=None):
        """Hand pose from complete markers.

        Parameters
        ----------
        positions : ndarray (..., M, 3)
            Every marker, metres (no NaN).
        visible : ndarray (..., M) bool, optional
            The markers really measured (the others were predicted): only they
            place the hand's frame, as in the streaming filler. Default: all.

        Returns
        -------
        phi : ndarray (..., 27)
            Anatomical angles, radians.
        global_orient : ndarray (..., 3)
            Axis-angle of the wrist in the world.
        transl : ndarray (..., 3)
            Wrist position in the world, metres.
        """
        positions = np.asarray(positions, dtype=np.float64)
        visible = np.ones(positions.shape[:-1], bool) if visible is None else np.asarray(visible, bool)
        rotation, centre, template_centre = fit_registration(positions, visible, self.template, self.weights)
        out = self.predict_local(apply_registration(positions, rotation, centre, template_centre))
        return outputs_to_world(out, rotation, centre, template_centre)

    def arrays(self) -> dict:
        """The regressor as ``.npz`` entries.

        Returns
        -------
        dict of str to ndarray
            ``jr_names`` (M,), ``jr_template`` (M, 3) metres, ``jr_weights`` (M,), ``jr_mean`` and
            ``jr_scale`` (M, 3) metres, ``jr_out_mean`` and ``jr_out_scale`` (36,), and the network's
            ``jr_w<i>``, ``jr_b<i>``.
        """
        return {"jr_names": np.array(self.names), "jr_template": self.template, "jr_weights": self.weights,
                "jr_mean": self.mean, "jr_scale": self.scale, "jr_out_mean": self.out_mean,
                "jr_out_scale": self.out_scale, **self.net.arrays("jr_")}

    @classmethod
    def from_arrays(cls, arrays) -> "JointRegressor":
        """The regressor stored by :meth:`arrays`.

        Parameters
        ----------
        arrays : mapping of str to ndarray
            The ``jr_*`` entries.

        Returns
        -------
        JointRegressor
        """
        return cls(tuple(str(n) for n in arrays["jr_names"]),
                   *(np.asarray(arrays[f"jr_{k}"], float)
                     for k in ("template", "weights", "mean", "scale", "out_mean", "out_scale")),
                   Mlp.from_arrays(arrays, "jr_"))


def outputs_to_world(out, rotation, centre, template_centre):
    """(phi, global_orient, transl) from raw outputs (..., 36) and the registration of their frames.

    Parameters
    ----------
    out : ndarray (..., 36)
        ``phi`` (27, radians), the wrist rotation's first two columns (6) and the wrist position
        (3, metres), in the template frame.
    rotation : ndarray (..., 3, 3)
    centre : ndarray (..., 3)
        Metres.
    template_centre : ndarray (..., 3)
        Metres; the registration of each frame (:func:`~handcap.occlusion.register.fit_registration`).

    Returns
    -------
    phi : ndarray (..., 27)
        Radians.
    global_orient : ndarray (..., 3)
        Axis-angle of the wrist in the world, radians.
    transl : ndarray (..., 3)
        Wrist position in the world, metres.
    """
    phi = out[..., :N_PHI]
    local_rot = matrix_from_6d(out[..., N_PHI:N_PHI + 6])
    local_pos = out[..., N_PHI + 6:]
    # local = (world - c) R + tc as rows, so world = R (local - tc) + c as columns.
    world_rot = rotation @ local_rot
    transl = np.einsum("...ij,...j->...i", rotation, local_pos - template_centre) + centre
    return phi, axis_angle_from_matrix(world_rot), transl


def targets_in_frame(phi, global_orient, transl, rotation, centre, template_centre) -> np.ndarray:
    """Raw outputs (..., 36) of a pose, its wrist pose expressed in the registered frame.

    The inverse of :func:`outputs_to_world`.

    Parameters
    ----------
    phi : ndarray (..., 27)
        Radians.
    global_orient : ndarray (..., 3)
        Axis-angle of the wrist in the world, radians.
    transl : ndarray (..., 3)
        Wrist position in the world, metres.
    rotation : ndarray (..., 3, 3)
    centre : ndarray (..., 3)
        Metres.
    template_centre : ndarray (..., 3)
        Metres; the registration of each frame.

    Returns
    -------
    ndarray (..., 36)
        ``phi`` (radians), the first two columns of the wrist rotation in the template frame,
        and the wrist position there (metres).
    """
    world_rot = matrix_from_axis_angle(global_orient)
    local_rot = np.swapaxes(rotation, -1, -2) @ world_rot
    local_pos = np.einsum("...ji,...j->...i", rotation, transl - centre) + template_centre
    six = np.concatenate([local_rot[..., :, 0], local_rot[..., :, 1]], axis=-1)
    return np.concatenate([phi, six, local_pos], axis=-1)


def train_joint_regressor(positions, phi, global_orient, transl, names, *, template, weights, seed: int = 0,
                          epochs: int = 60, batch_size: int = 256, hidden=HIDDEN, dropout: float = DROPOUT,
                          jitter: float = 0.0, progress=None) -> JointRegressor:
    """Train a joint regressor on complete frames with known poses.

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        Markers, metres; frames with a missing marker are skipped.
    phi : ndarray (T, 27)
        Radians.
    global_orient, transl : ndarray (T, 3)
        Wrist axis-angle and position, metres.
    names : sequence of str (M,)
    template, weights : ndarray (M, 3), (M,)
        Registration (use the marker predictor's, so both stages share a frame).
    seed : int
        Deterministic for a seed.
    epochs, batch_size : int
    hidden : tuple of int
        The paper's 200, 200, 200.
    dropout : float
        The paper's 0.1.
    jitter : float
        Standard deviation of noise added to the markers during training, metres.
    progress : callable (epoch, loss), optional
    """
    import torch

    positions = np.asarray(positions, dtype=np.float64)
    complete = ~np.isnan(positions).any(axis=(1, 2))
    if complete.sum() < 10:
        raise HandcapError(f"only {complete.sum()} frames with poses have every marker; "
                           "a joint regressor needs at least 10")
    positions = positions[complete]
    phi, global_orient, transl = (np.asarray(a, dtype=np.float64)[complete] for a in (phi, global_orient, transl))
    m = positions.shape[1]
    visible = np.ones(positions.shape[:2], bool)
    pose = fit_registration(positions, visible, template, weights)
    local = apply_registration(positions, *pose)
    mean, scale = local.mean(axis=0), np.maximum(local.std(axis=0), 0.005)
    targets = targets_in_frame(phi, global_orient, transl, *pose)
    out_mean, out_scale = targets.mean(axis=0), np.maximum(targets.std(axis=0), 1e-3)
    # Weigh each output by how far it moves the joints (phi of a knuckle moves three joints, of a
    # fingertip one; the wrist moves all 21), so the loss approximates the joint position error.
    output_weights = joint_sensitivity(targets, pick=np.random.default_rng(seed)) * out_scale ** 2
    output_weights = torch.from_numpy((output_weights / output_weights.mean()).astype(np.float32))
    torch.manual_seed(seed)
    module = torch_mlp((3 * m,) + tuple(hidden) + (N_OUT,), dropout)

    def make_batches(epoch, rng):
        order = rng.permutation(len(positions))
        frames = positions[order]
        if jitter > 0:
            frames = frames + rng.normal(0.0, jitter, frames.shape)
        # At run time the hand's frame comes from the measured markers only (the predicted ones do
        # not place it): half the samples are registered on a random subset, as the filler would.
        shown = visible[order] & ~(knock_out(visible[order], rng) & (rng.random(len(order)) < 0.5)[:, None])
        sample_pose = fit_registration(frames, shown, template, weights)
        x = ((apply_registration(frames, *sample_pose) - mean) / scale).reshape(len(order), -1)
        y = (targets_in_frame(phi[order], global_orient[order], transl[order], *sample_pose) - out_mean) / out_scale
        x, y = (torch.from_numpy(a.astype(np.float32)) for a in (x, y))
        w = output_weights.expand_as(y)
        for start in range(0, len(order), batch_size):
            s = slice(start, start + batch_size)
            yield x[s], y[s], w[s]

    train_network(module, make_batches, epochs=epochs, seed=seed, progress=progress)
    return JointRegressor(tuple(names), np.asarray(template, float), np.asarray(weights, float), mean, scale,
                          out_mean, out_scale, mlp_from_torch(module))


def joint_sensitivity(targets, *, pick, frames: int = 16, step: float = 1e-4) -> np.ndarray:
    """Mean squared displacement of the 21 joints per unit change of each raw output (36,), metres squared.

    Finite differences of the right OpenHand (average shape) at ``frames`` training poses drawn by ``pick``.

    Parameters
    ----------
    targets : ndarray (T, 36)
        Raw outputs (:func:`targets_in_frame`): radians, rotation columns, metres.
    pick : numpy Generator
        Draws the poses (without replacement).
    frames : int
        Number of poses used (at most T).
    step : float
        Finite-difference step, in each output's unit.

    Returns
    -------
    ndarray (36,)
        Squared joint displacement per squared unit of each output (m^2/rad^2 for ``phi``,
        m^2 per unit of the rotation columns, dimensionless for the wrist position), averaged
        over the joints and the poses.
    """

    hand = OpenHand("right")
    rows = targets[pick.choice(len(targets), size=min(frames, len(targets)), replace=False)]

    def joints(out):
        local_rot = matrix_from_6d(out[..., N_PHI:N_PHI + 6])
        posed = hand.forward(phi=out[..., :N_PHI], vertices=False).joints
        return np.einsum("...ij,...kj->...ki", local_rot, posed) + out[..., None, N_PHI + 6:]

    base = joints(rows)
    moved = rows[:, None, :] + step * np.eye(N_OUT)[None]  # (F, 36, 36)
    shift = (joints(moved) - base[:, None]) / step  # (F, 36, 21, 3)
    return (shift ** 2).sum(axis=-1).mean(axis=(0, 2))
