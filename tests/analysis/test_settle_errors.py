"""Error terms of the settle estimate (seed 003 eqs 11-13) against independent computations:
the continuous normal equations by quadrature, the seed's eq 11 written out, and direct
numerical integration of the nonlinear equation 1."""

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from gyrostand.analysis.settle import (
    d1_discrete,
    d1_limit,
    d2_discrete,
    d2_limit,
    disturbance_limit,
    error_terms_for,
    estimate_settle_point,
    settle_error_terms,
    settle_response,
)

OMEGA0 = 2 * np.pi / 100.0


def continuous_response(signal, u: float) -> float:
    """R-component of the continuous least-squares fit of signal(x) on [0, u] (omega0 = 1), by
    quadrature of the Gram matrix: independent of the SVD solver under test."""
    basis = [lambda x: 1.0, np.sin, np.cos]
    gram = [[quad(lambda x, f=f, g=g: f(x) * g(x), 0, u)[0] for g in basis] for f in basis]
    rhs = [quad(lambda x, f=f: f(x) * signal(x), 0, u, limit=200)[0] for f in basis]
    return float(np.linalg.solve(gram, rhs)[0])


@pytest.mark.parametrize("u", [2.0, 5.0, 4 * np.pi + 1.0, 20.0])
@pytest.mark.parametrize("phi", [0.3, 2.2])
def test_limit_weights_match_continuous_least_squares(u: float, phi: float) -> None:
    c = phi + u / 2
    assert continuous_response(lambda x: -x * np.cos(x + phi), u) == pytest.approx(
        d1_limit(u) * np.sin(c), abs=1e-9
    )
    assert continuous_response(lambda x: np.sin(3 * (x + phi)), u) == pytest.approx(
        -d2_limit(u) * np.sin(3 * c), abs=1e-9
    )


def seed_eq11(signal: np.ndarray, lam: float) -> float:
    """dR^ of seed 003 eq 11 written out with k1, k2, k3 and f1-f3."""
    n = signal.size
    i = np.arange(n)
    k1 = np.sin(lam / 2) * (n * np.sin(lam) + np.sin(n * lam))
    k2 = -2 * np.sin(n * lam / 2) * np.sin((n - 1) / 2 * lam) * np.sin(lam)
    k3 = -2 * np.sin(n * lam / 2) * np.cos((n - 1) / 2 * lam) * np.sin(lam)
    f = (signal.sum(), signal @ np.sin(lam * i), signal @ np.cos(lam * i))
    den = n * k1 - 4 * np.cos(lam / 2) * np.sin(n * lam / 2) ** 2
    return (k1 * f[0] + k2 * f[1] + k3 * f[2]) / den


@pytest.mark.parametrize(("lam", "n"), [(0.3, 20), (0.5, 9), (1.1, 5), (0.05, 101)])
@pytest.mark.parametrize("phi", [0.3, 1.2, 2.5])
def test_discrete_weights_match_seed_eq11(lam: float, n: int, phi: float) -> None:
    x = lam * np.arange(n)
    c = phi + (n - 1) * lam / 2
    assert seed_eq11(-x * np.cos(x + phi), lam) == pytest.approx(
        d1_discrete(lam, n) * np.sin(c), abs=1e-10
    )
    assert seed_eq11(np.sin(3 * (x + phi)), lam) == pytest.approx(
        -d2_discrete(lam, n) * np.sin(3 * c), abs=1e-10
    )


def test_discrete_weights_tend_to_the_limit() -> None:
    u = 2 * np.pi * 2.3
    for n in (2001, 20001):
        assert d1_discrete(u / (n - 1), n) == pytest.approx(d1_limit(u), rel=2e3 / n)
        assert d2_discrete(u / (n - 1), n) == pytest.approx(d2_limit(u), rel=2e3 / n)


