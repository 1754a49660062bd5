"""The compensated criterion's error budget against the reading's own noise (issue 34): cheap,
before whole campaigns (`validation/misstated_plan.py`), ~0.5 s a draw.

Stored compensated campaigns give the structure: every settle block and observation window
(stand times, lengths), the steps, which series were compensated. Per draw the record is made
anew: the true transient (the plan's period and damping, which the simulator's compass has; the
state fitted to the stored record) plus the simulator's reading noise at its 10 Hz rate
(exponentially correlated, white, the 16-bit encoder: `stand.physics`, `stand.simconfig`),
averaged over the same windows. The acquisition's own `TransientRecord` takes the windows in
time order, and each compensated series is compensated at its end as `acquisition.engine` does
(the free fit of the record so far, its transient over the series' windows, the sensitivity to
period and damping, the compensation's SE). The trial means are then analysed as
`report.stored` gives them (each series' N_eff from the simulator's correlation function, the
generalised fit), with the compensated mean's variance

- "before": S^2/N + s_c^2 (s_c the settle point's SE) times the N_eff correction, as until
  issue 34's fix;
- "scalar": the compensation's SE^2 from the fit's own covariance and one inflation factor for
  the whole record (`analysis.transient.compensated_mean_se` without a correlation time);
- "after": the compensation's SE^2 with the reading's correlation time (the shipped plan's
  20 s), as the acquisition now stores it.

Printed, as SD of the errors over the RMS of the reported SEs (1 when the SE is honest) with a
bootstrap 95 % interval: the period and damping ratio of each compensation's free fit, its
settle point, its compensated mean; and the regression of the compensated mean's error on the
period and damping errors beside the stored sensitivity G (finite differences of the refit).
Then the fit trials' means against V, and C and T of the generalised fit (coverage too).

Run: .venv/bin/python validation/compensation_noise.py [--structures 3] [--draws 120] [--seed 2]
     (runs the first `--structures` compensated campaigns of `validation/end_to_end.py`'s draws
     of seed 1 for the structure, ~20 s each), or on stored campaigns: ... CAMPAIGN.sqlite [...]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gyrostand.acquisition.early_settle import TransientRecord
from gyrostand.analysis.effective import variance_inflation, window_mean_correlation
from gyrostand.analysis.gls import SharedError, shared_covariance
from gyrostand.analysis.noise import CorrelationModel
from gyrostand.analysis.transient import Segments, TransientModel, Windows, design, fit_transient

DT_S = 0.1  # the simulated compass's heading rate, 10 Hz (stand.simconfig)
QUANTUM_DEG = 360.0 / 65536  # its 16-bit encoder
C_RANGE, T_RANGE = (3e7, 12e7), (0.4, 1.4)  # as validation/end_to_end.py draws them
BOOTSTRAP = 1000
METHODS = ("before", "scalar", "no trial-1 cov", "after")
TAU_K = 20.0  # the shipped plan's correlation_time_s (the simulator's 1 / mu)


@dataclass(frozen=True)
class Series:
    trial: int
    j: int
    segment: int
    step_s: float
    windows: np.ndarray  # (n, 2) start, end s of every window of the series, in time order
    observed: np.ndarray  # (N,) indices of its observation windows in `windows`
    compensated: bool


@dataclass(frozen=True)
class Structure:
    """A stored compensated campaign: its series, the true transient, trials and settings."""

    model: TransientModel
    steps: Segments
    series: tuple[Series, ...]
    theta: np.ndarray
    trials: dict[int, dict[str, Any]]
    constants: Any
    start: tuple[float, float]
    noise: Any


def load(path: Path) -> Structure:
    from gyrostand.cmd_data import open_db
    from gyrostand.db.queries import load_campaign
    from gyrostand.plan.model import parse_plan
    from gyrostand.report.stored import stored_settings
    from gyrostand.report.transient import _segments
    from gyrostand.stand.simconfig import NoiseParams

    sessions = open_db(str(path), must_exist=True)
    with sessions() as session:
        campaign = load_campaign(session, 1)
        plan = parse_plan(campaign.plan_toml)
        settings, _ = stored_settings(campaign)
        segs = _segments(campaign)
        compensated = {
            (t.index, s.j): s.compensation_se_deg is not None
            for t in campaign.trials
            for s in t.series
        }
        trials = {
            t.index: {
                "role": t.role,
                "direction_deg": t.direction_deg,
                "amplitude_cm": t.amplitude_cm,
                "period_s": t.period_s,
            }
            for t in campaign.trials
        }
    sessions.kw["bind"].dispose()
    if any(s.free for s in segs[1:]):
        raise SystemExit(f"{path}: the campaign ran in more than one run (a free series)")
    model = plan.settle.transient_model
    steps = Segments(tuple(s.start_ms / 1000 for s in segs), tuple(s.free for s in segs))
    series, rows = [], []
    for k, s in enumerate(segs):
        w = np.array([(a, b) for a, b, _ in s.windows]) / 1000
        observed = np.array([int(np.argmin(np.abs(w[:, 0] * 1000 - a))) for a, _ in s.observed])
        key = (s.trial, s.j)
        series.append(Series(*key, k, s.start_ms / 1000, w, observed, compensated[key]))
        rows += [(k, (a + b) / 2, b - a, v) for (a, b), (_, _, v) in zip(w, s.windows, strict=True)]
    truth = fit_transient(model, steps, Windows.of(rows))
    return Structure(
        model,
        steps,
        tuple(series),
        truth.theta,
        trials,
        settings.constants,
        settings.start,
        NoiseParams(),
    )


def readings(st: Structure, rng: np.random.Generator) -> list[np.ndarray]:
    """One draw: per series the means over its windows of the true transient + the noise."""
    from scipy.signal import lfilter

    end = max(float(s.windows[:, 1].max()) for s in st.series)
    n = int(math.ceil(end / DT_S)) + 1
    t = np.arange(n) * DT_S
    nz = st.noise
    r = math.exp(-nz.corr_mu_per_s * DT_S)  # the AR(1) of stand.physics.CorrelatedNoise
    drive = rng.standard_normal(n) * nz.corr_sigma_deg * math.sqrt(1 - r * r)
    drive[0] = rng.standard_normal() * nz.corr_sigma_deg
    noise = lfilter([1.0], [1.0, -r], drive) + rng.standard_normal(n) * nz.white_sigma_deg
    segment = np.searchsorted(np.asarray(st.steps.step_s), t, side="right") - 1
    truth = np.zeros(n)
    after = segment >= 0
    truth[after] = design(st.model, st.steps, segment[after], t[after]) @ st.theta
    cum = np.concatenate([[0.0], np.cumsum(np.round((truth + noise) / QUANTUM_DEG) * QUANTUM_DEG)])
    out = []
    for s in st.series:
        a, b = (np.ceil(s.windows[:, k] / DT_S - 1e-9).astype(int) for k in (0, 1))
        out.append((cum[b] - cum[a]) / (b - a))
    return out


def compensate(record: TransientRecord, model: TransientModel, s: Series, values: np.ndarray):
    """What `acquisition.engine` stores at a compensated series' end (its `_compensation`)."""
    fit, j = record.fit(model, free=True)  # type: ignore[misc]
    w = s.windows[s.observed]
    t_s, width_s = w.mean(axis=1), w[:, 1] - w[:, 0]
    transient, _ = fit.transient(j, t_s, width_s)
    d_period, d_ratio, previous = record.sensitivity(fit.model, t_s, width_s)
    assert fit.pd_covariance is not None
    shared = SharedError(
        (-d_period, -d_ratio),
        tuple(tuple(float(v) for v in row) for row in fit.pd_covariance),  # type: ignore[arg-type]
        0,
        round(w[-1, 1] * 1000),
        previous,
        record.earlier_covariances(fit, t_s, width_s, len(w), TAU_K),
    )
    return {
        "values": values[s.observed] - transient,
        "settle_se": fit.settle_point(j)[1],
        "se": record.compensation_se(fit, t_s, width_s, TAU_K),
        "se_scalar": record.compensation_se(fit, t_s, width_s),
        "R": fit.settle_point(j)[0],
        "period": fit.model.undamped_period_s,
        "period_se": fit.period_se_s,
        "ratio": fit.model.damping_ratio,
        "ratio_se": fit.damping_ratio_se,
        "shared": shared,
    }


