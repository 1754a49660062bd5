"""The motion a stand really made during a rocking series, per measuring source: the amplitude
A (cm) and period tau (s) of Potemkin 1982 model 1.1, the direction K where the source knows it,
the phase, their scatter over the cycles, and how many cycles (or reports) they come from.

A roll-angle source (an inclinometer's slope, a drive's actual position) is fitted cycle by
cycle (`analysis.measured_roll`); its amplitude is an angle, and model 1.1's A is the arm's
displacement: A = arm x angle (rad). A smart stand's own reports (K, A, tau every status) are
averaged, their scatter being the reports' (no cycles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.measured_roll import measure_roll

INCLINOMETER = "inclinometer"
DRIVE_POSITION = "drive position"
STAND_REPORT = "stand report"
PREFERENCE = (INCLINOMETER, DRIVE_POSITION, STAND_REPORT)
"""Whose measured A and tau a trial applies, first found first: an independent sensor before
the drive's own position, before what a smart stand says it does."""


@dataclass(frozen=True)
class MeasuredMotion:
    source: str  # one of PREFERENCE
    amplitude_cm: float  # A, mean over the cycles (or reports)
    amplitude_se_cm: float
    amplitude_sd_cm: float  # cycle-to-cycle (report-to-report) scatter
    period_s: float  # tau
    period_se_s: float
    period_sd_s: float
    direction_deg: float | None  # K (None: the source does not know it)
    phase_deg: float | None  # of sin at the first fitted cycle's start (None: reports)
    phase_sd_deg: float | None
    first_cycle_ms: int | None  # that start, campaign clock
    n_cycles: int | None  # fitted cycles (None: reports)
    n_samples: int


def from_roll(
    source: str,
    t_ms: np.ndarray,
    angle_deg: np.ndarray,
    nominal_period_s: float,
    arm_length_cm: float,
) -> MeasuredMotion:
    """A roll-angle record fitted per cycle (RollFitError: no whole cycle to fit)."""
    t0 = int(t_ms[0])
    roll = measure_roll((np.asarray(t_ms) - t0) / 1000.0, angle_deg, nominal_period_s)
    cm_per_deg = arm_length_cm * math.pi / 180.0  # A = arm x angle (rad)
    w = 2.0 * math.pi / roll.period_s
    first = roll.cycles[0].t0_s
    # the phase each cycle implies at the first cycle's start: their scatter is the jitter
    phases = np.unwrap([c.phase_rad - w * (c.t0_s - first) for c in roll.cycles])
    return MeasuredMotion(
        source,
        roll.amplitude * cm_per_deg,
        roll.amplitude_se * cm_per_deg,
        roll.amplitude_sd * cm_per_deg,
        roll.period_s,
        roll.period_se_s,
        roll.period_sd_s,
        None,
        math.degrees(float(np.mean(phases))) % 360.0,
        math.degrees(float(np.std(phases, ddof=1))) if len(phases) > 1 else 0.0,
        t0 + round(first * 1000.0),
        len(roll.cycles),
        len(t_ms),
    )


def from_reports(
    direction_deg: np.ndarray,
    amplitude_cm: np.ndarray,
    period_s: np.ndarray,
    source: str = STAND_REPORT,
) -> MeasuredMotion:
    """A stand's statuses of its K, A, tau (a smart stand's own reports; a CiA 402 stand's
    fitted to the drive's actual position, `source` DRIVE_POSITION): their means (K circular),
    the SEs s / sqrt(n) (the reports are not independent measurements: a stand repeating one value
    gives SE 0)."""
    n = len(amplitude_cm)
    rad = np.radians(direction_deg)
    direction = math.degrees(math.atan2(np.sin(rad).mean(), np.cos(rad).mean())) % 360.0

    def sd(x: np.ndarray) -> float:
        return float(np.std(x, ddof=1)) if n > 1 else 0.0

    return MeasuredMotion(
        source,
        float(np.mean(amplitude_cm)),
        sd(amplitude_cm) / math.sqrt(n),
        sd(amplitude_cm),
        float(np.mean(period_s)),
        sd(period_s) / math.sqrt(n),
        sd(period_s),
        round(direction, 6),
        None,
        None,
        None,
        None,
        n,
    )


def preferred(motions: tuple[MeasuredMotion, ...]) -> MeasuredMotion | None:
    """The source a trial applies (`PREFERENCE`), None without any."""
    by_source = {m.source: m for m in motions}
    return next((by_source[s] for s in PREFERENCE if s in by_source), None)
