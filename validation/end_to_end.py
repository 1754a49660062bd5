"""End-to-end validation of the whole chain over simulated campaigns, per settle criterion.

`validation/monte_carlo.py` validates the analysis alone, on synthetic trial tables. This script
runs whole campaigns as `gyrostand campaign run PLAN --db DB` does: the simulated
compass on its rolling stand (virtual time) -> virtual CAN bus -> acquisition engine (settle
criterion, observation windows) -> SQLite database; then the stored campaign is analysed as
`gyrostand analyze ID` does (Potemkin 1982: trial statistics, Cochran, the Gauss-Newton fit of C
and T, adequacy, control trials with the prediction intervals of eqs 2.10-2.11). What the
analysis alone cannot show, the settle criterion's effect, shows here: a series that starts
before the compass's damped transient has died out (the settle point of a damped gyro
oscillation, Bezvesilna & Gura) carries part of it into <delta> and biases C and T.

Each campaign draws the compass's true C uniformly in 3-12 x 10^7 g cm^2 s^-2 and T in 0.4-1.4 s
(inside the plan's admissible ranges; set in the plan as [bus.simulator.compass] c_gcm2s2 and
t_s) and a simulator seed of its own ([bus] seed), and runs in a fresh temporary folder (plan,
database, raw CAN logs; deleted afterwards). Every criterion of CRITERIA runs on the same draws
(a paired comparison). A failed trial is counted and the campaign goes on (the analysis uses the
trials it has); a campaign that raises is counted with its error and the run goes on.

Per criterion it prints: campaigns run, completed, with failed trials, errors; the bias of C and
T in units of their reported standard error, pooled (mean relative error over RMS relative SE,
with its SE; the paper design leaves the fit 2 residual dof, so (estimate - true) / SE follows
t(2), whose mean over campaigns does not settle), and the median of (estimate - true) / SE with
its 95 % interval; the coverage of the 95 % confidence intervals of C and T
(estimate +- t(1 - q/2; dof) SE, the analysis's q and dof) with the binomial SE; the coverage of
the control trials' residuals by their 95 % prediction intervals (the analysis's own verdict);
the mean stand time per trial (stand time, from the stored settle, window and event times), its
ratio to the band criterion's on the same draws; and wall time.

Targets (printed beside the figures): |bias| <= 0.3 SE; coverage 92-97 %; for a "compensated"
criterion, stand time <= 0.35 x the band criterion's.

Run: .venv/bin/python validation/end_to_end.py [--campaigns 100] [--seed 1]
         [--criteria band,estimate,compensated] [--jobs 2] [--out rows.json]
     .venv/bin/python validation/end_to_end.py ... --out rows.json --resume   (a stopped run)
     .venv/bin/python validation/end_to_end.py --table-from rows.json   (tables of kept rows)
A campaign takes ~16 s of one core with the band criterion (the paper campaign: 6 trials,
N = 5, ~15 h of stand time), ~40 s with "estimate" (~20 h of stand time), ~10 s compensated
(~5.5 h); on a shared 2-core machine two to three times that: 100 campaigns x the three
criteria take a few hours, so run it with --out and --resume. Progress goes to stderr, one line per
campaign; --out keeps the rows as they come. The same arguments give the same table (virtual
time; only the wall times differ).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import typer
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

# Settle criteria: label -> (plan file in examples/, [settle] keys set over the file's).
# Adding one is one line, e.g. "band, tighter": ("paper.toml", {"band_deg": 0.02, ...}).
# A key set to None is removed (the band criterion takes no transient-model tolerances).
MODEL_ONLY = ("expected_se_deg", "tolerance_fraction", "stable_estimates", "transient_fraction")
CRITERIA: dict[str, tuple[str, dict[str, Any]]] = {
    # the paper's band: +-0.03 deg, trend 0.006 deg, held 1800 s
    "band": ("paper.toml", {"method": "band"} | dict.fromkeys(MODEL_ONLY)),
    "estimate": ("paper.toml", {}),  # as shipped: the transient model, left <= 0.05 S_e
    "compensated": ("paper-compensated.toml", {}),  # as shipped: observed in the transient
    # the run's first series (not compensated: its state is unknown) waiting for a looser bound
    "compensated-first-0.2": ("paper-compensated.toml", {"transient_fraction": 0.2}),
    # the plan's instrument data mis-stated (the compass's are 5064 s and 0.7), issue 34 item 2:
    # validation/misstated_plan.py
    **{
        f"{label} {what}": (name, {key: value})
        for label, name in (("estimate", "paper.toml"), ("compensated", "paper-compensated.toml"))
        for what, key, value in (
            ("period -10%", "undamped_period_s", 0.9 * 5064.0),
            ("period +10%", "undamped_period_s", 1.1 * 5064.0),
            ("damping -0.05", "damping_ratio", 0.65),
            ("damping +0.05", "damping_ratio", 0.75),
        )
    },
}
REFERENCE = "band"  # stand time ratios are to this criterion's, on the same draws

C_RANGE = (3e7, 12e7)  # g cm^2 s^-2
T_RANGE = (0.4, 1.4)  # s
PARAMETERS = {"C_gcm2s2": "C", "T_s": "T"}
BIAS_TARGET = 0.3  # |mean (est - true) / SE|
COVERAGE_TARGET = (0.92, 0.97)
COMPENSATED_STAND_TARGET = 0.35  # x the reference criterion's stand time per trial


@dataclass(frozen=True)
class Draw:
    """One campaign's hidden truth and simulator seed (the same for every criterion)."""

    index: int
    C_gcm2s2: float
    T_s: float
    bus_seed: int


