"""Constant-velocity Kalman filters for many targets at once (seed 003 §3.1, eqs. 5-6; no ROS here).

Per target the state of eq. 5 is ``x = [x, Δx, y, Δy]``: the box centre in pixels and its velocity
in pixels per second, because the frame interval ``T`` of eq. 6 is taken from the time stamps of
the frames (seconds), not a constant. The acceleration ``u = [a_x, a_y] ~ N(0, σ²)`` of eq. 5 is
the process noise through ``G``; eq. 5's ``C u + G w`` with ``C = G`` gives ``Q = σ² G Gᵀ``.
The measurement is the detection's centre, ``z = H x + v`` with ``v ~ N(0, r² I)``.

The box size is not part of the seed's state; it is carried beside it and smoothed exponentially
on every update (``w ← w + β (w_det − w)``, same for ``h``), and kept while a target coasts.

All targets live in one :class:`KalmanBank` of stacked arrays (states ``(N, 4)``, covariances
``(N, 4, 4)``) so that one frame of a thousand targets is a handful of batched matrix products.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aircraft_docking_tracker.config import param

#: Measurement matrix H of eq. 6: the filter observes the position (x, y).
H = np.array([[1.0, 0.0, 0.0, 0.0],
              [0.0, 0.0, 1.0, 0.0]])


@dataclass
class KalmanConfig:
    """Noise model of eqs. 5-6 (the seed gives no numbers; these suit boxes of tens of pixels)."""

    acceleration_noise: float = param(400.0, "σ of the acceleration a_x, a_y ~ N(0, σ²) of eq. 5 [px/s²]",
                                      low=1e-3, high=1e6)
    measurement_noise: float = param(4.0, "std of the measured centre, v_k of eq. 5 [px]", low=1e-3, high=1e4)
    initial_velocity_std: float = param(100.0, "std of the unknown velocity of a new target [px/s]",
                                        low=0.0, high=1e5)
    size_gain: float = param(0.6, "β: weight of a new detection's w, h in the smoothed box size", low=0.0, high=1.0)
    missed_update: str = param("prediction", "a frame without detection: 'prediction' updates the filter with "
                               "its own prediction (seed §3.3 rule 1), 'none' only predicts",
                               choices=("prediction", "none"))


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


def process_noise(T: float, sigma: float) -> np.ndarray:
    """Q = σ² G Gᵀ: covariance of ``C u + G w`` with the acceleration as the only noise (eq. 5)."""
    G = noise_gain(T)
    return sigma * sigma * (G @ G.T)


class KalmanBank:
    """The filters of all targets: one row per target in every array."""

    def __init__(self, config: KalmanConfig | None = None):
        self.config = config or KalmanConfig()
        self.x = np.zeros((0, 4))        # states [x, Δx, y, Δy], centre [px] and velocity [px/s]
        self.P = np.zeros((0, 4, 4))     # state covariances
        self.size = np.zeros((0, 2))     # smoothed box width and height [px]

    @property
    def R(self) -> np.ndarray:
        """Measurement noise covariance r² I (eq. 5's v_k)."""
        return np.eye(2) * self.config.measurement_noise ** 2

    def __len__(self) -> int:
        return len(self.x)

    # -- targets in and out -------------------------------------------------------------------
    def add(self, xywh: np.ndarray) -> None:
        """Start filters at boxes ``(k, 4)`` x, y, w, h: centre measured, velocity zero and unknown."""
        xywh = np.asarray(xywh, dtype=np.float64).reshape(-1, 4)
        k = len(xywh)
        x = np.zeros((k, 4))
        x[:, 0] = xywh[:, 0] + xywh[:, 2] / 2.0
        x[:, 2] = xywh[:, 1] + xywh[:, 3] / 2.0
        P = np.zeros((k, 4, 4))
        P[:, 0, 0] = P[:, 2, 2] = self.config.measurement_noise ** 2
        P[:, 1, 1] = P[:, 3, 3] = self.config.initial_velocity_std ** 2
        self.x = np.concatenate([self.x, x])
        self.P = np.concatenate([self.P, P])
        self.size = np.concatenate([self.size, xywh[:, 2:4]])

    def keep(self, mask: np.ndarray) -> None:
        """Keep only the targets where ``mask`` is True (deletion, §3.3 rule 1)."""
        self.x, self.P, self.size = self.x[mask], self.P[mask], self.size[mask]

    # -- the filter ---------------------------------------------------------------------------
    def predict(self, T: float) -> None:
        """Time update over T seconds: x ← F x, P ← F P Fᵀ + Q (eqs. 5-6)."""
        F = transition(T)
        self.x = self.x @ F.T
        self.P = F @ self.P @ F.T + process_noise(T, self.config.acceleration_noise)

    def innovation_covariance(self) -> np.ndarray:
        """S = H P Hᵀ + R for every target, ``(N, 2, 2)`` (for the Mahalanobis gate)."""
        return self.P[:, 0::2, 0::2] + self.R

    def update(self, rows: np.ndarray, z: np.ndarray, sizes: np.ndarray | None = None) -> None:
        """Measurement update of targets ``rows`` with centres ``z`` ``(k, 2)``; smooth their box sizes.

        K = P Hᵀ S⁻¹, x ← x + K (z − H x), P ← (I − K H) P.
        """
        rows = np.asarray(rows, dtype=np.intp)
        if len(rows) == 0:
            return
        P = self.P[rows]
        S = P[:, 0::2, 0::2] + self.R
        K = P[:, :, 0::2] @ np.linalg.inv(S)                       # P Hᵀ S⁻¹, (k, 4, 2)
        residual = np.asarray(z, dtype=np.float64).reshape(-1, 2) - self.x[rows][:, 0::2]
        self.x[rows] += (K @ residual[:, :, None])[:, :, 0]
        self.P[rows] = P - K @ P[:, 0::2, :]                         # (I − K H) P
        if sizes is not None:
            beta = self.config.size_gain
            self.size[rows] += beta * (np.asarray(sizes, dtype=np.float64).reshape(-1, 2) - self.size[rows])

    def coast(self, rows: np.ndarray) -> None:
        """A frame without detection for ``rows`` (§3.3 rule 1): update with the prediction, or nothing."""
        if self.config.missed_update == "prediction" and len(rows):
            self.update(rows, self.x[np.asarray(rows, dtype=np.intp)][:, 0::2])

    # -- read-outs ----------------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """Box centres ``(N, 2)`` [px]."""
        return self.x[:, 0::2]

    @property
    def velocities(self) -> np.ndarray:
        """Velocities ``(N, 2)`` [px/s]."""
        return self.x[:, 1::2]

    def boxes(self) -> np.ndarray:
        """Boxes ``(N, 4)`` x, y, w, h (top-left corner) from the centres and smoothed sizes."""
        return np.concatenate([self.positions - self.size / 2.0, self.size], axis=1)
