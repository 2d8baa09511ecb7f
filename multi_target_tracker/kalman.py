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
the defaults (measured in ``bench/association.py`` on pedestrians 100-300 px tall and aircraft and
vehicles 12-140 px) are mostly the size-proportional terms.

All targets live in one :class:`KalmanBank` of stacked arrays (states ``(N, 4)``, covariances
``(N, 4, 4)``) so that one frame of a thousand targets is a handful of batched matrix products.
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

    acceleration_noise: float = param(50.0, "σ of the acceleration a_x, a_y ~ N(0, σ²) of eq. 5 [px/s²]",
                                      low=0.0, high=1e6)
    acceleration_noise_per_px: float = param(12.0, "σ added per pixel of box height [1/s²]", low=0.0, high=1e4)
    measurement_noise: float = param(0.5, "std of the measured centre, v_k of eq. 5 [px]", low=0.0, high=1e4)
    measurement_noise_per_px: float = param(0.05, "measurement std added per pixel of box height", low=0.0, high=10.0)
    initial_velocity_std: float = param(100.0, "std of the unknown velocity of a new target [px/s]",
                                        low=0.0, high=1e5)
    size_gain: float = param(0.8, "β: weight of a new detection's w, h in the smoothed box size", low=0.0, high=1.0)
    missed_update: str = param("prediction", "a frame without detection: 'prediction' updates the filter with "
                               "its own prediction (seed §3.3 rule 1), 'none' only predicts",
                               choices=("prediction", "none"))

    def validate(self) -> None:
        if self.measurement_noise <= 0 and self.measurement_noise_per_px <= 0:
            raise ConfigError("measurement_noise and measurement_noise_per_px cannot both be 0")


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


def inverse_2x2(S: np.ndarray) -> np.ndarray:
    """Inverses of a stack of 2x2 matrices ``(k, 2, 2)`` in closed form (adjugate / determinant)."""
    a, b, c, d = S[:, 0, 0], S[:, 0, 1], S[:, 1, 0], S[:, 1, 1]
    out = np.empty_like(S)
    det = a * d - b * c
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = d / det, -b / det, -c / det, a / det
    return out


class KalmanBank:
    """The filters of all targets: one row per target in every array."""

    def __init__(self, config: KalmanConfig | None = None):
        self.config = config or KalmanConfig()
        self.x = np.zeros((0, 4))        # states [x, Δx, y, Δy], centre [px] and velocity [px/s]
        self.P = np.zeros((0, 4, 4))     # state covariances
        self.size = np.zeros((0, 2))     # smoothed box width and height [px]

    def measurement_std(self, heights: np.ndarray) -> np.ndarray:
        """r_i [px] for boxes of the given heights."""
        return self.config.measurement_noise + self.config.measurement_noise_per_px * heights

    def R(self, rows=slice(None)) -> np.ndarray:
        """Measurement noise covariances r_i² I (eq. 5's v_k) of targets ``rows``, ``(k, 2, 2)``."""
        return np.multiply.outer(self.measurement_std(self.size[rows, 1]) ** 2, np.eye(2))

    def _innovation(self, P: np.ndarray, rows) -> np.ndarray:
        """S = H P Hᵀ + R for covariances ``P`` of targets ``rows`` (R is diagonal: added in place)."""
        S = P[:, 0::2, 0::2].copy()
        r2 = self.measurement_std(self.size[rows, 1]) ** 2
        S[:, 0, 0] += r2
        S[:, 1, 1] += r2
        return S

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
        P[:, 0, 0] = P[:, 2, 2] = self.measurement_std(xywh[:, 3]) ** 2
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
        sigma = self.config.acceleration_noise + self.config.acceleration_noise_per_px * self.size[:, 1]
        self.P = F @ self.P @ F.T + process_noise(T, sigma)

    def innovation_covariance(self) -> np.ndarray:
        """S = H P Hᵀ + R for every target, ``(N, 2, 2)`` (for the Mahalanobis gate)."""
        return self._innovation(self.P, slice(None))

    def update(self, rows: np.ndarray, z: np.ndarray, sizes: np.ndarray | None = None) -> None:
        """Measurement update of targets ``rows`` with centres ``z`` ``(k, 2)``; smooth their box sizes.

        K = P Hᵀ S⁻¹, x ← x + K (z − H x), P ← (I − K H) P.
        """
        rows = np.asarray(rows, dtype=np.intp)
        if len(rows) == 0:
            return
        P = self.P[rows]
        K = P[:, :, 0::2] @ inverse_2x2(self._innovation(P, rows))  # P Hᵀ S⁻¹, (k, 4, 2)
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

    def boxes(self, rows=slice(None)) -> np.ndarray:
        """Boxes ``(k, 4)`` x, y, w, h (top-left corner) of targets ``rows`` from the centres and sizes."""
        size = self.size[rows]
        return np.concatenate([self.x[rows][:, 0::2] - size / 2.0, size], axis=1)
