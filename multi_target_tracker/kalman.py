"""Constant-velocity Kalman filters for many targets at once (seed 003 §3.1, eqs. 5-6; no ROS here).

Per target the state of eq. 5 is ``x = [x, Δx, y, Δy]``: the box centre in pixels and its velocity
in pixels per second, because the frame interval ``T`` of eq. 6 is taken from the time stamps of
the frames (seconds), not a constant. The acceleration ``u = [a_x, a_y] ~ N(0, σ²)`` of eq. 5 is
the process noise through ``G``; eq. 5's ``C u + G w`` with ``C = G`` gives ``Q = σ² G Gᵀ``.
The measurement is the detection's centre, ``z = H x + v`` with ``v ~ N(0, r² I)``.

The box size is not part of the seed's state; it is carried beside it and smoothed exponentially
on every update (``w ← w + β (w_det − w)``, same for ``h``), and kept while a target coasts.

The seed gives no noise values. Both noises may grow with the target's apparent size (a choice of
ours, as in DeepSORT / ByteTrack): ``σ_i = acceleration_noise + acceleration_noise_per_px · h_i`` and
``r_i = measurement_noise + measurement_noise_per_px · h_i``, with ``h_i`` the smoothed box height;
the defaults (chosen leave-one-sequence-out in ``bench/association.py`` on pedestrians 100-300 px
tall and aircraft and vehicles 12-140 px) are purely size-proportional for the acceleration, so the
same setting holds at every scale.

A frame without detection: the seed's rule 1 updates the filter with its own prediction, which
shrinks P as if a measurement had arrived; ``missed_update="none"`` (the default) only predicts,
so P, and the Mahalanobis gate built on it, grows while a target is hidden (issue 13).

All targets live in one :class:`KalmanBank` of stacked arrays, so a frame of a thousand targets
is a few vector operations. With F, G, H of eq. 6 and R = r² I the x and y axes never mix and
have the same noise, so P = diag(P_a, P_a) with one 2x2 block P_a = [[p_pp, p_pv], [p_pv, p_vv]]
per target (position / velocity of one axis); the bank stores those three numbers, and every
formula below is eq. 5-6's 4x4 one written for that block (:attr:`KalmanBank.P` rebuilds the 4x4).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aircraft_docking_tracker.config import ConfigError, param

#: Measurement matrix H of eq. 6: the filter observes the position (x, y).
H = np.array([[1.0, 0.0, 0.0, 0.0],
              [0.0, 0.0, 1.0, 0.0]])


@dataclass
class KalmanConfig:
    """Noise model of eqs. 5-6 (the seed gives no numbers; the defaults are measured, see the module)."""

    acceleration_noise: float = param(0.0, "σ of the acceleration a_x, a_y ~ N(0, σ²) of eq. 5 [px/s²]",
                                      low=0.0, high=1e6)
    acceleration_noise_per_px: float = param(2.0, "σ added per pixel of box height [1/s²]", low=0.0, high=1e4)
    measurement_noise: float = param(0.5, "std of the measured centre, v_k of eq. 5 [px]", low=0.0, high=1e4)
    measurement_noise_per_px: float = param(0.05, "measurement std added per pixel of box height", low=0.0, high=10.0)
    initial_velocity_std: float = param(100.0, "std of the unknown velocity of a new target [px/s]",
                                        low=0.0, high=1e5)
    size_gain: float = param(0.8, "β: weight of a new detection's w, h in the smoothed box size", low=0.0, high=1.0)
    missed_update: str = param("none", "a frame without detection: 'none' only predicts (the covariance and the "
                               "gate grow while a target is missed), 'prediction' updates the filter with its own "
                               "prediction (seed §3.3 rule 1: the covariance shrinks)",
                               choices=("prediction", "none"))

    def validate(self) -> None:
        if self.measurement_noise <= 0 and self.measurement_noise_per_px <= 0:
            raise ConfigError("measurement_noise and measurement_noise_per_px cannot both be 0",
                              ("measurement_noise", "measurement_noise_per_px"))


def transition(T: float) -> np.ndarray:
    """F of eq. 6 for a frame interval T [s]."""
    return np.array([[1.0, T, 0.0, 0.0],
                     [0.0, 1.0, 0.0, 0.0],
                     [0.0, 0.0, 1.0, T],
                     [0.0, 0.0, 0.0, 1.0]])


def noise_gain(T: float) -> np.ndarray:
    """C = G of eq. 6: how an acceleration [px/s²] held over T moves position and velocity."""
    return np.array([[T * T / 2.0, 0.0],
                     [T, 0.0],
                     [0.0, T * T / 2.0],
                     [0.0, T]])


def process_noise(T: float, sigma) -> np.ndarray:
    """Q = σ² G Gᵀ: covariance of ``C u + G w`` with the acceleration as the only noise (eq. 5).

    ``sigma`` a number (one 4x4 Q) or an array of N (N stacked Qs).
    """
    G = noise_gain(T)
    return np.multiply.outer(np.square(sigma), G @ G.T)


class KalmanBank:
    """The filters of all targets: one row per target in every array."""

    def __init__(self, config: KalmanConfig | None = None):
        self.config = config or KalmanConfig()
        self.x = np.zeros((0, 4))        # states [x, Δx, y, Δy], centre [px] and velocity [px/s]
        self.cov = np.zeros((0, 3))      # per target the block P_a: p_pp, p_pv, p_vv (same for x and y)
        self.size = np.zeros((0, 2))     # smoothed box width and height [px]

    def __len__(self) -> int:
        return len(self.x)

    @property
    def P(self) -> np.ndarray:
        """The full 4x4 covariances ``(N, 4, 4)`` of eq. 5's state (for inspection)."""
        P = np.zeros((len(self.x), 4, 4))
        for axis in (0, 2):
            P[:, axis, axis], P[:, axis + 1, axis + 1] = self.cov[:, 0], self.cov[:, 2]
            P[:, axis, axis + 1] = P[:, axis + 1, axis] = self.cov[:, 1]
        return P

    def measurement_std(self, heights: np.ndarray) -> np.ndarray:
        """r_i [px] for boxes of the given heights."""
        return self.config.measurement_noise + self.config.measurement_noise_per_px * heights

    def innovation_variance(self, rows=slice(None)) -> np.ndarray:
        """s_i with S_i = H P_i Hᵀ + R_i = s_i I (``(k,)``, for the update and the Mahalanobis gate)."""
        return self.cov[rows, 0] + self.measurement_std(self.size[rows, 1]) ** 2

    # -- targets in and out -------------------------------------------------------------------
    def add(self, xywh: np.ndarray) -> None:
        """Start filters at boxes ``(k, 4)`` x, y, w, h: centre measured, velocity zero and unknown."""
        xywh = np.asarray(xywh, dtype=np.float64).reshape(-1, 4)
        k = len(xywh)
        x = np.zeros((k, 4))
        x[:, 0] = xywh[:, 0] + xywh[:, 2] / 2.0
        x[:, 2] = xywh[:, 1] + xywh[:, 3] / 2.0
        cov = np.zeros((k, 3))
        cov[:, 0] = self.measurement_std(xywh[:, 3]) ** 2            # P = diag(r², σ_v², r², σ_v²)
        cov[:, 2] = self.config.initial_velocity_std ** 2
        self.x = np.concatenate([self.x, x])
        self.cov = np.concatenate([self.cov, cov])
        self.size = np.concatenate([self.size, xywh[:, 2:4]])

    def copy(self) -> "KalmanBank":
        """An independent bank with the same filters (same config): predicting it leaves this one as it is."""
        bank = KalmanBank(self.config)
        bank.x, bank.cov, bank.size = self.x.copy(), self.cov.copy(), self.size.copy()
        return bank

    def keep(self, mask: np.ndarray) -> None:
        """Keep only the targets where ``mask`` is True (deletion, §3.3 rule 1)."""
        self.x, self.cov, self.size = self.x[mask], self.cov[mask], self.size[mask]

    # -- the filter ---------------------------------------------------------------------------
    def predict(self, T: float) -> None:
        """Time update over T seconds: x ← F x, P ← F P Fᵀ + Q (eqs. 5-6).

        Per axis F's block is [[1, T], [0, 1]] and Q's is σ² g gᵀ with g = (T²/2, T), G's column.
        """
        self.x[:, 0] += T * self.x[:, 1]
        self.x[:, 2] += T * self.x[:, 3]
        q = (self.config.acceleration_noise + self.config.acceleration_noise_per_px * self.size[:, 1]) ** 2
        pp, pv, vv = self.cov[:, 0], self.cov[:, 1], self.cov[:, 2]      # views: updated in place, in
        pp += 2 * T * pv + T * T * vv + q * (T ** 4 / 4)                    # this order, each line using
        pv += T * vv + q * (T ** 3 / 2)                                     # the old values below it
        vv += q * (T * T)

    def update(self, rows: np.ndarray, z: np.ndarray, sizes: np.ndarray | None = None) -> None:
        """Measurement update of targets ``rows`` with centres ``z`` ``(k, 2)``; smooth their box sizes.

        K = P Hᵀ S⁻¹, x ← x + K (z − H x), P ← (I − K H) P; per axis K = (p_pp, p_pv) / s.
        """
        rows = np.asarray(rows, dtype=np.intp)
        if len(rows) == 0:
            return
        z = np.asarray(z, dtype=np.float64).reshape(-1, 2)
        cov = self.cov[rows]
        pp, pv, vv = cov[:, 0], cov[:, 1], cov[:, 2]
        s = pp + self.measurement_std(self.size[rows, 1]) ** 2           # S = s I
        k_pos, k_vel = (pp / s)[:, None], (pv / s)[:, None]
        x = self.x[rows]
        residual = z - x[:, 0::2]
        x[:, 0::2] += k_pos * residual
        x[:, 1::2] += k_vel * residual
        self.x[rows] = x
        vv -= k_vel[:, 0] * pv                                           # (I − K H) P, in the order
        pv *= 1.0 - k_pos[:, 0]                                          # that reads each old value
        pp *= 1.0 - k_pos[:, 0]
        self.cov[rows] = cov
        if sizes is not None:
            beta = self.config.size_gain
            self.size[rows] += beta * (np.asarray(sizes, dtype=np.float64).reshape(-1, 2) - self.size[rows])

    def update_frame(self, rows: np.ndarray, z: np.ndarray, sizes: np.ndarray, missed: np.ndarray) -> None:
        """One frame's updates in one batch: ``rows`` with their detections (§3.3 rule 3) and the
        ``missed`` targets with their own prediction (rule 1, ``missed_update="prediction"``; their
        state and size stay, their covariance shrinks) or not at all (``"none"``)."""
        if self.config.missed_update == "prediction" and len(missed):
            rows = np.concatenate([rows, missed])
            z = np.concatenate([z, self.x[missed][:, 0::2]])
            sizes = np.concatenate([sizes, self.size[missed]])
        self.update(rows, z, sizes)

    def coast(self, rows: np.ndarray) -> None:
        """A frame without detection for ``rows`` (§3.3 rule 1): update with the prediction, or nothing."""
        self.update_frame(np.zeros(0, dtype=np.intp), np.zeros((0, 2)), np.zeros((0, 2)), rows)

    # -- read-outs ----------------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """Box centres ``(N, 2)`` [px]."""
        return self.x[:, 0::2]

    @property
    def velocities(self) -> np.ndarray:
        """Velocities ``(N, 2)`` [px/s]."""
        return self.x[:, 1::2]

    def boxes(self, rows=slice(None)) -> np.ndarray:
        """Boxes ``(k, 4)`` x, y, w, h (top-left corner) of targets ``rows`` from the centres and sizes."""
        size = self.size[rows]
        return np.concatenate([self.x[rows][:, 0::2] - size / 2.0, size], axis=1)
