"""Settle criteria compared on the simulated paper campaign: stand time per trial and the error
of the series means (issue 7 section 2), and the sensitivity of the transient-model criteria to
the plan's precession period and damping ratio.

Run: .venv/bin/python bench/bench_early_settle.py   (prints tables; ~3 minutes on 2 idle cores)

The paper campaign (Potemkin 1982; six trials, N = 5) runs on the simulator's default compass
(84.4-minute undamped period, damping 0.7, correlated + white sensor noise, rocking harmonics)
driven in lockstep with the campaign engine: no bus, no clock, deterministic per seed. Criteria:

- band (paper): examples/paper.toml with method = "band" (+-0.03 deg, trend <= 0.006 deg, held
  1800 s);
- band (tighter): +-0.02 deg, trend <= 0.004 deg, held 2700 s, max wait 12 h;
- estimate: examples/paper.toml as shipped (the transient model of Bezvesilna & Gura fitted
  online across the stand's starts and stops; observe once the settle point is known within
  0.5 S_e and the transient left over the N windows, fit + 2 SE, is within 0.2 S_e);
- compensated: examples/paper-compensated.toml as shipped (observe during the transient, the
  fitted transient subtracted from each observation; the first series of a run waits as
  "estimate" does).

Error = series mean minus the simulator's true settled reading (the stand's heading, plus the
rolling error of model 1.1 while rocking); for a compensated series the mean of the compensated
observations, as the analysis uses them. z = error / the standard error of the mean the analysis
states: sqrt(SE_c^2 + s^2 / N), with s the scatter of the N (compensated) observations and SE_c
the compensation's standard error (0 for a series not compensated); RMS z near 1 means the stated
uncertainty is honest. Last, the period and damping ratio that the whole record of each run
gives (the analysis reports them and warns when they contradict the plan's), with the plan's
right and off.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from acquisition_stream import ROOT

from gyrostand.acquisition.engine import Engine, ObservationResult, SeriesCompensation
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.analysis.transient import (
    REJECT_SE,
    Segments,
    TransientFit,
    TransientModel,
    Windows,
    contradicts,
    fit_transient_free,
)
from gyrostand.plan.model import Plan, parse_plan
from gyrostand.stand.simconfig import SimConfig

SEEDS = (1, 2, 3)
STEP_S = 20.0  # stand seconds per lockstep step
TRIALS = 6  # in the paper campaign
Keys = Mapping[str, str | None]  # plan key -> new value (None: delete the key's line)
BAND: Keys = {
    "method": '"band"',
    "expected_se_deg": None,
    "tolerance_fraction": None,
    "stable_estimates": None,
    "transient_fraction": None,
}
TIGHTER: Keys = {
    "band_deg": "0.02",
    "drift_deg": "0.004",
    "hold_s": "2700.0",
    "max_wait_s": "43200.0",
}
CRITERIA: dict[str, tuple[str, Keys]] = {
    "band (paper)": ("paper.toml", BAND),
    "band (tighter)": ("paper.toml", {**BAND, **TIGHTER}),
    "estimate": ("paper.toml", {}),
    "compensated": ("paper-compensated.toml", {}),
}
MISMATCHES: dict[str, Keys] = {  # the plan's instrument data off, the compass unchanged
    "period -10%": {"undamped_period_s": "4557.6"},
    "period +10%": {"undamped_period_s": "5570.4"},
    "damping 0.65": {"damping_ratio": "0.65"},
    "damping 0.75": {"damping_ratio": "0.75"},
}
SENSITIVE = ("compensated", "estimate")
SENSITIVITY = [
    label for method in SENSITIVE for label in (method, *(f"{method}, {m}" for m in MISMATCHES))
]
CONFIGS = CRITERIA | {
    f"{method}, {label}": (CRITERIA[method][0], keys)
    for method in SENSITIVE
    for label, keys in MISMATCHES.items()
}


def override(text: str, keys: Keys) -> str:
    """The plan text with each key's line replaced by `key = value`, or deleted (value None)."""
    for key, value in keys.items():
        line = "" if value is None else f"{key} = {value}\n"
        text, n = re.subn(rf"^{key} = \S+.*\n", line, text, flags=re.M)
        if n != 1:
            raise ValueError(f"{key}: {n} lines in the plan")
    return text


def plan_for(label: str) -> Plan:
    name, keys = CONFIGS[label]
    return parse_plan(override((ROOT / "examples" / name).read_text(), keys))


