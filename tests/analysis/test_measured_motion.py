"""The measured motion of a rocking series: a roll-angle record turned into Potemkin 1982 model
1.1's A (arm x angle in rad) and tau per fitted cycle, the stand's reports averaged, and which
source a trial applies."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyrostand.analysis.measured_motion import (
    INCLINOMETER,
    STAND_REPORT,
    from_reports,
    from_roll,
    preferred,
)
from gyrostand.analysis.measured_roll import RollFitError


def test_a_roll_record_gives_a_and_tau_of_the_arm() -> None:
    """A 10 deg roll at 6.2 s on a 120 cm arm, sampled at 10 Hz with 0.01 deg noise and a
    0.3 deg bias: A = 120 x 10 pi / 180 = 20.944 cm, within 4 SE; tau within 4 SE."""
    rng = np.random.default_rng(3)
    t_ms = 40_000 + np.arange(0, 62_000, 100)
    t = (t_ms - t_ms[0]) / 1000.0
    angle = 0.3 + 10.0 * np.sin(2 * math.pi / 6.2 * t + 0.4) + 0.01 * rng.standard_normal(len(t))
    m = from_roll(INCLINOMETER, t_ms, angle, 6.0, 120.0)  # (from a nominal 6 s)
    assert abs(m.amplitude_cm - 120.0 * math.radians(10.0)) < 4 * m.amplitude_se_cm
    assert 0 < m.amplitude_se_cm < 0.01
    assert abs(m.period_s - 6.2) < 4 * m.period_se_s and m.period_se_s < 1e-3
    assert m.n_cycles == 9 and m.n_samples == len(t_ms) and m.direction_deg is None
    assert m.first_cycle_ms == 40_000
    assert abs(m.phase_deg - math.degrees(0.4)) < 1.0 and m.phase_sd_deg < 1.0


def test_too_short_a_record_is_refused() -> None:
    with pytest.raises(RollFitError, match="no whole cycle"):
        from_roll(INCLINOMETER, np.arange(0, 3000, 100), np.zeros(30), 6.0, 100.0)


def test_reports_are_averaged() -> None:
    m = from_reports(np.array([359.0, 1.0]), np.array([24.0, 24.2]), np.array([6.0, 6.1]))
    assert m.direction_deg is not None and abs((m.direction_deg + 180) % 360 - 180) < 1e-9
    assert m.amplitude_cm == pytest.approx(24.1)
    assert m.amplitude_sd_cm == pytest.approx(math.sqrt(0.02))  # sd of (24.0, 24.2)
    assert m.amplitude_se_cm == pytest.approx(0.1)  # sd / sqrt(2)
    assert (m.source, m.n_cycles, m.n_samples) == (STAND_REPORT, None, 2)


def test_the_inclinometer_is_preferred() -> None:
    report = from_reports(np.array([0.0]), np.array([24.0]), np.array([6.0]))
    assert preferred((report,)) is report
    roll = from_roll(
        INCLINOMETER,
        np.arange(0, 30_000, 100),
        np.sin(np.arange(300) * 2 * math.pi / 60),
        6.0,
        100.0,
    )
    assert preferred((report, roll)) is roll
    assert preferred(()) is None
