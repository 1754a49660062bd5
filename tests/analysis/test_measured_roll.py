"""The measured roll: a known sinusoid plus noise is recovered within the stated SE."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyrostand.analysis.measured_roll import RollFitError, measure_roll


def _record(seed: int, amp=5.0, period=4.1, phase=0.3, noise=0.05, dt=0.01, span=60.0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, span, dt)
    return t, amp * np.sin(2 * math.pi * t / period + phase) + 0.2 + rng.normal(0, noise, len(t))


def test_a_noisy_sinusoid_is_recovered_within_its_se():
    hits_a = hits_t = 0
    for seed in range(20):
        t, y = _record(seed)
        m = measure_roll(t, y, nominal_period_s=4.0)
        hits_a += abs(m.amplitude - 5.0) < 2 * m.amplitude_se
        hits_t += abs(m.period_s - 4.1) < 2 * m.period_se_s
    assert hits_a >= 17 and hits_t >= 17  # ~95 % inside 2 SE


def test_per_cycle_se_matches_least_squares_theory():
    # N samples of white noise sigma: SE(A) = sigma sqrt(2 / N) for a whole cycle
    t, y = _record(1)
    m = measure_roll(t, y, nominal_period_s=4.1)
    cycle = m.cycles[3]
    n = round(4.1 / 0.01)
    assert cycle.amplitude_se == pytest.approx(0.05 * math.sqrt(2 / n), rel=0.1)
    # the phase is of sin at the window's start: 2 pi t0 / tau + 0.3
    expected = (2 * math.pi * cycle.t0_s / 4.1 + 0.3 + math.pi) % (2 * math.pi) - math.pi
    assert cycle.phase_rad == pytest.approx(expected, abs=5 * cycle.phase_se_rad)


def test_cycle_to_cycle_variation_is_the_scatter():
    t = np.arange(0.0, 80.005, 0.01)  # 20 whole cycles
    amp = np.where(((t // 4.0) % 2) == 0, 4.0, 6.0)  # alternate cycles at 4 and 6
    m = measure_roll(t, amp * np.sin(2 * math.pi * t / 4.0), 4.0)
    assert m.amplitude == pytest.approx(5.0, abs=1e-6)
    assert m.amplitude_sd == pytest.approx(np.std([4.0, 6.0] * 10, ddof=1), rel=1e-6)
    assert m.amplitude_se == pytest.approx(m.amplitude_sd / math.sqrt(20), rel=1e-6)


def test_too_short_a_record_is_one_line():
    with pytest.raises(RollFitError, match="no whole cycle of 4 s"):
        measure_roll(np.arange(0, 3, 0.01), np.zeros(300), 4.0)
