"""Quality metrics of captured motion, each defined exactly in its docstring.

Distances are in metres in and out (tables print millimetres); ``rate`` in Hz.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from handcap.core.errors import HandcapError
from handcap.core.geometry import signed_distance


@dataclass(frozen=True)
class Stat:
    """Mean and standard deviation of a set of samples (and how many there were)."""

    mean: float
    std: float
    count: int

    @classmethod
    def of(cls, values) -> "Stat":
        """Mean, standard deviation (population, ``ddof=0``) and count of the finite ``values``.

        Parameters
        ----------
        values : array_like
            Any shape and unit (flattened); NaN and infinities are left out.

        Returns
        -------
        Stat
            In the unit of ``values``; NaN mean and std with count 0 when none is finite.
        """
        values = np.asarray(values, dtype=np.float64).ravel()
        values = values[np.isfinite(values)]
        if len(values) == 0:
            return cls(float("nan"), float("nan"), 0)
        return cls(float(values.mean()), float(values.std()), int(len(values)))

    def mm(self) -> str:
        """Mean ± standard deviation of a Stat in metres, printed in millimetres with two decimals."""
        return f"{1000 * self.mean:.2f} ± {1000 * self.std:.2f} mm"


def marker_reconstruction_error(fitted, observed) -> Stat:
    """MRE (DexterCap section 5.3): distance between model-predicted and observed markers.

    ``MRE = mean over every observed (frame, marker) of |fitted - observed|``,
    with the standard deviation over the same samples. Samples missing in
    ``observed`` (NaN) are left out.

    Parameters
    ----------
    fitted, observed : ndarray (T, M, 3)
        Metres.
    """
    fitted, observed = np.asarray(fitted, dtype=np.float64), np.asarray(observed, dtype=np.float64)
    if fitted.shape != observed.shape:
        raise HandcapError(f"fitted markers {fitted.shape} and observed markers {observed.shape} differ in shape")
    return Stat.of(np.linalg.norm(fitted - observed, axis=-1))


def joint_position_error(joints, truth) -> Stat:
    """Euclidean distance between estimated and true joints, over every frame and joint.

    Parameters
    ----------
    joints, truth : ndarray (T, J, 3)
        Metres (handcap's 21 joints: the 16 MANO joints and the 5 tips).
    """
    joints, truth = np.asarray(joints, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    if joints.shape != truth.shape:
        raise HandcapError(f"joints {joints.shape} and true joints {truth.shape} differ in shape")
    return Stat.of(np.linalg.norm(joints - truth, axis=-1))


def msnr(joints, kernel: int = 3) -> float:
    """Motion signal-to-noise ratio in dB (DexterCap Eq. 10, following HUMOTO).

    ``v`` is the local joint velocity: the frame-to-frame change of every joint
    position relative to the wrist joint (joint 0), which removes the motion
    of the whole hand. ``v_hat`` is ``v`` smoothed by a centred moving average
    of ``kernel`` frames (edges repeat the end values), and

        MSNR = 10 log10( mean(v_hat^2) / mean((v - v_hat)^2) ),

    the means over frames, joints and coordinates. Higher is smoother. The
    velocity's time unit cancels, so the capture rate is not needed.

    Parameters
    ----------
    joints : ndarray (T, J, 3)
        Joint 0 is the wrist.
    kernel : int
        Moving-average length in frames (3 in the paper).
    """
    joints = np.asarray(joints, dtype=np.float64)
    if len(joints) < kernel + 1:
        raise HandcapError(f"MSNR needs at least {kernel + 1} frames, got {len(joints)}")
    local = joints[:, 1:] - joints[:, :1]
    v = np.diff(local, axis=0)
    v_hat = uniform_filter1d(v, size=kernel, axis=0, mode="nearest")
    noise = np.mean((v - v_hat) ** 2)
    return float(10 * np.log10(np.mean(v_hat**2) / noise)) if noise > 0 else float("inf")


def jerk(joints, rate: float) -> Stat:
    """Jerk magnitude (m/s^3) of joint positions: the third time derivative.

    ``j_t = (x_{t+3} - 3 x_{t+2} + 3 x_{t+1} - x_t) * rate^3`` (third forward
    difference), its Euclidean norm for every joint and frame; mean and
    standard deviation over all of them.

    Parameters
    ----------
    joints : ndarray (T, J, 3)
        Metres.
    rate : float
        Hz.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if len(joints) < 4:
        raise HandcapError(f"jerk needs at least 4 frames, got {len(joints)}")
    third = np.diff(joints, n=3, axis=0) * float(rate) ** 3
    return Stat.of(np.linalg.norm(third, axis=-1))


def penetration(hand_vertices, object_vertices, object_faces) -> Stat:
    """Penetration depth of the hand into an object (DexterCap section 5.4).

    For every frame, the depth of the deepest hand-mesh vertex inside the
    object's closed mesh (its distance to the object's surface); frames where
    no vertex is inside count as 0 and are left out. Mean and standard
    deviation over the frames with penetration (``count`` says how many).

    Parameters
    ----------
    hand_vertices : ndarray (T, V, 3)
        Metres.
    object_vertices : ndarray (T, W, 3) or (W, 3)
        The object's mesh in every frame, or a fixed one. A rigid object is best given fixed, in its own
        frame, with the hand's vertices moved into that frame: its box then bounds it tightly (only the
        vertices inside the box are measured), and its spatial index is made once for all frames. The depths are
        exact (:func:`handcap.core.geometry.signed_distance`, libigl's): on the session test's take of 260 frames
        held around a 192-face cylinder, 0.45 s (the library loaded) where trimesh's signed distance took 15.6 s.
    object_faces : ndarray (F, 3)
    """
    hand_vertices = np.asarray(hand_vertices, dtype=np.float64)
    object_vertices = np.asarray(object_vertices, dtype=np.float64)
    if object_vertices.ndim == 2:
        flat = hand_vertices.reshape(-1, 3)
        near = np.flatnonzero(((flat >= object_vertices.min(axis=0)) & (flat <= object_vertices.max(axis=0)))
                              .all(axis=1))
        depth = np.zeros(len(hand_vertices))
        if len(near):
            np.maximum.at(depth, near // hand_vertices.shape[1], signed_distance(flat[near], object_vertices,
                                                                                  object_faces))
        return Stat.of(depth[depth > 0])
    depths = []
    for verts, obj in zip(hand_vertices, object_vertices):
        near = np.flatnonzero(((verts >= obj.min(axis=0)) & (verts <= obj.max(axis=0))).all(axis=1))
        if len(near) == 0:
            continue
        inside = signed_distance(verts[near], obj, object_faces)
        if (inside > 0).any():
            depths.append(inside.max())
    return Stat.of(depths)


