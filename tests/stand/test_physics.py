"""Physics of the simulated unit against the paper, closed forms and an independent ODE solver."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import lfilter

from gyrostand.stand.engine import StandEngine
from gyrostand.stand.physics import CorrelatedNoise, DampedPrecession, rolling_error_rad
from gyrostand.stand.simconfig import CompassParams
from tests.stand.frames import QUIET, command, config, headings

PAPER = {  # seed 000, example: known constants B
    "lP_gcm2s2": 6.57e6,
    "H1_gcm2s": 1.55e8,
    "U_rad_s": 7.3e-5,
    "g_cm_s2": 981.0,
}


def test_model_1_1_reproduces_the_papers_forecast() -> None:
    # seed 000 example: C = 6.8e7, T = 1.0, K = 45, A = 65 cm, tau = 7 s, phi = 57 -> 2.322 deg
    alpha = rolling_error_rad(45, 65, 7, C_gcm2s2=6.8e7, T_s=1.0, latitude_deg=57, **PAPER)
    assert abs(math.degrees(alpha)) == pytest.approx(2.322, rel=0.005)


def test_model_1_1_reproduces_the_papers_control_trial() -> None:
    # trial 5 (K 31, A 23.5, tau 6.2) with the fitted C, T: predicted +0.307 deg; the paper's
    # experimental accuracy is +-0.015 deg
    alpha = rolling_error_rad(
        31, 23.5, 6.2, C_gcm2s2=6.8349685e7, T_s=1.0167358, latitude_deg=46.5, **PAPER
    )
    assert math.degrees(alpha) == pytest.approx(0.307, abs=0.015)


@pytest.mark.parametrize(
    ("k_deg", "a_cm", "tau_s", "measured_deg"),
    [(332, 24, 8, -0.117), (18, 24, 6.3, 0.21), (316, 23, 5.5, -0.466), (346, 11.8, 3.5, -0.401)],
)
def test_model_1_1_has_the_sign_of_the_papers_trials(k_deg, a_cm, tau_s, measured_deg) -> None:
    alpha = rolling_error_rad(
        k_deg, a_cm, tau_s, C_gcm2s2=6.8349685e7, T_s=1.0167358, latitude_deg=46.5, **PAPER
    )
    assert math.copysign(1, alpha) == math.copysign(1, measured_deg)


def damped_closed_form(t: np.ndarray, x0: float, w0: float, xi: float) -> np.ndarray:
    """seed 003 eq 2, x = A e^(-xi t) sin(w t + phi), for x(0) = x0 and x'(0) = 0."""
    w = math.sqrt(w0**2 - xi**2)
    phi = math.atan2(w, xi)  # x'(0) = A (w cos phi - xi sin phi) = 0
    return x0 / math.sin(phi) * np.exp(-xi * t) * np.sin(w * t + phi)


def test_linear_precession_steps_follow_the_closed_form() -> None:
    w0, xi = 2 * math.pi / 5064, 0.7 * 2 * math.pi / 5064
    precession = DampedPrecession(w0, xi, 0.1, nonlinear=False)
    precession.x_rad = 0.01
    x = np.array([precession.x_rad] + [precession.step() for _ in range(50_000)])
    expected = damped_closed_form(np.arange(len(x)) * 0.1, 0.01, w0, xi)
    assert np.max(np.abs(x - expected)) < 1e-12


def test_rocking_start_transient_in_the_frames_matches_the_damped_solution() -> None:
    cfg = config(
        noise=QUIET.__dict__,
        compass={"nonlinear": False, "harmonic_p_deg_per_g": 0, "harmonic_2p_deg_per_g": 0},
        heading_rate_hz=1.0,
    )
    engine = StandEngine(cfg)
    engine.advance_to(100.0)
    command(engine, "set", 45, 50, 3)
    (ack,) = command(engine, "start")
    shift = CompassParams().settled_shift_deg(45, 50, 3)  # 10.5 deg: a large, visible step
    assert engine.equilibrium_deg == pytest.approx(shift)
    t, reading, _ = headings(engine.advance_to(100.0 + 4 * 3600))
    after = t > ack.stand_time_ms / 1000  # the command takes effect at the next sample
    t0 = t[after][0]
    w0 = 2 * math.pi / cfg.compass.undamped_period_s
    expected = (
        120.0
        + shift
        + np.degrees(damped_closed_form(t[after] - t0, math.radians(-shift), w0, 0.7 * w0))
    )
    assert np.max(np.abs(reading[after] - expected)) < 0.0006  # frame resolution 0.001 deg
    assert np.all(reading[~after] == 120.0)


