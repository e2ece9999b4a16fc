"""Constant-acceleration Kalman filters for many markers at once (Section 3.2 of the paper).

State per marker: position, velocity and acceleration along each axis. The
three axes share the dynamics, the (isotropic) noise and the times of their
updates, so they share one 3x3 covariance: a batch of B filters is a state
(B, 3, 3) (``[position, velocity, acceleration] x axis``) and a covariance
(B, 3, 3). Process noise: white jerk of spectral density ``q`` (m^2/s^5);
measurement noise: ``r`` (m^2) per axis.

The transition log-likelihood of a hypothesis (Eq. 3) is the sum over its
markers of ``log N(innovation; 0, S)`` with ``S = s I`` the innovation
covariance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.labeling.innovations import innovation_log_likelihoods


@dataclass(frozen=True)
class KalmanSettings:
    """Noise and timing of the filters.

    Attributes
    ----------
    dt : float
        Seconds between frames.
    jerk : float
        Spectral density of the white jerk driving the model, m^2/s^5.
    measurement : float
        Variance of a measured coordinate, m^2.
    initial_velocity, initial_acceleration : float
        Variances of the unknown velocity (m^2/s^2) and acceleration (m^2/s^4)
        of a newly started filter.
    """

    dt: float
    jerk: float
    measurement: float
    initial_velocity: float = 0.5**2
    initial_acceleration: float = 20.0**2

    def __post_init__(self):
        for name in ("dt", "jerk", "measurement"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise HandcapError(f"Kalman {name} must be a positive number, got {value}")

    @property
    def transition(self) -> np.ndarray:
        """State transition (3, 3) of one axis over one frame of ``dt`` seconds (position, velocity, acceleration)."""
        dt = self.dt
        return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])

    @property
    def process(self) -> np.ndarray:
        """Process noise covariance (3, 3) of one axis over one frame (continuous white jerk)."""
        dt, q = self.dt, self.jerk
        return q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6],
                             [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                             [dt**3 / 6, dt**2 / 2, dt]])

    @classmethod
    def from_training(cls, positions, rate: float) -> "KalmanSettings":
        """Noise levels that best explain labeled training trajectories (T, M, 3), metres, at ``rate`` Hz.

        Maximum likelihood over a grid: the filters are run over the training
        trajectories for every pair of measurement noise (:data:`SIGMAS_MM`, 0.05 to
        5 mm) and jerk density (:data:`JERKS`, 1 to 10^8.5 m^2/s^5), and the pair whose
        one-step innovations are most likely wins (the innovation likelihood is the
        exact likelihood of the data under the model). A best pair on the grid's edge
        is searched again on a grid 3-10 times wider each way (:data:`WIDER_SIGMAS_MM`,
        :data:`WIDER_JERKS`); one still on that grid's edge is what :meth:`edge_warning`
        reports. Labels whose tracks jump are left out (see :meth:`fit`, which also says which).

        Parameters
        ----------
        positions, rate
            As :meth:`fit`.

        Returns
        -------
        KalmanSettings
            ``dt = 1 / rate`` seconds, the best ``jerk`` (m^2/s^5) and ``measurement`` (m^2).
        """
        return cls.fit(positions, rate)[0]

    @classmethod
    def fit(cls, positions, rate: float) -> tuple["KalmanSettings", np.ndarray]:
        """:meth:`from_training`, and the markers left out of it because their tracks jump.

        Each marker's own best noise is found on the first grid too; a marker whose best noise is over
        :data:`JUMPING_FACTOR` times the median marker's (and over 1 mm) jumps between frames, most often a label
        swapped back and forth in the training take, and is left out of the pooled search (it would set every
        filter's noise). Nothing is left out when most markers jump.

        Parameters
        ----------
        positions : array_like of shape (T, M, 3)
            Labeled trajectories, metres, NaN where missing.
        rate : float
            Frames per second.

        Returns
        -------
        settings : KalmanSettings
        jumping : ndarray (M,) bool
            The markers left out.

        Raises
        ------
        HandcapError
            Fewer than 30 pairs of consecutive samples.
        """
        pos = np.asarray(positions, dtype=np.float64)
        dt = 1.0 / float(rate)
        seen = ~np.isnan(pos[..., 0])
        if (seen[1:] & seen[:-1]).sum() < 30:
            raise HandcapError("too few pairs of consecutive samples in the training take to tune the Kalman filters")
        sigmas, jerks = np.asarray(SIGMAS_MM) * 1e-3, np.asarray(JERKS)
        measurement, jerk = np.repeat(sigmas**2, len(jerks)), np.tile(jerks, len(sigmas))
        base = cls(dt, 1.0, 1.0)  # unit jerk and noise: the process noise of each setting is its jerk times this
        each = innovation_log_likelihoods(base, jerk, measurement, pos, per_marker=True)  # (C, M)
        counted = (seen[1:] & seen[:-1]).sum(axis=0) >= 30
        own = np.sqrt(measurement[np.argmax(each, axis=0)])  # each marker's own best noise, metres
        typical = np.median(own[counted]) if counted.any() else np.median(own)
        jumping = counted & (own > max(JUMPING_FACTOR * typical, 1e-3))
        if jumping.sum() * 2 > pos.shape[1]:
            jumping[:] = False
        kept = ~jumping
        ll = each[:, kept].sum(axis=1)
        for wider in (False, True):
            if wider:
                sigmas, jerks = np.asarray(WIDER_SIGMAS_MM) * 1e-3, np.asarray(WIDER_JERKS)
                measurement, jerk = np.repeat(sigmas**2, len(jerks)), np.tile(jerks, len(sigmas))
                ll = innovation_log_likelihoods(base, jerk, measurement, pos[:, kept])
            best = int(np.argmax(ll))
            row, column = divmod(best, len(jerks))
            if 0 < row < len(sigmas) - 1 and 0 < column < len(jerks) - 1:
                break
        return cls(dt, float(jerk[best]), float(measurement[best])), jumping

    def edge_warning(self) -> str:
        """A warning line when these settings lie on the edge of the widest grid :meth:`from_training` searches.

        Trajectories best explained by centimetres of noise or an extreme jerk are not a hand's markers tracked
        by a camera system: most often labels swapped back and forth in the training take, or lengths not in
        metres; a noise or jerk at the grid's low end, tracks smoother than any marker's.
        """
        sigma_mm = 1e3 * float(np.sqrt(self.measurement))
        edges = (np.isclose(sigma_mm, WIDER_SIGMAS_MM[0]) or np.isclose(sigma_mm, WIDER_SIGMAS_MM[-1])
                 or np.isclose(self.jerk, WIDER_JERKS[0]) or np.isclose(self.jerk, WIDER_JERKS[-1]))
        if not edges:
            return ""
        return (f"the training take's marker tracks are best explained by {sigma_mm:.3g} mm of measurement noise "
                f"and a jerk density of {self.jerk:.3g} m^2/s^5, at the edge of what is searched "
                f"({WIDER_SIGMAS_MM[0]:g}-{WIDER_SIGMAS_MM[-1]:g} mm, {WIDER_JERKS[0]:.3g}-{WIDER_JERKS[-1]:.3g} "
                f"m^2/s^5): labels swapped back and forth, or lengths not in metres? Check the training take")


#: Measurement noise (standard deviation per coordinate, mm) and jerk densities (m^2/s^5) that
#: :meth:`KalmanSettings.from_training` searches first: optical markers at 0.05-5 mm; synthetic range-of-motion
#: takes pick 10 (at 100 Hz), the real glove recording 31.6, the ezc3d samples 10^2-10^4.
SIGMAS_MM = (0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0)
JERKS = tuple(10.0 ** np.arange(0.0, 8.75, 0.5))
#: A marker whose own best noise is this many times the median marker's jumps (see :meth:`KalmanSettings.fit`).
JUMPING_FACTOR = 5.0
#: The grid searched when the best pair lies on the first grid's edge.
WIDER_SIGMAS_MM = (0.01, 0.02, *SIGMAS_MM, 10.0, 20.0, 50.0)
WIDER_JERKS = tuple(10.0 ** np.arange(-1.0, 10.25, 0.5))


class KalmanBatch:
    """B independent constant-acceleration filters over 3D positions.

    Attributes
    ----------
    state : ndarray (B, 3, 3)
        ``state[b, :, a]`` = position, velocity, acceleration of axis a.
    cov : ndarray (B, 3, 3)
        Shared covariance of the three axes' states.
    age : ndarray (B,) int
        Updates since the filter (re)started.
    missed : ndarray (B,) int
        Frames since the last update (0 right after one).
    """

    def __init__(self, settings: KalmanSettings, n: int):
        self.settings = settings
        self._f = settings.transition
        self._q = settings.process
        self.state = np.zeros((n, 3, 3))
        self.cov = np.zeros((n, 3, 3))
        self.age = np.zeros(n, dtype=np.int64)
        self.missed = np.full(n, 1 << 30, dtype=np.int64)  # never seen

    def copy_from(self, other: "KalmanBatch", index) -> None:
        """Replace every filter by ``other``'s filters ``index`` (B,).

        Parameters
        ----------
        other : KalmanBatch
            Filters with the same settings; not changed (its arrays are copied).
        index : ndarray (B,) int
            Filters of ``other`` to take; this batch then holds B filters.
        """
        self.state = other.state[index].copy()
        self.cov = other.cov[index].copy()
        self.age = other.age[index].copy()
        self.missed = other.missed[index].copy()

    def take_over(self, index, fresh) -> None:
        """Each filter replaced by filter ``index`` (B,) of this batch, then those ``fresh`` (B,) made to start
        afresh: age 0, so that their next update scores no transition.

        Parameters
        ----------
        index : ndarray (B,) int
        fresh : ndarray (B,) bool (any shape of B elements)
        """
        self.copy_from(self, index)
        self.age[np.ravel(fresh)] = 0

    def predicted(self) -> tuple[np.ndarray, np.ndarray]:
        """Predicted state and covariance one frame ahead (nothing changed)."""
        f = self._f
        return f @ self.state, f @ self.cov @ f.T + self._q

    def innovation_variance(self, cov_pred) -> np.ndarray:
        """Per-axis variance (B,) of the innovation for predicted covariances (B, 3, 3)."""
        return cov_pred[:, 0, 0] + self.settings.measurement

    @staticmethod
    def log_likelihood(residual, variance) -> np.ndarray:
        """``log N(residual; 0, variance I3)`` for residuals (..., 3) and variances (...).

        Parameters
        ----------
        residual : ndarray (..., 3)
            Innovation, metres.
        variance : ndarray (...)
            Per-axis innovation variance, m^2.

        Returns
        -------
        ndarray (...)
            Natural log of the density (density in 1/m^3).
        """
        return -1.5 * np.log(2 * np.pi * variance) - 0.5 * (residual**2).sum(axis=-1) / variance

    def step(self, measured, predicted=None) -> None:
        """Advance one frame: predict every filter, update those with a measurement.

        Parameters
        ----------
        measured : ndarray (B, 3)
            Measured position per filter, NaN for none (the filter coasts).
        predicted : (ndarray (B, 3, 3), ndarray (B, 3, 3)), optional
            :meth:`predicted`, when the caller has it already (it is not recomputed).
        """
        state, cov = self.predicted() if predicted is None else (predicted[0].copy(), predicted[1].copy())
        has = ~np.isnan(measured[:, 0])
        if has.any():
            s = cov[has, 0, 0] + self.settings.measurement
            gain = cov[has, :, 0] / s[:, None]  # (b, 3)
            innovation = measured[has] - state[has, 0]  # (b, 3 axes)
            state[has] += gain[:, :, None] * innovation[:, None, :]
            cov[has] -= gain[:, :, None] * cov[has, 0, None, :]
        self.state, self.cov = state, cov
        self.missed = np.where(has, 0, self.missed + 1)
        self.age = np.where(has, self.age + 1, self.age)

    def successors(self, index, measured, predicted, max_coast: int) -> "KalmanBatch":
        """The filters ``index`` (B,) of this batch one frame on, each updated with its measurement.

        A filter that had coasted more than ``max_coast`` frames starts afresh at its measurement.
        The same as copying, :meth:`step` and :meth:`restart`, in fewer array operations (a
        streaming labeler does this every frame).

        Parameters
        ----------
        index : ndarray (B,) int
        measured : ndarray (B, 3)
            Metres, NaN for none (the filter coasts).
        predicted : (ndarray (n, 3, 3), ndarray (n, 3, 3))
            :meth:`predicted` of this batch.
        """
        out = KalmanBatch.__new__(KalmanBatch)
        out.settings, out._f, out._q = self.settings, self._f, self._q
        state, cov = predicted[0][index], predicted[1][index]
        missed, age = self.missed[index], self.age[index]
        has = ~np.isnan(measured[:, 0])
        fresh = has & (missed > max_coast)
        update = np.flatnonzero(has & ~fresh)
        if len(update):
            c = cov[update]
            gain = c[:, :, 0] / (c[:, 0, 0] + self.settings.measurement)[:, None]  # (b, 3)
            state[update] += gain[:, :, None] * (measured[update] - state[update, 0])[:, None, :]
            cov[update] = c - gain[:, :, None] * c[:, 0, None, :]
        out.state, out.cov = state, cov
        out.missed = np.where(has, 0, missed + 1)
        out.age = np.where(has, age + 1, age)
        if fresh.any():
            out.restart(fresh, measured)
        return out

    def restart(self, which, positions) -> None:
        """Start filters ``which`` (B,) bool afresh at ``positions`` (B, 3): zero velocity and acceleration.

        Parameters
        ----------
        which : ndarray (B,) bool
            Filters to restart (age 1, missed 0).
        positions : ndarray (B, 3)
            Metres; only the rows of ``which`` are read.
        """
        s = self.settings
        self.state[which] = 0.0
        self.state[which, 0] = positions[which]
        self.cov[which] = np.diag([s.measurement, s.initial_velocity, s.initial_acceleration])
        self.age[which] = 1
        self.missed[which] = 0