def draws(n: int, seed: int) -> list[Draw]:
    """n draws; draw i depends on (seed, i) only, so a longer run extends a shorter one."""
    out = []
    for i, child in enumerate(np.random.SeedSequence(seed).spawn(n)):
        rng = np.random.default_rng(child)
        c, t = float(rng.uniform(*C_RANGE)), float(rng.uniform(*T_RANGE))
        out.append(Draw(i, c, t, int(rng.integers(1, 2**31))))
    if len({d.bus_seed for d in out}) != n:
        raise SystemExit(f"--seed {seed}: two campaigns drew the same simulator seed; pick another")
    return out


def plan_text(criterion: str, draw: Draw, folder: Path, base: str | None = None) -> str:
    """The plan file the campaign runs: the criterion's plan file (or `base`, a plan's text)
    with the criterion's [settle] keys, the draw's compass and simulator seed, and the raw CAN
    logs in `folder` (the database is given as `campaign run`'s --db)."""
    from gyrostand.plan.overrides import with_keys

    name, settle = CRITERIA[criterion]
    text = base if base is not None else (EXAMPLES / name).read_text()
    return with_keys(
        text,
        {
            "campaign": {"raw_log_dir": str(folder / "raw")},
            "settle": settle,
            "bus": {"seed": draw.bus_seed},
            "bus.simulator.compass": {"c_gcm2s2": draw.C_gcm2s2, "t_s": draw.T_s},
        },
    )


def _where(exc: BaseException) -> str:
    """Where an exception was raised: the innermost traceback line in gyrostand's code
    (path:line in function), and the innermost of all when that is in a library."""
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if Path(f.filename).is_relative_to(ROOT)]
    shown = ([ours[-1]] if ours else []) + ([frames[-1]] if frames[-1] not in ours[-1:] else [])
    return ", raised at ".join(
        f"{Path(f.filename).relative_to(ROOT) if f in ours else Path(f.filename).name}:"
        f"{f.lineno} in {f.name}"
        for f in shown
    )


@contextmanager
def _folder(keep: Path | None) -> Iterator[Path]:
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        yield keep
        return
    # on a RAM file system where there is one: the same numbers, without the disk's fsyncs (the
    # database commits every observation durably: ~20 % of a campaign's CPU on a disk)
    shm = Path("/dev/shm")
    where = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="gyrostand-e2e-", dir=where) as tmp:
        yield Path(tmp)