def inflation(st: Structure, s: Series) -> float:
    """f of the series' mean from the simulator's correlation function (what the fitted one
    gives on average, `report.signal.observation_correlations`)."""
    nz = st.noise
    white = nz.white_sigma_deg**2 + QUANTUM_DEG**2 / 12
    model = CorrelationModel(nz.corr_sigma_deg**2, nz.corr_mu_per_s, None, white)
    w = s.windows[s.observed]
    window, step = float(np.median(w[:, 1] - w[:, 0])), float(np.median(np.diff(w[:, 0])))
    n = len(w)
    rho = [window_mean_correlation(model, window, k * step, DT_S) for k in range(1, n)]
    return variance_inflation(np.array(rho), n)


def one_draw(st: Structure, rng: np.random.Generator, f: dict) -> dict[tuple[int, int], dict]:
    """Per series: its mean's error against the truth and what the acquisition stored."""
    values = readings(st, rng)
    record = TransientRecord()
    out = {}
    for s, v in zip(st.series, values, strict=True):
        if s.segment > 0:
            record.step(s.step_s)
        for (a, b), value in zip(s.windows, v, strict=True):
            record.add(float(a), float(b), float(value))
        if s.compensated:
            c = compensate(record, st.model, s, v)
        else:
            record.observed((s.trial, s.j), s.windows[s.observed])  # as the engine labels it
            c = {"values": v[s.observed], "settle_se": None, "se": None, "shared": None}
        c |= {"err": float(c["values"].mean() - st.theta[s.segment]), "f": f[s.trial, s.j]}
        out[s.trial, s.j] = c
    return out


