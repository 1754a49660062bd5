"""The simulated compass switched on from rotor stop, one run-up after another.

A run-up is a fresh compass (switching off loses the sensitive element's state): at switch-on
the element lies `runup_error_deg` from its settle point and settles by the damped precession
of Bezvesilna & Gura eq 1 (`physics.DampedPrecession` with the compass's w0 and damping), the
readings carrying the compass's noise (`StandEngine`). Each run-up's settle point departs from
the compass's (true heading + `settle_point_error_deg`) by a draw of N(0, repeatability_sd_deg)
(seeded: run-up k of seed s is always the same). The truth a test compares with is here too."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from gyrostand.stand.engine import StandEngine
from gyrostand.stand.physics import DampedPrecession
from gyrostand.stand.simconfig import SimConfig

_RUNUP_STREAM = 35  # a seed stream of its own: the campaign's other draws stay as they were


def _seeds(config: SimConfig, k: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([config.seed, _RUNUP_STREAM, k])


def settle_scatter_deg(config: SimConfig, k: int) -> float:
    """The departure of run-up k's settle point from the compass's (true, hidden)."""
    rng = np.random.default_rng(_seeds(config, k))
    return float(rng.normal(0.0, config.compass.repeatability_sd_deg))


def runup_config(config: SimConfig, k: int) -> SimConfig:
    """The simulated compass of run-up k (k = 1, 2, ...): the element at the run-up error,
    the settle point moved by the run-up's scatter, noise of a seed of its own."""
    compass = config.compass
    compass = dataclasses.replace(
        compass,
        transient=True,
        initial_error_deg=compass.runup_error_deg,
        settle_point_error_deg=compass.settle_point_error_deg + settle_scatter_deg(config, k),
    )
    seed = int(_seeds(config, k).generate_state(1)[0])
    return dataclasses.replace(config, compass=compass, seed=seed)


def switch_on(config: SimConfig, k: int, at_s: float) -> StandEngine:
    """The compass of run-up k switched on at stand time `at_s` (its frames' stand clock
    continues from there; its physics starts at 0 = switch-on)."""
    return StandEngine(runup_config(config, k), clock_ms=round(at_s * 1000.0))


def true_settle_point_deg(config: SimConfig, k: int) -> float:
    """Run-up k's settle point heading (the reading it settles to at rest, noise aside)."""
    compass = runup_config(config, k).compass
    return compass.heading_deg + compass.settle_point_error_deg


def true_deviation_deg(config: SimConfig, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Stand seconds from switch-on and the element's deviation from its settle point (deg),
    noise-free, on the heading samples (the same integration as the engine's)."""
    compass = config.compass
    dt = 1.0 / config.heading_rate_hz
    w0 = 2.0 * math.pi / compass.undamped_period_s
    precession = DampedPrecession(w0, compass.damping_ratio * w0, dt, nonlinear=compass.nonlinear)
    precession.x_rad = math.radians(compass.runup_error_deg)
    n = math.floor(duration_s * config.heading_rate_hz) + 1
    return np.arange(n) * dt, np.degrees(precession.run(n))


def true_settling_time_s(config: SimConfig, half_band_deg: float, duration_s: float) -> float:
    """Stand seconds from switch-on after which the noise-free reading stays within
    +-half_band_deg of its settle point (within the first `duration_s`)."""
    t, x = true_deviation_deg(config, duration_s)
    outside = np.flatnonzero(np.abs(x) > half_band_deg)
    if outside.size == 0:
        return 0.0
    i = int(outside[-1])
    if i + 1 >= len(t):
        return math.inf
    # the crossing between the last sample outside and the next, linearly interpolated
    a, b = abs(x[i]) - half_band_deg, abs(x[i + 1]) - half_band_deg
    return float(t[i] + (t[i + 1] - t[i]) * a / (a - b))