class _Record:
    """A Sink keeping what the comparison needs (the rest is dropped)."""

    def __init__(self) -> None:
        self.settled: dict[tuple[int, int], SettleOutcome] = {}
        self.observed: dict[tuple[int, int], list[ObservationResult]] = {}
        self.compensation: dict[tuple[int, int], SeriesCompensation] = {}
        self.failures = 0

    def series_settled(self, trial: int, j: int, t_ms: int, outcome: SettleOutcome) -> None:
        self.settled[(trial, j)] = outcome

    def observation(self, obs: ObservationResult) -> None:
        self.observed.setdefault((obs.trial, obs.j), []).append(obs)

    def series_completed(
        self, trial: int, j: int, compensation: SeriesCompensation | None = None, *motion: Any
    ) -> None:
        if compensation is not None:
            self.compensation[(trial, j)] = compensation

    def trial_failed(self, trial: int, j: int | None, reason: str) -> None:
        self.failures += 1

    def __getattr__(self, name: str) -> Any:  # trial_started, event, ...: not needed
        return lambda *args, **kwargs: None


@dataclass(frozen=True)
class SeriesResult:
    settle_s: float
    error_deg: float  # mean of the (compensated) observations - true settled reading
    z: float  # error / the stated standard error of the mean
    compensated: bool


@dataclass(frozen=True)
class Run:
    label: str
    seed: int
    ok: bool  # completed, no trial failed
    stand_s: float
    series: tuple[SeriesResult, ...]
    record_fit: TransientFit | None  # with the period and damping fitted to the whole record


def corrected(values: list[float], compensation: SeriesCompensation | None) -> np.ndarray:
    """The observations as the analysis uses them (value - compensation, when compensated)."""
    out = np.array(values)
    if compensation is not None:
        k = compensation.first_k - 1
        out[k : k + len(compensation.transient_deg)] -= compensation.transient_deg
    return out


def series_result(
    sink: _Record, key: tuple[int, int], truth_deg: float, settle_s: float
) -> SeriesResult:
    comp = sink.compensation.get(key)
    values = corrected([o.value_deg for o in sink.observed[key]], comp)
    error = float(values.mean()) - truth_deg
    se_c = 0.0 if comp is None else comp.standard_error_deg
    stated = math.sqrt(se_c**2 + values.var(ddof=1) / values.size)
    return SeriesResult(settle_s, error, error / stated, comp is not None)


def next_series(key: tuple[int, int]) -> tuple[int, int]:
    trial, j = key
    return (trial, 2) if j == 1 else (trial + 1, 1)


def record_fit(plan: Plan, sink: _Record) -> TransientFit | None:
    """The transient model fitted to the whole record the sink saw (settle blocks and
    observations) with the period and damping ratio estimated too, from the plan's, as the
    analysis re-estimates them; the state carries over to the next series unless one is missing."""
    rows: list[tuple[int, float, float, float]] = []
    steps: list[float] = []
    free: list[bool] = []
    previous: tuple[int, int] | None = None
    for key, outcome in sorted(sink.settled.items()):
        observed = sink.observed.get(key, [])
        obs = [(o.window_start_ms, o.window_end_ms, o.value_deg) for o in observed]
        windows = [*outcome.blocks, *obs]
        step: int | None = outcome.step_ms if previous and next_series(previous) == key else None
        steps.append((windows[0][0] if step is None else step) / 1000)
        free.append(step is None)
        rows += [(len(steps) - 1, (a + b) / 2000, (b - a) / 1000, v) for a, b, v in windows]
        previous = key
    assert plan.settle.transient_model is not None
    try:
        seg = Segments(tuple(steps), tuple(free))
        return fit_transient_free(plan.settle.transient_model, seg, Windows.of(rows))
    except AnalysisError:
        return None


def drive(plan: Plan, seed: int) -> tuple[Engine, _Record]:
    """The campaign in lockstep with the simulated stand."""
    stand, sink = Lockstep(SimConfig(seed=seed), STEP_S), _Record()
    engine = Engine(plan, sink, stand)
    for _ in stand.steps(engine, max_stand_s=math.inf):
        pass
    return engine, sink


def run(label: str, seed: int) -> Run:
    plan = plan_for(label)
    engine, sink = drive(plan, seed)
    compass = SimConfig(seed=seed).compass
    results = []
    for trial in plan.trials:
        shift = compass.settled_shift_deg(trial.direction_deg, trial.amplitude_cm, trial.period_s)
        for j in (1, 2):
            key = (trial.index, j)
            if key not in sink.settled or len(sink.observed.get(key, [])) < plan.n_obs:
                continue
            truth = compass.heading_deg + (shift if j == 2 else 0.0)
            settle_s = sink.settled[key].settle_s
            results.append(series_result(sink, key, truth, settle_s))
    ok = engine.outcome == "completed" and sink.failures == 0
    return Run(label, seed, ok, engine.now_ms / 1000, tuple(results), record_fit(plan, sink))