def summary(c: dict[str, Any], method: str):
    """The series as `report.stored.series_summary` gives it, before and after the fix."""
    from gyrostand.analysis.trials import SeriesSummary

    v = c["values"]
    n, s2 = v.size, float(v.var(ddof=1))
    if c["se"] is None:
        return SeriesSummary(float(v.mean()), s2, n)
    if method == "before":
        return SeriesSummary(float(v.mean()), s2 + n * c["settle_se"] ** 2, n)
    if method == "scalar":  # the fit's own inflation, not the correlation time
        se = c["se_scalar"]
        return SeriesSummary(float(v.mean()), s2 + n * se**2, n, var_mean_deg2=se**2)
    return SeriesSummary(float(v.mean()), s2 + n * c["se"] ** 2, n, var_mean_deg2=c["se"] ** 2)


def analyse(st: Structure, draw: dict, method: str, rng: np.random.Generator) -> dict[str, Any]:
    """The generalised fit of C and T on the draw's trial means (true C, T drawn)."""
    from dataclasses import replace

    from gyrostand.analysis.campaign import analyze_campaign
    from gyrostand.analysis.gyro_model import Conditions, RollingErrorModel
    from gyrostand.analysis.trials import TrialInput

    c, t = float(rng.uniform(*C_RANGE)), float(rng.uniform(*T_RANGE))
    idx = sorted(st.trials)
    names = ("direction_deg", "amplitude_cm", "period_s")
    cond = Conditions(*(np.array([st.trials[i][k] for i in idx]) for k in names))
    alpha = RollingErrorModel(st.constants)(cond, C_gcm2s2=c, T_s=t)
    inputs = []
    for i, a in zip(idx, alpha, strict=True):
        under = summary(draw[i, 2], method)
        under = replace(under, mean_deg=under.mean_deg - st_theta(st, i, 2) + float(a))
        before = summary(draw[i, 1], method)
        before = replace(before, mean_deg=before.mean_deg - st_theta(st, i, 1))
        inputs.append(TrialInput(index=i, **st.trials[i], before=before, under=under))
    shared = {k: x["shared"] for k, x in draw.items() if x["shared"] is not None}
    if method != "after":  # without the compensations' covariance with uncompensated series
        shared = {k: replace(x, earlier_deg2=()) for k, x in shared.items()}
    infl = {i: (draw[i, 1]["f"], draw[i, 2]["f"]) for i in idx}
    an = analyze_campaign(inputs, st.constants, start=st.start, inflation=infl, shared=shared)
    fits = list(an.fit_indices)
    stats = {s.index: s for s in an.trials}
    part = shared_covariance(shared, fits)
    v = np.diag([stats[i].var_mean_deg2 for i in fits]) + (0.0 if part is None else part)
    row: dict[str, Any] = {
        "trial_err": [draw[i, 2]["err"] - draw[i, 1]["err"] for i in fits],
        "V": v,
    }
    for name, true in (("C_gcm2s2", c), ("T_s", t)):
        est, se = an.fit.estimates[name], an.fit.std_errors[name]
        lo, hi = an.confidence_intervals[name]
        row[name] = ((est - true) / true, se / true, lo <= true <= hi)
    return row


