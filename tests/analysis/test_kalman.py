"""Kalman estimate of the settle state vs least squares (seed 003 compares both)."""

import numpy as np
import pytest

from gyrostand.analysis.kalman import SettleKalman
from gyrostand.analysis.settle import estimate_settle_point, observation_rows

T0_S = 84 * 60.0
OMEGA = 2 * np.pi / T0_S


@pytest.mark.parametrize("xi_ratio", [0.0, 0.35])
def test_diffuse_filter_equals_least_squares(xi_ratio: float) -> None:
    rng = np.random.default_rng(11)
    xi = xi_ratio * OMEGA
    t = 500.0 + np.arange(0, 2 * T0_S, 2.0)
    y = 87.0 + 9.0 * np.exp(-xi * (t - t[0])) * np.sin(OMEGA * (t - t[0]) + 1.0)
    y += rng.normal(0, 0.05, t.size)
    kf = SettleKalman(OMEGA, 0.05, damping_per_s=xi)
    kf.update_many(t, y)
    lsq = estimate_settle_point(t, y, OMEGA, xi)
    coef = np.linalg.lstsq(observation_rows(t - t[0], OMEGA, xi), y, rcond=None)[0]
    assert kf.state == pytest.approx(coef, abs=1e-7)
    assert kf.settle_point_deg == pytest.approx(lsq.settle_point_deg, abs=1e-7)
    # KF covariance with the true noise = sigma^2 (X^T X)^-1 of least squares
    rows = observation_rows(t - t[0], OMEGA, xi)
    assert kf.standard_error_deg == pytest.approx(
        0.05 * np.sqrt(np.linalg.inv(rows.T @ rows)[0, 0]), rel=1e-6
    )
    assert kf.n == t.size


def test_filter_tracks_least_squares_after_each_reading() -> None:
    """From a diffuse prior, even a few readings of a half-period record (ill-conditioned)."""
    rng = np.random.default_rng(2)
    t = np.arange(0, 0.5 * T0_S, 30.0)
    y = 10.0 + 3.0 * np.sin(OMEGA * t) + rng.normal(0, 0.02, t.size)
    kf = SettleKalman(OMEGA, 0.02)
    for k, (tk, yk) in enumerate(zip(t, y, strict=True)):
        kf.update(tk, yk)
        if k >= 10 and k % 10 == 0:
            lsq = estimate_settle_point(t[: k + 1], y[: k + 1], OMEGA)
            tol = 1e-6 * lsq.standard_error_deg  # the prior (s.d. 1e4 deg) weighs ~1e-8 here
            assert kf.settle_point_deg == pytest.approx(lsq.settle_point_deg, abs=tol)


def test_filter_unwraps_across_north() -> None:
    t = np.arange(0, T0_S, 20.0)
    heading = 0.5 + 3.0 * np.sin(OMEGA * t + 0.2)
    kf = SettleKalman(OMEGA, 0.01)
    kf.update_many(t, np.mod(heading, 360.0))
    assert kf.settle_point_deg == pytest.approx(0.5, abs=1e-6)


def test_standard_error_matches_monte_carlo_scatter() -> None:
    rng = np.random.default_rng(5)
    t = np.arange(0, 0.8 * T0_S, 20.0)
    xi = 0.3 * OMEGA
    clean = 5.0 + 4.0 * np.exp(-xi * t) * np.cos(OMEGA * t)
    finals, ses = [], []
    for _ in range(200):
        kf = SettleKalman(OMEGA, 0.1, damping_per_s=xi)
        kf.update_many(t, clean + rng.normal(0, 0.1, t.size))
        finals.append(kf.settle_point_deg)
        ses.append(kf.standard_error_deg)
    assert np.std(finals) == pytest.approx(np.mean(ses), rel=0.15)
    assert abs(np.mean(finals) - 5.0) < 4 * np.std(finals) / np.sqrt(200)
