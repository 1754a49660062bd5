"""Settle-point least squares (seed 003 eqs 3-8) against the seed's closed form and simulation."""

import numpy as np
import pytest

from gyrostand.analysis.errors import SingularDesignError
from gyrostand.analysis.settle import estimate_settle_point, estimate_settle_point_free

T0_S = 84 * 60.0
OMEGA = 2 * np.pi / T0_S


def seed_eq8_settle_point(alpha: np.ndarray, lam: float) -> float:
    """R^ of seed 003 eq 8 for uniform sampling, written out from the paper (k1, k2, k3, S1-S3)."""
    n = alpha.size
    i = np.arange(n)
    k1 = np.sin(lam / 2) * (n * np.sin(lam) + np.sin(n * lam))
    k2 = -2 * np.sin(n * lam / 2) * np.sin((n - 1) / 2 * lam) * np.sin(lam)
    k3 = -2 * np.sin(n * lam / 2) * np.cos((n - 1) / 2 * lam) * np.sin(lam)
    s1, s2, s3 = alpha.sum(), alpha @ np.sin(lam * i), alpha @ np.cos(lam * i)
    return (k1 * s1 + k2 * s2 + k3 * s3) / (n * k1 - 4 * np.cos(lam / 2) * np.sin(n * lam / 2) ** 2)


@pytest.mark.parametrize(("n", "lam"), [(3, 0.7), (10, 0.3), (60, 0.05), (7, np.pi / 2)])
def test_least_squares_matches_seed_closed_form(n: int, lam: float) -> None:
    rng = np.random.default_rng(n)
    alpha = 100 + rng.normal(size=n)
    est = estimate_settle_point(np.arange(n) * lam, alpha, 1.0)
    assert est.settle_point_deg == pytest.approx(seed_eq8_settle_point(alpha, lam), abs=1e-9)


def test_seed_extra_forbidden_value_is_solvable() -> None:
    """Eq 7 also forbids lambda = pi/2, but the n = 3 determinant is 2 sin(l)(cos(l) - 1) != 0."""
    t = np.arange(3) * (np.pi / 2)
    rows = np.column_stack([np.ones(3), np.sin(t), np.cos(t)])
    assert np.linalg.matrix_rank(rows) == 3
    assert np.linalg.det(rows) == pytest.approx(2 * np.sin(np.pi / 2) * (np.cos(np.pi / 2) - 1))
    est = estimate_settle_point(t, np.array([1.0, 2.0, 4.0]), 1.0)
    assert est.settle_point_deg == pytest.approx(np.linalg.solve(rows, [1.0, 2.0, 4.0])[0])


@pytest.mark.parametrize("lam", [np.pi, 2 * np.pi, 3 * np.pi])
def test_forbidden_sampling_interval_is_refused(lam: float) -> None:
    t = np.arange(50) * lam / OMEGA
    with pytest.raises(SingularDesignError, match="eq 7"):
        estimate_settle_point(t, np.ones(50), OMEGA)


def test_too_few_readings_are_refused() -> None:
    with pytest.raises(SingularDesignError, match="n >= 3"):
        estimate_settle_point([0.0, 1.0], [1.0, 2.0], OMEGA)


def test_noise_free_records_are_recovered_exactly() -> None:
    t = 1000.0 + np.arange(0, 0.6 * T0_S, 5.0)
    xi = 0.3 * OMEGA
    truth = 123.4 + 8.0 * np.exp(-xi * (t - t[0])) * np.sin(OMEGA * (t - t[0]) + 2.1)
    est = estimate_settle_point(t, truth, OMEGA, xi)
    assert (est.settle_point_deg, est.amplitude_deg, est.phase_rad) == pytest.approx(
        (123.4, 8.0, 2.1), abs=1e-9
    )
    assert est.predict(t) == pytest.approx(truth, abs=1e-9)
    assert est.to_dict()["n"] == t.size


def test_heading_across_north_is_unwrapped() -> None:
    t = np.arange(0, 1.5 * T0_S, 10.0)
    heading = 1.0 + 4.0 * np.sin(OMEGA * t + 0.3)
    est = estimate_settle_point(t, np.mod(heading, 360.0), OMEGA)
    assert est.settle_point_deg - 360.0 * (heading[0] < 0) == pytest.approx(1.0, abs=1e-9)


def ar1(rng: np.random.Generator, n: int, rho: float, sd: float, reps: int) -> np.ndarray:
    """`reps` stationary AR(1) records of length n with lag-1 correlation rho and s.d. sd."""
    x = np.empty((reps, n))
    x[:, 0] = rng.normal(0, sd, reps)
    shocks = rng.normal(0, sd * np.sqrt(1 - rho**2), (reps, n))
    for i in range(1, n):
        x[:, i] = rho * x[:, i - 1] + shocks[:, i]
    return x


@pytest.mark.parametrize(("rho", "white_sd"), [(0.0, 0.0), (0.9, 0.0), (0.8, 0.05)])
def test_standard_error_matches_monte_carlo_scatter(rho: float, white_sd: float) -> None:
    """Reported SE (with the inflation for correlated noise) vs the scatter of R^ over 300 noisy
    records of 0.7 T0 with known damping: shorter than one period, as the damped model allows.
    Noise: white, AR(1), and AR(1) plus as much white noise (seed 004's exponential + white),
    where the lag-1 rule (1 + r1) / (1 - r1) alone would give two thirds of the SE."""
    rng = np.random.default_rng(7)
    t = np.arange(0, 0.7 * T0_S, 10.0)
    xi = 0.35 * OMEGA
    clean = 50.0 + 10.0 * np.exp(-xi * t) * np.sin(OMEGA * t + 0.5)
    noise = ar1(rng, t.size, rho, 0.05, 300) + rng.normal(0, white_sd, (300, t.size))
    ests = [estimate_settle_point(t, clean + e, OMEGA, xi) for e in noise]
    r_hat = np.array([e.settle_point_deg for e in ests])
    reported = np.sqrt(np.mean([e.standard_error_deg**2 for e in ests]))
    assert abs(r_hat.mean() - 50.0) < 4 * r_hat.std() / np.sqrt(r_hat.size)
    assert reported == pytest.approx(r_hat.std(), rel=0.15)


def test_free_omega_and_damping_are_recovered() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0, 1.5 * T0_S, 10.0)
    xi = 0.2 * OMEGA
    y = 200.0 + 6.0 * np.exp(-xi * t) * np.sin(OMEGA * t - 1.0) + rng.normal(0, 0.01, t.size)
    est = estimate_settle_point_free(t, y, 1.05 * OMEGA, 0.15 * OMEGA)
    assert est.settle_point_deg == pytest.approx(200.0, abs=4 * est.standard_error_deg)
    assert est.omega_rad_s == pytest.approx(OMEGA, abs=4 * est.omega_se_rad_s)
    assert est.damping_per_s == pytest.approx(xi, abs=4 * est.damping_se_per_s)
    assert est.omega_se_rad_s < 0.01 * OMEGA