def st_theta(st: Structure, trial: int, j: int) -> float:
    return float(st.theta[next(s.segment for s in st.series if (s.trial, s.j) == (trial, j))])


def ratio(err: np.ndarray, se: np.ndarray, rng: np.random.Generator) -> str:
    """SD of the errors over the RMS SE, with a bootstrap 95 % interval, and the mean z."""

    def value(k: np.ndarray) -> float:
        return float(err[k].std(ddof=1) / math.sqrt(np.mean(se[k] ** 2)))

    k = np.arange(err.size)
    boot = [value(rng.integers(0, err.size, err.size)) for _ in range(BOOTSTRAP)]
    low, high = np.percentile(boot, [2.5, 97.5])
    return f"{value(k):.2f} [{low:.2f}, {high:.2f}] (mean z {np.mean(err / se):+.2f})"


def report(structures: list[Structure], draws: list[list[dict]], rows: dict[str, list]) -> None:
    rng = np.random.default_rng(34)
    for st, ds in zip(structures, draws, strict=True):
        print(f"  structure: C {st.start[0]:.3g} start, {len(ds)} draws; SD/SE per series:")
        for s in st.series:
            d = [x[s.trial, s.j] for x in ds]
            err = np.array([x["err"] for x in d])
            if not s.compensated:
                f = np.array([x["f"] for x in d])
                n = np.array([x["values"].size for x in d])
                s2 = np.array([x["values"].var(ddof=1) for x in d])
                se = np.sqrt(s2 * (n - 1) / (n - f) * f / n)  # analysis.effective
                where = f"trial {s.trial} series {s.j}"
                print(f"    {where} (not compensated): mean {ratio(err, se, rng)}")
                continue
            p = np.array([x["period"] for x in d]) - st.model.undamped_period_s
            r = np.array([x["ratio"] for x in d]) - st.model.damping_ratio
            big_r = np.array([x["R"] for x in d]) - st_theta(st, s.trial, s.j)
            pse, rse = (np.array([x[k] for x in d]) for k in ("period_se", "ratio_se"))
            settle = np.array([x["settle_se"] for x in d])
            se = np.array([x["se"] for x in d])
            f = np.array([x["f"] for x in d])
            n = np.array([x["values"].size for x in d])
            s2 = np.array([x["values"].var(ddof=1) for x in d]) + n * settle**2
            old = np.sqrt(s2 * (n - 1) / (n - f) * f / n)
            scalar = np.array([x["se_scalar"] for x in d])
            print(
                f"    trial {s.trial} series {s.j}: period {ratio(p, pse, rng)}, damping "
                f"{ratio(r, rse, rng)}, settle point {ratio(big_r, settle, rng)}; compensated "
                f"mean before {ratio(err, old, rng)}, scalar {ratio(err, scalar, rng)}, "
                f"after {ratio(err, se, rng)}"
            )
            g = np.mean([x["shared"].sensitivity for x in d], axis=0)
            coef = np.linalg.lstsq(np.column_stack([p, r, np.ones_like(p)]), err, rcond=None)[0]
            print(
                f"      d mean / d (period, ratio): stored G {g[0]:+.2e} deg/s, {g[1]:+.4f} deg;"
                f" regression over the draws {coef[0]:+.2e}, {coef[1]:+.4f}"
            )
    for st, ds in zip(structures, draws, strict=True):
        earlier(st, ds, rng)
    for method in METHODS:
        rs = rows[method]
        err = np.array([r["trial_err"] for r in rs])
        v = np.array([r["V"] for r in rs])
        se = np.sqrt(np.array([np.diag(x) for x in v]))
        print(f"  {method}: fit trials' means SD/SE {ratio(err.ravel(), se.ravel(), rng)}")
        corr = np.mean([x / np.outer(d, d) for x, d in zip(v, se, strict=True)], axis=0)
        sim = np.corrcoef(err.T)
        print(
            "    first fit trial's mean with the others, correlation in V / simulated: "
            + ", ".join(f"{corr[0, k]:+.2f} / {sim[0, k]:+.2f}" for k in range(1, len(sim)))
        )
        for name, short in (("C_gcm2s2", "C"), ("T_s", "T")):
            e = np.array([r[name][0] for r in rs])
            s = np.array([r[name][1] for r in rs])
            cover = 100 * np.mean([r[name][2] for r in rs])
            print(f"    {short}: SD/SE {ratio(e, s, rng)}, coverage {cover:.1f} % (93-97 %)")