def test_nonlinear_transient_matches_an_ode_solver_and_differs_from_the_linear_one() -> None:
    cfg = config(noise=QUIET.__dict__, compass={"initial_error_deg": 60.0}, heading_rate_hz=1.0)
    t, reading, _ = headings(StandEngine(cfg).advance_to(3 * 3600))
    w0 = 2 * math.pi / cfg.compass.undamped_period_s
    xi = 0.7 * w0
    solution = solve_ivp(
        lambda _, y: [y[1], -2 * xi * y[1] - w0**2 * math.sin(y[0])],  # seed 003 eq 1
        (0, t[-1]),
        [math.radians(60.0), 0.0],
        t_eval=t,
        rtol=1e-11,
        atol=1e-13,
    )
    assert np.max(np.abs(reading - (120.0 + np.degrees(solution.y[0])))) < 0.0006
    linear = 120.0 + np.degrees(damped_closed_form(t, math.radians(60.0), w0, xi))
    assert np.max(np.abs(reading - linear)) > 1.0  # the sin term matters at 60 deg


def test_settled_mean_shift_while_rocking_equals_model_1_1() -> None:
    engine = StandEngine(config(heading_rate_hz=1.0, seed=11))
    t_before, before, _ = headings(engine.advance_to(3600.0))
    command(engine, "set", 31, 23.5, 6.2)
    command(engine, "start")
    t, rocking, _ = headings(engine.advance_to(3600.0 + 5 * 3600))
    settled = t > 3600.0 + 3 * 3600  # 3 h: the 84-min, 0.7-damped transient is < 0.1 % left
    shift = CompassParams().settled_shift_deg(31, 23.5, 6.2)
    # sd of a 2-h mean of the default noise (sigma 0.01, 1/mu 20 s) is ~0.0008 deg
    assert rocking[settled].mean() - 120.0 == pytest.approx(shift, abs=0.004)
    assert before.mean() == pytest.approx(120.0, abs=0.004)
    assert shift == pytest.approx(0.3153, abs=1e-4)


def test_stopping_returns_the_reading_to_the_true_heading() -> None:
    cfg = config(noise=QUIET.__dict__, compass={"harmonic_p_deg_per_g": 0}, heading_rate_hz=1.0)
    engine = StandEngine(cfg)
    command(engine, "set", 45, 40, 4)
    command(engine, "start")
    engine.advance_to(4 * 3600)
    command(engine, "stop")
    t, reading, _ = headings(engine.advance_to(8 * 3600))
    assert engine.equilibrium_deg == 0.0
    assert reading[-1] == pytest.approx(120.0, abs=0.002)
    assert reading[0] == pytest.approx(120.0 + cfg.compass.settled_shift_deg(45, 40, 4), abs=0.01)


def autocorrelation(x: np.ndarray, lags: int) -> np.ndarray:
    x = x - x.mean()
    return np.array([np.dot(x[: len(x) - k], x[k:]) / len(x) for k in range(lags)])


def test_correlated_noise_has_exponential_autocorrelation() -> None:
    sigma, mu, dt = 0.05, 0.5, 0.1
    cfg = config(
        noise={"corr_sigma_deg": sigma, "corr_mu_per_s": mu, "white_sigma_deg": 0, "quantum_deg": 0}
    )
    _, reading, _ = headings(StandEngine(cfg).advance_to(4000.0))
    lags = np.arange(60)
    k = autocorrelation(reading, len(lags))
    assert k[0] == pytest.approx(sigma**2, rel=0.15)
    # seed 004 §8.3: K(tau) = sigma^2 exp(-mu |tau|); estimator sd ~0.02 of sigma^2 here
    assert np.max(np.abs(k / k[0] - np.exp(-mu * lags * dt))) < 0.08
    fit = np.polyfit(lags[:15] * dt, np.log(k[:15] / k[0]), 1)
    assert -fit[0] == pytest.approx(mu, rel=0.15)


def test_white_noise_is_uncorrelated_and_quantisation_applies() -> None:
    cfg = config(noise={"corr_sigma_deg": 0, "white_sigma_deg": 0.05, "quantum_deg": 0.01})
    _, reading, _ = headings(StandEngine(cfg).advance_to(2000.0))
    k = autocorrelation(reading, 3)
    assert math.sqrt(k[0]) == pytest.approx(0.05, rel=0.05)
    assert abs(k[1] / k[0]) < 0.05
    steps = reading / 0.01
    assert np.max(np.abs(steps - np.round(steps))) < 1e-6