def simulate_eq1(amp_rad, phase, xi, record_s, n=4001):
    """Seed 003 eq 1, alpha'' + 2 xi alpha' + omega0^2 sin(alpha) = 0, integrated numerically from
    the state of alpha1 = A0 e^(-xi t) sin(pt + phi0) + A0^3/192 e^(-xi t) sin 3(pt + phi0)."""
    p = OMEGA0 * (1 - amp_rad**2 / 16)
    a1 = amp_rad**3 / 192
    a0 = amp_rad * np.sin(phase) + a1 * np.sin(3 * phase)
    v0 = amp_rad * p * np.cos(phase) + 3 * a1 * p * np.cos(3 * phase) - xi * a0
    t = np.linspace(0, record_s, n)
    sol = solve_ivp(
        lambda _, s: [s[1], -2 * xi * s[1] - OMEGA0**2 * np.sin(s[0])],
        (0, record_s),
        [a0, v0],
        t_eval=t,
        rtol=1e-11,
        atol=1e-13,
        method="DOP853",
    )
    return t, np.degrees(sol.y[0])


CASES = {
    # name: (A0 rad, phi0, xi / omega0, omega_used / omega0 - 1, periods, relevant term)
    "nonisochronism": (0.3, 0.4, 0.0, 0.0, 2.3, "nonisochronism_deg"),
    "nonisochronism-short": (0.3, 2.0, 0.0, 0.0, 0.8, "nonisochronism_deg"),
    "damping": (0.01, 1.5, 1e-3, 0.0, 1.3, "damping_deg"),
    "damping-long": (0.01, 2.6, 1e-3, 0.0, 3.4, "damping_deg"),
    "mismatch": (0.02, 1.1, 0.0, 3e-3, 1.7, "frequency_mismatch_deg"),
}


@pytest.mark.parametrize("case", CASES)
def test_error_terms_match_simulation_of_eq1(case: str) -> None:
    amp, phase, xi_ratio, mismatch, periods, term = CASES[case]
    record_s = periods * 2 * np.pi / OMEGA0
    t, reading = simulate_eq1(amp, phase, xi_ratio * OMEGA0, record_s)
    omega_used = OMEGA0 * (1 + mismatch)
    error = estimate_settle_point(t, 30.0 + reading, omega_used).settle_point_deg - 30.0
    terms = settle_error_terms(
        np.degrees(amp),
        phase,
        OMEGA0,
        record_s,
        damping_per_s=xi_ratio * OMEGA0,
        omega_used_rad_s=omega_used,
        n_samples=t.size,
    )
    assert abs(getattr(terms, term)) > 0.9 * abs(terms.total_deg)  # the case isolates a term
    assert terms.total_deg == pytest.approx(error, rel=0.03)


def test_compensation_removes_most_of_the_error() -> None:
    """alpha^ = R^ - sum dR^ with A^, phi^ taken from the estimate itself."""
    t, reading = simulate_eq1(0.3, 0.4, 0.0, 2.3 * 2 * np.pi / OMEGA0)
    est = estimate_settle_point(t, 30.0 + reading, OMEGA0)
    compensated = error_terms_for(est, OMEGA0).compensate(est.settle_point_deg)
    assert abs(est.settle_point_deg - 30.0) > 0.04
    assert abs(compensated - 30.0) < 0.05 * abs(est.settle_point_deg - 30.0)


@pytest.mark.parametrize("time_const_s", [10.0, 50.0])
def test_exponential_disturbance_limit_and_monotone_decay(time_const_s: float) -> None:
    """dR5 of eq 13 (integrals) vs the sampled eq 11 on a dense grid (equal weights: O(dt/tau)
    apart); and the seed's finding that an exponential disturbance's error falls monotonically
    with observation time."""

    def eps(t):
        return np.exp(-t / time_const_s)

    records = np.linspace(150.0, 600.0, 10)
    limits = [disturbance_limit(eps, OMEGA0, rec) for rec in records]
    for rec, lim in zip(records, limits, strict=True):
        tau = np.linspace(0, rec, 20001)
        assert settle_response(tau, eps(tau), OMEGA0) == pytest.approx(lim, rel=3e-3)
    assert np.all(np.diff(limits) < 0)