def diversity_coherence(features, k: int = 5, seed: int = 0) -> tuple[float, float]:
    """Diversity and coherence of a take's poses (DexterCap Table 2; our definitions).

    The per-frame feature vectors are standardised and clustered into ``k``
    groups with k-means (scikit-learn, 10 starts, ``seed``).

    * Diversity: the normalised entropy of the cluster sizes,
      ``-sum p_c log p_c / log k`` with ``p_c`` the fraction of frames in cluster
      c: 1 when the take visits all k kinds of pose equally, near 0 when it
      stays in one.
    * Coherence: ``(s + 1) / 2`` with ``s`` the mean silhouette coefficient of
      the clustering (Rousseeuw 1987, doi:10.1016/0377-0427(87)90125-7): 1 for
      tight, well separated clusters, 0.5 for none.

    Parameters
    ----------
    features : ndarray (T, D)
        E.g. joints relative to the wrist, flattened (see :func:`pose_features`).
    k : int
    seed : int

    Returns
    -------
    diversity, coherence : float
    """
    from sklearn.cluster import KMeans
    from sklearn.metrics import silhouette_score
    x = np.asarray(features, dtype=np.float64)
    x = x[np.isfinite(x).all(axis=1)]
    if len(x) <= k:
        raise HandcapError(f"diversity and coherence need more than {k} frames, got {len(x)}")
    scale = x.std(axis=0)
    x = (x - x.mean(axis=0)) / np.where(scale > 0, scale, 1.0)
    labels = KMeans(n_clusters=k, n_init=10, random_state=seed).fit_predict(x)
    p = np.bincount(labels, minlength=k) / len(labels)
    p = p[p > 0]
    diversity = float(-(p * np.log(p)).sum() / np.log(k))
    coherence = float((silhouette_score(x, labels) + 1) / 2) if len(set(labels)) > 1 else 0.5
    return diversity, coherence


def pose_features(joints, object_translation=None) -> np.ndarray:
    """Per-frame features for :func:`diversity_coherence`: joints relative to the wrist, and the object.

    Parameters
    ----------
    joints : ndarray (T, J, 3)
        Metres, joint 0 the wrist.
    object_translation : ndarray (T, 3), optional
        Object position, metres; appended relative to the wrist when given.

    Returns
    -------
    ndarray (T, D)
        Metres; D = 3 (J - 1), plus 3 with an object.
    """
    joints = np.asarray(joints, dtype=np.float64)
    feats = [(joints[:, 1:] - joints[:, :1]).reshape(len(joints), -1)]
    if object_translation is not None:
        feats.append(np.asarray(object_translation) - joints[:, 0])
    return np.concatenate(feats, axis=1)