def campaign_row(
    criterion: str, draw: Draw, *, base: str | None = None, folder: Path | None = None
) -> dict[str, Any]:
    """Run one campaign end to end and analyse it; the row of figures (JSON types). `base`: a
    plan's text instead of the criterion's plan file; `folder`: where the plan, database and
    raw logs go (kept), instead of a temporary folder (deleted)."""
    from gyrostand.cmd_campaign import BusOptions, new_campaign
    from gyrostand.cmd_data import open_db
    from gyrostand.db.lease import take_lease
    from gyrostand.db.queries import campaign_summary, load_campaign
    from gyrostand.plan.model import parse_plan
    from gyrostand.report.stored import analyze_stored, trial_stand_spans

    row: dict[str, Any] = {"criterion": criterion, **asdict(draw), "error": None}
    start = time.perf_counter()
    try:
        with _folder(folder) as where:
            text = plan_text(criterion, draw, where, base)
            row["settle_method"] = parse_plan(text).settle.method
            plan = where / "plan.toml"
            plan.write_text(text)
            db = str(where / "campaign.sqlite")
            bus = BusOptions(None, None, None, None, None)  # the plan's simulated stand
            result, db = new_campaign(plan, db, bus, quiet=True)
            row |= {"campaign_id": result.campaign_id, "outcome": result.outcome}
            sessions = open_db(db, must_exist=True)
            try:
                take_lease(sessions, result.campaign_id).release()  # as the command's exit does
                with sessions() as session:
                    summary = campaign_summary(session, result.campaign_id)
                    spans = trial_stand_spans(load_campaign(session, result.campaign_id))
                row["trials_failed"] = [
                    f"trial {t.index}: {t.failure_reason}"
                    for t in summary.trials
                    if t.status == "failed"
                ]
                row["stand_s"] = {str(i): (b - a) / 1000 for i, (a, b) in sorted(spans.items())}
                row |= _analysis(analyze_stored(sessions, result.campaign_id).analysis, draw)
            finally:
                sessions.kw["bind"].dispose()
    except typer.Exit as exc:  # a one-line CLI error, already on stderr
        row["error"] = f"gyrostand stopped with exit code {exc.exit_code} (its line is on stderr)"
    except Exception as exc:  # counted, with where it came from
        from gyrostand.analysis.errors import AnalysisError

        kind = "analysis" if isinstance(exc, AnalysisError) else type(exc).__name__
        row["error"] = f"{kind}: {exc} ({_where(exc)})"
    row["wall_s"] = time.perf_counter() - start
    return row


def _analysis(analysis: Any, draw: Draw) -> dict[str, Any]:
    """What the rows keep of a CampaignAnalysis: per parameter the estimate, its SE and 95 %
    confidence interval, and each control trial's residual against its prediction interval."""
    from gyrostand.analysis.gyro_model import Conditions, RollingErrorModel

    fit = analysis.fit
    out: dict[str, Any] = {
        "q": analysis.q,
        "dof": fit.dof,
        "converged": fit.converged,
        "fit_path": fit.path,
        "warnings": list(analysis.warnings),
    }
    for name, short in PARAMETERS.items():
        est, se, true = fit.estimates[name], fit.std_errors[name], getattr(draw, name)
        out[short] = {
            "true": true,
            "estimate": est,
            "se": se,
            "ci": list(analysis.confidence_intervals[name]),
            "z": (est - true) / se if se > 0 else math.nan,
        }
    # each trial's <delta_i> against the rolling error model 1.1 gives at the true C and T (the
    # simulator's settled shift), with its reported standard error sqrt(var_mean) and dof
    conditions = Conditions(
        np.array([t.direction_deg for t in analysis.trials]),
        np.array([t.amplitude_cm for t in analysis.trials]),
        np.array([t.period_s for t in analysis.trials]),
    )
    alpha = RollingErrorModel(analysis.constants)(conditions, C_gcm2s2=draw.C_gcm2s2, T_s=draw.T_s)
    out["trials"] = [
        {
            "index": t.index,
            "error_deg": t.delta_deg - float(a),
            "se_deg": math.sqrt(t.var_mean_deg2) if t.var_mean_deg2 is not None else None,
            "dof": t.mean_dof,  # of var_mean: its interval's (inf: both series compensated)
            "n_eff": [t.n_eff_before, t.n_eff_under],  # from the fitted correlation (or None)
            "delta_deg": t.delta_deg,  # and the conditions: the fit can be redone from the row
            "conditions": [t.direction_deg, t.amplitude_cm, t.period_s],
        }
        for t, a in zip(analysis.trials, alpha, strict=True)
    ]
    cov = analysis.trial_covariance  # generalised least squares (compensated): V of the fit
    out["trial_covariance"] = None if cov is None else cov.tolist()
    out["fit_indices"] = list(analysis.fit_indices)
    out["controls"] = [
        {
            "index": c.index,
            "residual_deg": c.residual_deg,
            "half_width_deg": c.half_width_deg,
            "within_interval": c.within_interval,
        }
        for c in analysis.controls
    ]
    return out


