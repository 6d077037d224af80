"""Known-answer tests of the constant-velocity Kalman filter (values computed by hand)."""

from __future__ import annotations

import numpy as np
import pytest

from unitrack_env.agents.primitives.kalman import (
    CHI2_95_4DOF,
    KalmanConfig,
    KalmanFilter,
    xyah_to_xywh,
    xywh_to_xyah,
)

# One track measured at centre (50, 60), aspect 0.5, height 100.
Z0 = np.array([[50.0, 60.0, 0.5, 100.0]])
H = 100.0


def test_chi2_gate_matches_scipy() -> None:
    scipy_stats = pytest.importorskip("scipy.stats")
    assert CHI2_95_4DOF == pytest.approx(scipy_stats.chi2.ppf(0.95, 4), abs=1e-4)


def test_box_conversions_round_trip() -> None:
    boxes = np.array([[10.0, 20.0, 30.0, 60.0], [0.0, 0.0, 1.0, 4.0]])
    xyah = xywh_to_xyah(boxes)
    np.testing.assert_allclose(xyah, [[25.0, 50.0, 0.5, 60.0], [0.5, 2.0, 0.25, 4.0]])
    np.testing.assert_allclose(xyah_to_xywh(xyah), boxes)


def test_initiate_by_hand() -> None:
    mean, cov = KalmanFilter().initiate(Z0)
    np.testing.assert_array_equal(mean, [[50.0, 60.0, 0.5, 100.0, 0.0, 0.0, 0.0, 0.0]])
    # stds: 2*5=10 (u, v, h), 1e-2 (a), 10*0.625=6.25 (du, dv, dh), 1e-5 (da)
    expected = np.diag([100.0, 100.0, 1e-4, 100.0, 39.0625, 39.0625, 1e-10, 39.0625])
    np.testing.assert_allclose(cov[0], expected, rtol=1e-12, atol=0)


def test_predict_by_hand() -> None:
    kf = KalmanFilter()
    mean = np.array([[50.0, 60.0, 0.5, 100.0, 2.0, -1.0, 0.0, 0.5]])
    cov = np.diag([100.0, 100.0, 1e-4, 100.0, 39.0625, 39.0625, 1e-10, 39.0625])[None]
    new_mean, new_cov = kf.predict(mean, cov)
    # x' = x + v
    np.testing.assert_allclose(new_mean, [[52.0, 59.0, 0.5, 100.5, 2.0, -1.0, 0.0, 0.5]])
    # P' = F P F^T + Q, Q from the pre-prediction height (100): pos var 25, vel var 0.390625,
    # aspect var 1e-4, aspect velocity var 1e-10.
    e = np.zeros((8, 8))
    for p in (0, 1, 3):
        e[p, p] = 100.0 + 39.0625 + 25.0  # P_pp + P_vv + Q_pp
        e[p, p + 4] = e[p + 4, p] = 39.0625  # P_vv
        e[p + 4, p + 4] = 39.0625 + 0.390625
    e[2, 2] = 1e-4 + 1e-10 + 1e-4
    e[2, 6] = e[6, 2] = 1e-10
    e[6, 6] = 1e-10 + 1e-10
    np.testing.assert_allclose(new_cov[0], e, rtol=1e-12, atol=1e-18)


def test_update_by_hand_on_one_coordinate() -> None:
    """With a diagonal prior the update decouples per coordinate: check u and du."""
    kf = KalmanFilter()
    mean = np.array([[50.0, 60.0, 0.5, 100.0, 0.0, 0.0, 0.0, 0.0]])
    # Prior: var(u)=16, cov(u,du)=4, var(du)=9; same for v and h; aspect tiny.
    cov = np.zeros((1, 8, 8))
    for p in (0, 1, 3):
        cov[0, p, p], cov[0, p, p + 4], cov[0, p + 4, p], cov[0, p + 4, p + 4] = 16, 4, 4, 9
    cov[0, 2, 2], cov[0, 6, 6] = 1e-4, 1e-10
    z = np.array([[60.0, 60.0, 0.5, 100.0]])  # u measured 10 px to the right
    new_mean, new_cov = kf.update(mean, cov, z)
    # Measurement noise for u: (100/20)^2 = 25, so S = 16 + 25 = 41.
    s = 41.0
    k_u, k_du = 16.0 / s, 4.0 / s
    assert new_mean[0, 0] == pytest.approx(50.0 + k_u * 10.0)
    assert new_mean[0, 4] == pytest.approx(k_du * 10.0)
    np.testing.assert_allclose(new_mean[0, [1, 2, 3, 5, 6, 7]], [60.0, 0.5, 100.0, 0, 0, 0])
    assert new_cov[0, 0, 0] == pytest.approx(16.0 - 16.0 * 16.0 / s)
    assert new_cov[0, 0, 4] == pytest.approx(4.0 - 16.0 * 4.0 / s)
    assert new_cov[0, 4, 4] == pytest.approx(9.0 - 4.0 * 4.0 / s)
    # Aspect: S = 1e-4 + (1e-1)^2, gain 1e-4 / S; the measurement equals the mean, so no move.
    assert new_cov[0, 2, 2] == pytest.approx(1e-4 - 1e-8 / (1e-4 + 1e-2))
    np.testing.assert_allclose(new_cov[0], new_cov[0].T)


def test_gating_distance_by_hand() -> None:
    kf = KalmanFilter()
    mean, cov = kf.initiate(Z0)
    # Projected covariance: diag(100 + 25, 100 + 25, 1e-4 + 1e-2, 100 + 25).
    z = np.array([[60.0, 60.0, 0.5, 100.0], [50.0, 45.0, 0.6, 110.0], [50, 60, 0.5, 100]])
    d = kf.gating_distance(mean, cov, z)
    expected = [
        10.0**2 / 125.0,
        15.0**2 / 125.0 + 0.1**2 / (1e-4 + 1e-2) + 10.0**2 / 125.0,
        0.0,
    ]
    np.testing.assert_allclose(d, [expected], rtol=1e-10, atol=1e-12)


def test_batched_predict_equals_per_track() -> None:
    kf = KalmanFilter()
    zs = np.array([[50.0, 60.0, 0.5, 100.0], [10.0, 20.0, 0.4, 40.0], [300, 200, 0.7, 80]])
    mean, cov = kf.initiate(zs)
    mean[:, 4:] = [[1, 2, 0, 1], [0, -1, 0, 0], [3, 0, 0, -2]]
    batch_mean, batch_cov = kf.predict(mean, cov)
    for i in range(3):
        m, c = kf.predict(mean[i : i + 1], cov[i : i + 1])
        np.testing.assert_allclose(batch_mean[i], m[0])
        np.testing.assert_allclose(batch_cov[i], c[0])


def test_config_is_used_and_validated() -> None:
    kf = KalmanFilter(KalmanConfig(std_weight_position=0.1, initial_position_factor=1.0))
    _, cov = kf.initiate(Z0)
    assert cov[0, 0, 0] == pytest.approx((0.1 * H) ** 2)
    with pytest.raises(ValueError, match="std_weight_velocity"):
        KalmanConfig(std_weight_velocity=0.0)


def test_bad_shapes_raise() -> None:
    kf = KalmanFilter()
    with pytest.raises(ValueError, match=r"\(n, 4\)"):
        kf.initiate(np.zeros(4))
    mean, cov = kf.initiate(Z0)
    with pytest.raises(ValueError, match="one measurement per track"):
        kf.update(mean, cov, np.zeros((2, 4)) + 1)