def rms(values: list[float]) -> float:
    return math.sqrt(float(np.mean(np.square(values)))) if values else math.nan


def hours_per_trial(runs: list[Run]) -> float:
    return sum(r.stand_s for r in runs) / (len(runs) * TRIALS) / 3600


def figures(runs: list[Run]) -> str:
    """Runs ok, h/trial, RMS error, max |error|, RMS z (all series; compensated series only)."""
    series = [s for r in runs for s in r.series]
    comp = rms([s.z for s in series if s.compensated])
    return (
        f"{sum(r.ok for r in runs):>6}/{len(runs)}{hours_per_trial(runs):>8.2f}"
        f"{rms([s.error_deg for s in series]):>9.4f}"
        f"{max(abs(s.error_deg) for s in series):>9.4f}{rms([s.z for s in series]):>7.2f}"
        + (f"{'-':>11}" if math.isnan(comp) else f"{comp:>11.2f}")
    )


HEADER = f"{'runs ok':>8}{'h/trial':>8}{'RMS err':>9}{'max|err|':>9}{'RMS z':>7}{'RMS z comp':>11}"


def criteria_table(by_label: dict[str, list[Run]]) -> None:
    print(f"{'settle criterion':<16}{'series':>7}{'settle s':>9}{HEADER}")
    for label in CRITERIA:
        series = [s for r in by_label[label] for s in r.series]
        settle_s = np.mean([s.settle_s for s in series])
        print(f"{label:<16}{len(series):>7}{settle_s:>9.0f}{figures(by_label[label])}")
    print("\n(err, deg: series mean - true settled reading, after compensation for compensated")
    print(" series; z: err / the stated SE of the mean, sqrt(SE_c^2 + s^2/N); RMS z comp: the")
    print(" compensated series only.)\n")


def ratios(by_label: dict[str, list[Run]]) -> None:
    band = hours_per_trial(by_label["band (paper)"])
    print("Stand time per trial against band (paper); the issue's target: compensated <= 0.35x")
    for label in ("compensated", "estimate"):
        h = hours_per_trial(by_label[label])
        print(f"  {label:<12} {h:5.2f} h vs {band:5.2f} h = {h / band:.2f}x")


def from_record(fit: TransientFit | None, plan: TransientModel) -> str:
    """The period and damping ratio a whole record gives, +- SE; "*" where the analysis warns
    that they contradict the plan's (`analysis.transient.contradicts`)."""
    if fit is None or fit.period_se_s is None or fit.damping_ratio_se is None:
        return f"{'not fitted':<25}"
    period, ratio = fit.model.undamped_period_s, fit.model.damping_ratio
    mark = "*" if contradicts(fit, plan) else " "
    return f"{period:4.0f}+-{fit.period_se_s:<3.0f} s {ratio:.3f}+-{fit.damping_ratio_se:.3f}{mark}"


def sensitivity(by_label: dict[str, list[Run]]) -> None:
    print("\nThe plan's period and damping ratio off, the compass unchanged (5064 s, 0.70):")
    print(f"  {'plan':<26}{HEADER}")
    for label in SENSITIVITY:
        print(f"  {label:<26}{figures(by_label[label])}")
    print(
        "\nThe period and damping ratio the whole record gives (+- SE), per seed, as the analysis"
    )
    print(f"re-estimates them (*: it warns they contradict the plan's, > {REJECT_SE:g} SE):")
    for label in SENSITIVITY:
        plan = plan_for(label).settle.transient_model
        assert plan is not None
        fits = " ".join(from_record(r.record_fit, plan) for r in by_label[label])
        print(f"  {label:<26}{fits}".rstrip())


def main() -> None:
    jobs = [(label, seed) for label in CONFIGS for seed in SEEDS]
    with ProcessPoolExecutor(max_workers=2) as pool:
        done = list(pool.map(run, *zip(*jobs, strict=True)))
    by_label = {label: [r for r in done if r.label == label] for label in CONFIGS}
    print("Paper campaign (Potemkin 1982: 6 trials, N = 5), simulated compass T0 = 84.4 min,")
    print(f"damping 0.7; seeds {SEEDS}; {sum(len(r.series) for r in done)} series in all.\n")
    criteria_table(by_label)
    ratios(by_label)
    sensitivity(by_label)


if __name__ == "__main__":
    main()