# ------------------------------------------------------------------------------- summary


def _share(hits: list[bool]) -> tuple[float, float, int]:
    n = len(hits)
    if n == 0:
        return math.nan, math.nan, 0
    p = sum(hits) / n
    return p, math.sqrt(p * (1 - p) / n), n


def per_trial_s(row: Mapping[str, Any]) -> float | None:
    stand = row.get("stand_s") or {}
    return sum(stand.values()) / len(stand) if stand else None


def pooled_bias(rows: list[Mapping[str, Any]], p: str) -> tuple[float, float]:
    """Bias in units of SE, pooled over campaigns: mean((est - true) / true) / RMS(SE / true),
    with its own SE. Not the mean of (est - true) / SE: with the paper design's 2 residual dof
    that ratio follows t(2), whose variance is infinite (a rare fit with s^2 near 0 gives |z| of
    30 and dominates any mean); the relative errors and SE^2 (exponential with 2 dof) have finite
    variance, so both means settle."""
    if len(rows) < 2:
        return math.nan, math.nan
    rel = np.array([(r[p]["estimate"] - r[p]["true"]) / r[p]["true"] for r in rows])
    rms_se = math.sqrt(np.mean([(r[p]["se"] / r[p]["true"]) ** 2 for r in rows]))
    return float(rel.mean() / rms_se), float(rel.std(ddof=1) / math.sqrt(rel.size) / rms_se)


def median_z(z: list[float]) -> tuple[float, float, float]:
    """Median of (est - true) / SE and its distribution-free 95 % interval (order statistics of
    the sign test); 0 for an unbiased estimate whatever the dof."""
    if not z:
        return math.nan, math.nan, math.nan
    ordered = sorted(z)
    k = max(int(stats.binom.ppf(0.025, len(z), 0.5)) - 1, 0)
    return float(np.median(z)), ordered[k], ordered[len(z) - 1 - k]


def _flag(ok: bool) -> str:
    return "ok" if ok else "MISS"


def summarize(criterion: str, rows: list[dict[str, Any]], reference: list[dict[str, Any]]) -> str:
    """The table of one criterion's campaigns (`reference`: the band criterion's rows)."""
    name, settle = CRITERIA[criterion]
    keys = ", ".join(f"{k} = {v!r}" for k, v in settle.items()) or "as in the file"
    errors = [r for r in rows if r["error"]]
    failed = [r for r in rows if r.get("trials_failed")]
    completed = sum(r.get("outcome") == "completed" and not r.get("trials_failed") for r in rows)
    fitted = [
        r for r in rows if "C" in r and math.isfinite(r["C"]["z"]) and math.isfinite(r["T"]["z"])
    ]
    lines = [
        f'criterion "{criterion}" (examples/{name}, [settle] {keys}):',
        f"  campaigns run {len(rows)}: completed {completed}, with failed trials {len(failed)} "
        f"({sum(len(r['trials_failed']) for r in failed)} trials), errors {len(errors)}; "
        f"analysed {len(fitted)}",
    ]
    lines.append(f"  {'':<28}{'C':>22}{'T':>22}   target")
    bias = {p: pooled_bias(fitted, p) for p in PARAMETERS.values()}
    median = {p: median_z([r[p]["z"] for r in fitted]) for p in bias}
    cover = {
        p: _share([r[p]["ci"][0] <= r[p]["true"] <= r[p]["ci"][1] for r in fitted]) for p in bias
    }
    lo, hi = COVERAGE_TARGET
    lines.append(
        f"  {'bias, in SE (pooled)':<28}"
        + "".join(f"{f'{m:+.2f} +- {s:.2f}':>22}" for m, s in bias.values())
        + f"   |bias| <= {BIAS_TARGET}: "
        + " ".join(_flag(abs(m) <= BIAS_TARGET) for m, _ in bias.values())
    )
    lines.append(
        f"  {'median of (est - true) / SE':<28}"
        + "".join(f"{f'{m:+.2f} [{a:+.2f}, {b:+.2f}]':>22}" for m, a, b in median.values())
        + "   0 if unbiased (95 % interval)"
    )
    lines.append(
        f"  {'95 % CI coverage':<28}"
        + "".join(f"{f'{100 * p:.1f} +- {100 * s:.1f} %':>22}" for p, s, _ in cover.values())
        + f"   {100 * lo:.0f}-{100 * hi:.0f} %: "
        + " ".join(_flag(lo <= p <= hi) for p, _, _ in cover.values())
    )
    pi, pi_se, n_pi = _share([c["within_interval"] for r in fitted for c in r["controls"]])
    lines.append(
        f"  control residuals within their 95 % prediction interval (eqs 2.10-2.11): "
        f"{100 * pi:.1f} +- {100 * pi_se:.1f} % of {n_pi}   {100 * lo:.0f}-{100 * hi:.0f} %: "
        f"{_flag(lo <= pi <= hi)}"
    )
    stand = [s for r in rows if (s := per_trial_s(r)) is not None]
    line = f"  stand time per trial {np.mean(stand) / 3600 if stand else math.nan:.2f} h"
    ref = {r["index"]: s for r in reference if (s := per_trial_s(r)) is not None}
    pairs = [
        (s, ref[r["index"]])
        for r in rows
        if (s := per_trial_s(r)) is not None and r["index"] in ref
    ]
    if pairs:
        ratio = sum(s for s, _ in pairs) / sum(b for _, b in pairs)
        line += f"; x {ratio:.3f} the {REFERENCE} criterion's on the same {len(pairs)} draws"
        if any(r.get("settle_method") == "compensated" for r in rows):
            line += f"   <= {COMPENSATED_STAND_TARGET}: {_flag(ratio <= COMPENSATED_STAND_TARGET)}"
    else:
        line += f" (no {REFERENCE} criterion run to compare with)"
    lines.append(line)
    wall = sum(r["wall_s"] for r in rows)
    lines.append(
        f"  wall time {wall:.0f} s of campaigns, {wall / max(len(rows), 1):.1f} s per campaign"
    )
    for r in errors:
        lines.append(f"  error, draw {r['index']}: {r['error']}")
    for r in failed:
        lines.append(f"  failed, draw {r['index']}: " + "; ".join(r["trials_failed"]))
    return "\n".join(lines)