def test_correlated_noise_chunks_equal_one_draw() -> None:
    whole = CorrelatedNoise(1.0, 0.5, 0.1, np.random.default_rng(4)).sample(1000)
    chunked = CorrelatedNoise(1.0, 0.5, 0.1, np.random.default_rng(4))
    parts = [chunked.sample(n) for n in (1, 0, 337, 662)]
    assert np.array_equal(whole, np.concatenate(parts))


def test_correlated_noise_is_scipys_ar1_filter_to_the_bit() -> None:
    """The recursion gives lfilter's numbers exactly (what it replaced: the same campaigns)."""
    sigma, mu, step = 0.02, 0.05, 0.1
    noise = CorrelatedNoise(sigma, mu, step, np.random.default_rng(7))
    ours = np.concatenate([noise.sample(n) for n in (1, 500, 0, 20_000)])
    w = np.random.default_rng(7).standard_normal(20_501)
    r = math.exp(-mu * step)
    drive = sigma * math.sqrt(1.0 - r**2) * w
    drive[0] = sigma * w[0]
    assert np.array_equal(ours, lfilter([1.0], [1.0, -r], drive))
    k = autocorrelation(ours, 11)  # and it is the process asked for: sigma^2 e^(-mu tau)
    assert k[10] / k[0] == pytest.approx(math.exp(-mu * 10 * step), abs=0.05)


def test_drift_and_spurious_harmonic() -> None:
    noise = QUIET.__dict__ | {"drift_deg_per_h": 2.0}
    t, reading, _ = headings(StandEngine(config(noise=noise)).advance_to(1800.0))
    assert np.polyfit(t, reading, 1)[0] * 3600 == pytest.approx(2.0, rel=0.001)
    noise = QUIET.__dict__ | {"spurious_amplitude_deg": 0.05, "spurious_period_s": 30.0}
    t, reading, _ = headings(StandEngine(config(noise=noise)).advance_to(600.0))
    amplitude = harmonic_amplitudes(t, reading, [2 * math.pi / 30.0])[0]
    assert amplitude == pytest.approx(0.05, abs=0.001)


def harmonic_amplitudes(t: np.ndarray, y: np.ndarray, omegas: list[float]) -> np.ndarray:
    """Least-squares amplitudes of sinusoids at the given angular frequencies (plus a mean)."""
    columns = [np.ones_like(t)]
    for w in omegas:
        columns += [np.sin(w * t), np.cos(w * t)]
    coef, *_ = np.linalg.lstsq(np.column_stack(columns), y, rcond=None)
    return np.hypot(coef[1::2], coef[2::2])


def test_rocking_adds_components_at_p_and_2p() -> None:
    cfg = config(noise=QUIET.__dict__, compass={"transient": False})
    engine = StandEngine(cfg)
    command(engine, "set", 45, 40, 4)
    command(engine, "start")
    t, reading, _ = headings(engine.advance_to(400.0))
    p = 2 * math.pi / 4
    accel_g = 40 * p**2 / 981.0
    amplitudes = harmonic_amplitudes(t, reading, [p, 2 * p])
    assert amplitudes == pytest.approx([1.0 * accel_g, 0.5 * accel_g], abs=0.001)
    assert reading.mean() == pytest.approx(120 + cfg.compass.settled_shift_deg(45, 40, 4), abs=0.01)


def test_a_campaign_starts_with_the_compass_at_its_settle_point() -> None:
    """Issue 34, trial 1's suspects: the compass a campaign starts with is settled (no start-up
    transient: its first series reads the true heading, noise aside), and the correlated noise
    is stationary from its first sample (drawn from N(0, sigma^2), not started at 0, which
    would leave sigma^2 (1 - r^2) = 1 % of it)."""
    engine = StandEngine(config(noise=QUIET.__dict__, heading_rate_hz=1.0))
    t, reading, _ = headings(engine.advance_to(7200.0))
    assert t[-1] == 7200.0 and np.all(reading == 120.0)
    sigma, mu, step = 0.01, 0.05, 0.1
    first = np.array(
        [
            CorrelatedNoise(sigma, mu, step, np.random.default_rng(s)).sample(601)
            for s in range(3000)
        ]
    )
    for k in (0, 600):  # the first sample and one a minute later (correlation e^-3)
        assert np.var(first[:, k]) == pytest.approx(sigma**2, rel=0.08)  # SE 2.6 %
        assert abs(np.mean(first[:, k])) < 4 * sigma / math.sqrt(3000)
