"""The constant-velocity Kalman filter (seed 003 eqs. 5-6) against a predict/update worked by hand."""
from __future__ import annotations

import numpy as np
import pytest

from multi_target_tracker.kalman import KalmanBank, KalmanConfig, noise_gain, process_noise, transition


def fixed(**values) -> KalmanConfig:
    """Noise independent of the box size, as in the seed's eq. 5."""
    return KalmanConfig(acceleration_noise_per_px=0.0, measurement_noise_per_px=0.0, **values)


def test_matrices_of_eq6():
    T = 0.5
    np.testing.assert_allclose(transition(T), [[1, .5, 0, 0], [0, 1, 0, 0], [0, 0, 1, .5], [0, 0, 0, 1]])
    np.testing.assert_allclose(noise_gain(T), [[.125, 0], [.5, 0], [0, .125], [0, .5]])
    # Q = σ² G Gᵀ: the x block is σ² [[T⁴/4, T³/2], [T³/2, T²]]
    Q = process_noise(T, 2.0)
    np.testing.assert_allclose(Q[:2, :2], 4 * np.array([[T ** 4 / 4, T ** 3 / 2], [T ** 3 / 2, T ** 2]]))
    assert Q[0, 2] == 0 and Q[1, 3] == 0


def test_predict_update_by_hand():
    # σ_a = 2 px/s², r = 1 px, σ_v0 = 3 px/s, T = 0.1 s; box (10, 20, 4, 6) -> centre (12, 23).
    bank = KalmanBank(fixed(acceleration_noise=2.0, measurement_noise=1.0, initial_velocity_std=3.0, size_gain=0.5))
    bank.add([[10, 20, 4, 6]])
    np.testing.assert_allclose(bank.x[0], [12, 0, 23, 0])
    np.testing.assert_allclose(np.diag(bank.P[0]), [1, 9, 1, 9])

    bank.predict(0.1)
    # F P Fᵀ = [[1 + 9·0.01, 0.9], [0.9, 9]];  Q = 4·[[0.000025, 0.0005], [0.0005, 0.01]]
    np.testing.assert_allclose(bank.P[0][:2, :2], [[1.0901, 0.902], [0.902, 9.04]])
    np.testing.assert_allclose(bank.x[0], [12, 0, 23, 0])

    bank.update([0], [[13.0, 23.0]], sizes=[[8.0, 6.0]])
    S = 1.0901 + 1.0
    k_pos, k_vel = 1.0901 / S, 0.902 / S
    np.testing.assert_allclose(bank.x[0], [12 + k_pos, k_vel, 23, 0])
    # P ← (I − K H) P on the x block
    np.testing.assert_allclose(bank.P[0][0, 0], 1.0901 - k_pos * 1.0901)
    np.testing.assert_allclose(bank.P[0][1, 1], 9.04 - k_vel * 0.902)
    np.testing.assert_allclose(bank.P[0][0, 1], 0.902 - k_pos * 0.902)
    # size smoothed with β = 0.5: w 4 -> 6, h stays 6
    np.testing.assert_allclose(bank.size[0], [6, 6])
    np.testing.assert_allclose(bank.boxes()[0], [12 + k_pos - 3, 20, 6, 6])


def test_velocity_in_pixels_per_second_from_stamps():
    bank = KalmanBank(fixed(measurement_noise=0.01, initial_velocity_std=1000.0))
    bank.add([[0, 0, 2, 2]])
    for k in range(1, 20):
        bank.predict(0.04)                             # 25 frames/s
        bank.update([0], [[1 + 2.0 * k, 1 - 1.0 * k]])  # 2 px and -1 px per frame
    np.testing.assert_allclose(bank.velocities[0], [50.0, -25.0], rtol=1e-3)


@pytest.mark.parametrize("mode, shrinks", [("prediction", True), ("none", False)])
def test_missed_frame_update(mode, shrinks):
    bank = KalmanBank(KalmanConfig(missed_update=mode))
    bank.add([[0, 0, 2, 2]])
    bank.predict(0.1)
    before = bank.P[0].copy()
    x_before = bank.x[0].copy()
    bank.coast([0])
    np.testing.assert_allclose(bank.x[0], x_before)    # updating with the prediction moves nothing
    assert (bank.P[0][0, 0] < before[0, 0]) == shrinks


def test_keep_removes_rows():
    bank = KalmanBank()
    bank.add([[0, 0, 2, 2], [10, 10, 2, 2], [20, 20, 4, 4]])
    bank.keep(np.array([True, False, True]))
    assert len(bank) == 2
    np.testing.assert_allclose(bank.positions, [[1, 1], [22, 22]])


def test_noise_grows_with_box_height():
    bank = KalmanBank(KalmanConfig(measurement_noise=1.0, measurement_noise_per_px=0.1,
                                   acceleration_noise=10.0, acceleration_noise_per_px=2.0))
    bank.add([[0, 0, 10, 10], [0, 0, 10, 100]])
    np.testing.assert_allclose(bank.measurement_std(bank.size[:, 1]), [1 + 1, 1 + 10])
    np.testing.assert_allclose(bank.innovation_variance(), [2 * (1 + 1) ** 2, 2 * (1 + 10) ** 2])  # P0 = R
    before = bank.P.copy()
    bank.predict(0.5)
    # velocity variance grows by σ² T² with σ = 10 + 2 h: 30 and 210 px/s²
    np.testing.assert_allclose(bank.P[:, 1, 1] - before[:, 1, 1], [30 ** 2 * 0.25, 210 ** 2 * 0.25])


def test_copy_predicts_apart_from_the_original():
    bank = KalmanBank(KalmanConfig())
    bank.add(np.array([[10.0, 20.0, 30.0, 40.0], [100.0, 50.0, 20.0, 10.0]]))
    bank.update(np.array([0, 1]), np.array([[26.0, 41.0], [111.0, 54.0]]))
    before = (bank.x.copy(), bank.cov.copy(), bank.size.copy())
    twin = bank.copy()
    twin.predict(0.5)
    assert twin.config is bank.config and not np.array_equal(twin.cov, before[1])
    for now, then in zip((bank.x, bank.cov, bank.size), before):
        np.testing.assert_array_equal(now, then)
    bank.predict(0.5)                                   # the same prediction on the original: the same numbers
    for mine, theirs in zip((twin.x, twin.cov, twin.size), (bank.x, bank.cov, bank.size)):
        np.testing.assert_array_equal(mine, theirs)