def progress(done: int, total: int, row: Mapping[str, Any]) -> str:
    head = (
        f"[{done:>{len(str(total))}}/{total}] {row['criterion']:<10} draw {row['index']:<3} "
        f"C = {row['C_gcm2s2']:.3e}, T = {row['T_s']:.3f} s, simulator seed {row['bus_seed']}: "
    )
    if row["error"]:
        return head + f"ERROR {row['error']}"
    parts = [str(row.get("outcome"))]
    if row.get("trials_failed"):
        parts.append(f"{len(row['trials_failed'])} trials failed")
    if "C" in row:
        parts.append(f"C {row['C']['z']:+.2f} SE, T {row['T']['z']:+.2f} SE")
        inside = sum(c["within_interval"] for c in row["controls"])
        parts.append(f"controls {inside}/{len(row['controls'])} in PI")
    if (s := per_trial_s(row)) is not None:
        parts.append(f"{s / 3600:.2f} h/trial stand")
    return head + ", ".join(parts) + f" ({row['wall_s']:.0f} s)"


def save(path: Path, args: argparse.Namespace, rows: list[dict[str, Any]], done: bool) -> None:
    """The rows so far as one JSON document, replacing the file whole (a run that is stopped
    keeps the campaigns it finished: `--table-from` prints their tables)."""
    document = {
        "arguments": {k: str(v) for k, v in vars(args).items() if k != "table_from"},
        "complete": done,
        "rows": rows,
    }
    partial = path.with_name(path.name + ".partial")
    partial.write_text(json.dumps(document, indent=1))
    partial.replace(path)


def print_tables(rows: list[dict[str, Any]], chosen: list[str]) -> None:
    rows.sort(key=lambda r: (chosen.index(r["criterion"]), r["index"]))
    by = {c: [r for r in rows if r["criterion"] == c] for c in chosen}
    for criterion in chosen:
        print()
        print(summarize(criterion, by[criterion], by.get(REFERENCE, [])))


