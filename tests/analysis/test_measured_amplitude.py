"""Why the analysis needs the measured roll: a stand whose platform rolls 3 % more than
commanded (a kinematics error), fitted with the commanded amplitudes, gives C off by ~6 %
(C goes as 1/A^2, eq 1.1), far outside its SE; with the amplitudes measured from an
inclinometer's record (per-cycle sinusoid fits) C and T are recovered within their SE."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyrostand.analysis import paper_example as paper
from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.measured_roll import measure_roll
from gyrostand.analysis.synthetic import Design, synthetic_trials
from gyrostand.analysis.trials import TrialInput

TRUE = {"C_gcm2s2": 6e7, "T_s": 1.15}
ARM_CM = 50.0
COMMANDED = Design(
    direction_deg=np.array([30, 60, 120, 150, 30, 60, 120, 150]),
    amplitude_cm=np.array([20, 24, 22, 18, 24, 20, 18, 22], dtype=float),
    period_s=np.array([3.5, 4.5, 5.5, 6.5, 8.0, 3.5, 4.5, 5.5]),
)
SCALE = 1.03


def _inclinometer_amplitude_cm(amplitude_cm: float, period_s: float, rng) -> float:
    """The amplitude measured from 20 periods of an inclinometer at 100 Hz (0.02 deg noise,
    0.01 deg steps, a bias), converted back to cm at the arm."""
    t = np.arange(0.0, 20 * period_s, 0.01)
    theta_deg = math.degrees(amplitude_cm / ARM_CM) * np.sin(2 * math.pi * t / period_s)
    slope = np.round((theta_deg + 0.1 + rng.normal(0, 0.02, t.size)) / 0.01) * 0.01
    return math.radians(measure_roll(t, slope, period_s).amplitude) * ARM_CM


def test_measured_amplitudes_recover_c_and_t_where_commanded_ones_do_not():
    rng = np.random.default_rng(5)
    real = Design(COMMANDED.direction_deg, SCALE * COMMANDED.amplitude_cm, COMMANDED.period_s)
    trials = synthetic_trials(
        paper.CONSTANTS, real, ["fit"] * 8, **TRUE, sigma_deg=0.003, n_obs=16, rng=rng
    )
    commanded = [
        TrialInput(**{**t.__dict__, "amplitude_cm": float(a)})
        for t, a in zip(trials, COMMANDED.amplitude_cm, strict=True)
    ]
    measured = [
        TrialInput(
            **{
                **t.__dict__,
                "amplitude_cm": _inclinometer_amplitude_cm(t.amplitude_cm, t.period_s, rng),
            }
        )
        for t in trials
    ]
    for t, c in zip(measured, real.amplitude_cm, strict=True):
        assert abs(t.amplitude_cm / c - 1) < 1e-3  # the inclinometer sees the real roll
    wrong = analyze_campaign(commanded, paper.CONSTANTS, start=paper.START)
    right = analyze_campaign(measured, paper.CONSTANTS, start=paper.START)
    c_true = TRUE["C_gcm2s2"]
    # commanded: C scaled by 1 / 1.03^2, many SE away; T (a uniform scale) untouched
    assert wrong.estimates["C_gcm2s2"] / c_true == pytest.approx(1 / SCALE**2, rel=0.01)
    assert abs(wrong.estimates["C_gcm2s2"] - c_true) > 5 * wrong.fit.std_errors["C_gcm2s2"]
    for name, true in TRUE.items():
        assert abs(right.estimates[name] - true) < 3 * right.fit.std_errors[name]
