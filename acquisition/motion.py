"""The rocking series' measured motion, as the engine collects it: every measuring source's
samples while the series is observed (an inclinometer's slope, later a drive's actual position:
`RollSample`s of any source name), the smart stand's own reports, and at the series' end one
`MeasuredMotion` per source, the one the trial applies, and whether it stays within the plan's
[tracking] tolerance."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.measured_motion import (
    MeasuredMotion,
    from_reports,
    from_roll,
)
from gyrostand.analysis.measured_roll import RollFitError
from gyrostand.frames.batch import RollSample, Statuses
from gyrostand.plan.model import Plan, TrialPlan


@dataclass(frozen=True)
class SeriesMotion:
    motions: tuple[MeasuredMotion, ...]  # one per source that measured the series
    notes: tuple[str, ...]  # why an expected source measured nothing (warning events)


class MotionRecorder:
    def __init__(self, plan: Plan, report_source: str) -> None:
        self.plan = plan
        self.report_source = report_source  # whose the statuses' K, A, tau are
        self._samples: dict[str, list[tuple[int, float]]] = {}
        self._reports: list[tuple[float, float, float]] = []

    def reset(self) -> None:
        self._samples = {}
        self._reports = []

    def sample(self, s: RollSample) -> None:
        self._samples.setdefault(s.source, []).append((s.t_ms, s.angle_deg))

    def reports(self, s: Statuses, start: int, stop: int) -> None:
        """The stand's statuses start..stop-1 (its own K, A, tau)."""
        for i in range(start, stop):
            row = (float(s.direction_deg[i]), float(s.amplitude_cm[i]), float(s.period_s[i]))
            self._reports.append(row)

    def series(self, trial: TrialPlan) -> SeriesMotion:
        """The measured motion of the rocking series just observed."""
        motions, notes = [], []
        arm = self.plan.stand.arm_length_cm
        for source, samples in sorted(self._samples.items()):
            if arm is None:
                notes.append(f"{source}: samples, but no [stand] arm_length_cm to turn them to A")
                continue
            t, angle = (np.array(x) for x in zip(*samples, strict=True))
            try:
                motions.append(from_roll(source, t, angle, trial.period_s, arm))
            except RollFitError as exc:
                notes.append(f"{source}: {exc} ({len(samples)} samples)")
        if self.plan.inclinometer is not None and "inclinometer" not in self._samples:
            notes.append("inclinometer: no slope received during the rocking series")
        if self._reports:
            d, a, p = (np.array(x) for x in zip(*self._reports, strict=True))
            motions.append(from_reports(d, a, p, self.report_source))
        return SeriesMotion(tuple(motions), tuple(notes))

    def tracking_problem(self, trial: TrialPlan, motion: MeasuredMotion | None) -> str | None:
        """Why the measured motion leaves the [tracking] tolerance (None: within, or not
        measured)."""
        if motion is None:
            return None
        tol = self.plan.tracking
        a, p = motion.amplitude_cm, motion.period_s
        if abs(a - trial.amplitude_cm) > tol.amplitude_rel * trial.amplitude_cm:
            return (
                f"measured amplitude {a:.3f} cm ({motion.source}), commanded "
                f"{trial.amplitude_cm:g} cm: outside [tracking] amplitude_rel "
                f"{tol.amplitude_rel:g}"
            )
        if abs(p - trial.period_s) > tol.period_rel * trial.period_s:
            return (
                f"measured period {p:.4f} s ({motion.source}), commanded {trial.period_s:g} s: "
                f"outside [tracking] period_rel {tol.period_rel:g}"
            )
        return None