def arguments(description: str, campaigns: int) -> argparse.ArgumentParser:
    """The options every whole-campaign validation takes (this script's and
    `validation/misstated_plan.py`'s): draws, jobs, the rows file, resume, tables from it."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--campaigns", type=int, default=campaigns)
    parser.add_argument("--seed", type=int, default=1, help="seed of the draws of C, T, seeds")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument(
        "--out", type=Path, help="keep the per-campaign rows here (JSON, rewritten as they come)"
    )
    parser.add_argument(
        "--resume",
        action="store_true",
        help="with --out: keep the rows already there for the same draws, run only the rest",
    )
    parser.add_argument(
        "--table-from", type=Path, help="print the tables of the rows kept by --out; run nothing"
    )
    return parser


def run(
    parser: argparse.ArgumentParser,
    args: argparse.Namespace,
    chosen: list[str],
    tables: Callable[[list[dict[str, Any]], list[str]], None],
) -> int:
    """Run the campaigns of the `chosen` criteria on the same draws (or print the tables of
    kept rows with --table-from) and print `tables`; 1 when a campaign raised."""
    unknown = [c for c in chosen if c not in CRITERIA]
    if unknown or not chosen or args.campaigns < 1 or args.jobs < 1:
        parser.error(
            f"unknown criteria {', '.join(unknown)} (known: {', '.join(CRITERIA)})"
            if unknown
            else "need at least one criterion, campaign and job"
        )
    if args.table_from is not None:
        document = json.loads(args.table_from.read_text())
        rows = [r for r in document["rows"] if r["criterion"] in chosen]
        chosen = [c for c in chosen if any(r["criterion"] == c for r in rows)]
        state = "complete" if document["complete"] else "INCOMPLETE (the run was stopped)"
        print(f"{len(rows)} campaigns from {args.table_from}, {state}: {document['arguments']}")
        tables(rows, chosen)
        return 0
    runs = [(c, d) for d in draws(args.campaigns, args.seed) for c in chosen]  # paired, in order
    kept: list[dict[str, Any]] = []
    if args.resume:
        if args.out is None or not args.out.is_file():
            parser.error("--resume continues the rows of an --out file that exists")
        earlier = {
            (r["criterion"], r["index"]): r for r in json.loads(args.out.read_text())["rows"]
        }
        for c, d in runs:  # the same criterion and draw (C, T, simulator seed), else run again
            r = earlier.get((c, d.index))
            if r is not None and all(r[k] == v for k, v in asdict(d).items()):
                kept.append(r)
        done = {(r["criterion"], r["index"]) for r in kept}
        runs = [(c, d) for c, d in runs if (c, d.index) not in done]
    print(
        f"{args.campaigns} campaigns per criterion (draws --seed {args.seed}): true C uniform in "
        f"{C_RANGE[0] / 1e7:g}-{C_RANGE[1] / 1e7:g} x 10^7 g cm^2 s^-2, T uniform in "
        f"{T_RANGE[0]:g}-{T_RANGE[1]:g} s, one simulator seed per campaign; the same draws for "
        "every criterion",
        flush=True,
    )
    if kept:
        print(f"{len(kept)} campaigns kept from {args.out}, {len(runs)} to run", flush=True)
    start = time.perf_counter()
    rows: list[dict[str, Any]] = list(kept)

    def finished(row: dict[str, Any]) -> None:
        rows.append(row)
        print(progress(len(rows) - len(kept), len(runs), row), file=sys.stderr, flush=True)
        if args.out is not None:
            save(args.out, args, rows, done=False)

    if args.jobs == 1:
        for criterion, draw in runs:
            finished(campaign_row(criterion, draw))
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futures = [pool.submit(campaign_row, c, d) for c, d in runs]
            for future in as_completed(futures):
                finished(future.result())
    elapsed = time.perf_counter() - start
    if args.out is not None:
        save(args.out, args, rows, done=True)
    tables(rows, chosen)
    print(f"\nelapsed {elapsed:.0f} s wall with {args.jobs} jobs")
    if args.out is not None:
        print(f"rows in {args.out}")
    return 1 if any(r["error"] for r in rows) else 0


def main() -> int:
    parser = arguments(__doc__.splitlines()[0], campaigns=100)
    parser.add_argument(
        "--criteria",
        default=",".join(CRITERIA),
        help=f"comma-separated labels of CRITERIA: {', '.join(CRITERIA)}".replace("%", "%%"),
    )
    args = parser.parse_args()
    chosen = [c.strip() for c in args.criteria.split(",") if c.strip()]
    return run(parser, args, chosen, print_tables)


if __name__ == "__main__":
    sys.exit(main())