def earlier(st: Structure, ds: list[dict], rng: np.random.Generator) -> None:
    """Each uncompensated series' mean against each later compensated one in its record:
    the covariance the compensation stores (``earlier_deg2``, mean over the draws) beside the
    one over the draws (bootstrap 95 %), as correlations (the simulated SDs)."""
    print("  uncompensated series vs later compensations, correlation predicted / simulated:")
    for s in st.series:
        if not s.compensated:
            continue
        e_s = np.array([x[s.trial, s.j]["err"] for x in ds])
        stored = [dict(x[s.trial, s.j]["shared"].earlier_deg2) for x in ds]
        parts = []
        for u in st.series:
            if u.compensated or u.segment >= s.segment:
                continue
            e_u = np.array([x[u.trial, u.j]["err"] for x in ds])
            pred = float(np.mean([x[u.trial, u.j] for x in stored])) / (e_s.std() * e_u.std())
            boot = []
            for _ in range(BOOTSTRAP // 5):
                k = rng.integers(0, e_s.size, e_s.size)
                boot.append(np.corrcoef(e_s[k], e_u[k])[0, 1])
            lo, hi = np.percentile(boot, [2.5, 97.5])
            sim = np.corrcoef(e_s, e_u)[0, 1]
            parts.append(f"({u.trial},{u.j}) {pred:+.2f} / {sim:+.2f} [{lo:+.2f}, {hi:+.2f}]")
        print(f"    trial {s.trial} series {s.j}: " + ", ".join(parts))
    idx = sorted({s.trial for s in st.series})
    err = {i: np.array([x[i, 2]["err"] - x[i, 1]["err"] for x in ds]) for i in idx}
    print(
        "    trial 1's mean vs trial i's, simulated correlation: "
        + ", ".join(f"{i}: {np.corrcoef(err[idx[0]], err[i])[0, 1]:+.2f}" for i in idx[1:])
    )


def _campaign(i: int, folder: Path) -> Path:
    """Draw i of seed 1's compensated campaigns (`validation/end_to_end.py`), its database."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from end_to_end import campaign_row, draws

    row = campaign_row("compensated", draws(i + 1, 1)[i], folder=folder / str(i))
    if row["error"] is not None:
        raise SystemExit(f"campaign {i}: {row['error']}")
    return folder / str(i) / "campaign.sqlite"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("campaigns", type=Path, nargs="*", help="compensated campaigns' databases")
    parser.add_argument("--structures", type=int, default=3, help="campaigns to run, without them")
    parser.add_argument("--draws", type=int, default=120, help="per campaign")
    parser.add_argument("--seed", type=int, default=2)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory(prefix="gyrostand-noise-") as tmp:
        paths = args.campaigns or [_campaign(i, Path(tmp)) for i in range(args.structures)]
        structures = [load(p) for p in paths]
    draws, rows = [], {m: [] for m in METHODS}
    for st in structures:
        f = {(s.trial, s.j): inflation(st, s) for s in st.series}
        ds = [one_draw(st, rng, f) for _ in range(args.draws)]
        draws.append(ds)
        for d in ds:
            truth = int(rng.integers(2**63))
            for method in METHODS:  # the same true C and T for both
                rows[method].append(analyse(st, d, method, np.random.default_rng(truth)))
    print(f"{sum(len(d) for d in draws)} draws (seed {args.seed}) of {len(structures)} campaigns")
    report(structures, draws, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
