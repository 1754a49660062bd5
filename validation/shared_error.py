"""The fit of C and T when the trial means share an error (issue 34), on synthetic trial means:
cheap, before whole campaigns (`validation/misstated_plan.py`).

A compensated campaign's structure is taken as stored (tests/analysis/data/
shared_error_campaign.json: the trials' conditions and var_mean, and per compensated series
its sensitivity to the period and damping ratio and their covariance, `analysis.gls`). Per draw,
true C and T as `validation/end_to_end.py` draws them; each trial mean is model 1.1 plus an
independent error (variance var_mean less its series' own period and damping part) plus the
compensations' shared error: one (period, ratio) error per series, those of one run nested
(Cov = Sigma of the later), drawn here from their own joint covariance, not from
`analysis.gls`. Printed per fit, each figure beside its target:
- "independent": the paper's fit (eq 1.6, S^2 with n - m dof): what the analysis did before;
- "generalised": `analyze_campaign(..., shared=)`, GLS with S^2 from the whitened residuals;
- "generalised, V known": the same estimates, SE from (X^T V^-1 X)^-1 alone, normal quantile;
with z = (estimate - true) / SE: mean z, SD/SE (SD of the relative errors over the RMS of the
relative SEs, 1.00 +- 0.05), coverage of the 95 % intervals (93-97 %), the controls within
their 95 % prediction intervals, and how often Fisher's test (trial-mean basis) rejects the
model, which is true here (q = 5 %).

Run: .venv/bin/python validation/shared_error.py [--draws 4000] [--seed 1]
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.gls import SharedError
from gyrostand.analysis.gyro_model import PARAMETERS, Conditions, KnownConstants, RollingErrorModel
from gyrostand.analysis.trials import SeriesSummary, TrialInput

DATA = Path(__file__).resolve().parents[1] / "tests/analysis/data/shared_error_campaign.json"
C_RANGE, T_RANGE = (3e7, 12e7), (0.4, 1.4)  # as validation/end_to_end.py draws them
METHODS = ("independent", "generalised", "generalised, V known")


@dataclass(frozen=True)
class Structure:
    """A campaign's trials and its compensated series' shared errors."""

    constants: KnownConstants
    start: tuple[float, float]
    trials: list[dict[str, Any]]
    shared: dict[tuple[int, int], SharedError]

    @classmethod
    def load(cls, path: Path = DATA) -> Structure:
        doc = json.loads(path.read_text())
        shared = {(s["trial"], s["j"]): SharedError.from_dict(s) for s in doc["shared"]}
        return cls(KnownConstants(**doc["constants"]), tuple(doc["start"]), doc["trials"], shared)

    def errors(self, rng: np.random.Generator) -> np.ndarray:
        """One draw of every trial mean's error (deg)."""
        keys = sorted(self.shared, key=lambda k: self.shared[k].at_ms)
        blocks = np.zeros((2 * len(keys), 2 * len(keys)))
        for a, ka in enumerate(keys):
            for b, kb in enumerate(keys):
                ea, eb = self.shared[ka], self.shared[kb]
                if ea.record_ms == eb.record_ms:
                    later = ea if ea.at_ms >= eb.at_ms else eb
                    blocks[2 * a : 2 * a + 2, 2 * b : 2 * b + 2] = later.covariance
        scale = np.sqrt(np.diag(blocks))  # the nearest PSD matrix (`analysis.gls.pd_covariance`)
        values, vectors = np.linalg.eigh(blocks / np.outer(scale, scale))
        root = vectors * np.sqrt(np.maximum(values, 0.0)) * scale[:, None]
        pd = (root @ rng.standard_normal(len(blocks))).reshape(-1, 2)
        out = []
        for t in self.trials:
            shared, own = 0.0, 0.0
            for j, sign in ((1, -1.0), (2, 1.0)):
                if (t["index"], j) in self.shared:
                    e = self.shared[(t["index"], j)]
                    g = np.array(e.sensitivity)
                    shared += sign * float(g @ pd[keys.index((t["index"], j))])
                    own += float(g @ np.array(e.covariance) @ g)
            out.append(shared + rng.normal(0.0, math.sqrt(t["var_mean_deg2"] - own)))
        return np.array(out)

    def inputs(self, c: float, t: float, errors: np.ndarray) -> list[TrialInput]:
        x = Conditions(*(np.array([r[k] for r in self.trials]) for k in _CONDITIONS))
        alpha = RollingErrorModel(self.constants)(x, C_gcm2s2=c, T_s=t)
        return [
            TrialInput(
                index=r["index"],
                role=r["role"],
                **{k: r[k] for k in _CONDITIONS},
                before=self._series(r, 1, 0.0),
                under=self._series(r, 2, float(a + e)),
            )
            for r, a, e in zip(self.trials, alpha, errors, strict=True)
        ]

    def _series(self, trial: dict[str, Any], j: int, mean: float) -> SeriesSummary:
        """Half the trial's variances to each series; a compensated one's mean has its own."""
        half = trial["var_mean_deg2"] / 2
        own = half if (trial["index"], j) in self.shared else None
        return SeriesSummary(mean, half * trial["n"], trial["n"], var_mean_deg2=own)


_CONDITIONS = ("direction_deg", "amplitude_cm", "period_s")


def draw_rows(structure: Structure, draws: int, seed: int) -> dict[str, list[tuple]]:
    """Per method, per draw and parameter: (relative error, relative SE, covered), and per
    draw the controls within their prediction intervals."""
    rng = np.random.default_rng(seed)
    rows: dict[str, list[tuple]] = {m: [] for m in METHODS}
    for method in ("independent", "generalised"):
        rows |= {f"controls {method}": [], f"failed {method}": [], f"rejected {method}": []}
    for _ in range(draws):
        c, t = float(rng.uniform(*C_RANGE)), float(rng.uniform(*T_RANGE))
        trials = structure.inputs(c, t, structure.errors(rng))
        true = {"C_gcm2s2": c, "T_s": t}
        for method, shared in (("independent", None), ("generalised", structure.shared)):
            try:
                a = analyze_campaign(
                    trials, structure.constants, start=structure.start, shared=shared
                )
            except AnalysisError as exc:  # counted: a fit that fails states no interval
                rows[f"failed {method}"].append(str(exc))
                continue
            ci = a.confidence_intervals
            for name in PARAMETERS:
                est, se = a.fit.estimates[name], a.fit.std_errors[name]
                covered = ci[name][0] <= true[name] <= ci[name][1]
                rows[method].append(
                    (name, (est - true[name]) / true[name], se / true[name], covered)
                )
            rows[f"controls {method}"].extend(x.within_interval for x in a.controls)
            rows[f"rejected {method}"].append(a.adequacy.decision is False)
            if a.trial_covariance is not None:  # SE from V alone (scale known), normal quantile
                scale = float(np.mean(np.diag(a.trial_covariance)))
                for k, name in enumerate(PARAMETERS):
                    est = a.fit.estimates[name]
                    se = math.sqrt(a.fit.xtx_inv[k, k] * scale)
                    covered = abs(est - true[name]) <= 1.959964 * se
                    rows["generalised, V known"].append(
                        (name, (est - true[name]) / true[name], se / true[name], covered)
                    )
    return rows


def figures(rows: list[tuple], name: str) -> tuple[float, float, float]:
    """Mean z, SD/SE (SD of the relative errors over the RMS relative SE), coverage."""
    rel = np.array([r[1] for r in rows if r[0] == name])
    se = np.array([r[2] for r in rows if r[0] == name])
    cover = np.array([r[3] for r in rows if r[0] == name])
    return (
        float(np.mean(rel / se)),
        float(rel.std(ddof=1) / math.sqrt(np.mean(se**2))),
        float(cover.mean()),
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--data", type=Path, default=DATA)
    args = parser.parse_args()
    rows = draw_rows(Structure.load(args.data), args.draws, args.seed)
    print(f"{args.draws} draws (seed {args.seed}) of the trial means of {args.data.name}")
    for method in METHODS:
        for name, short in (("C_gcm2s2", "C"), ("T_s", "T")):
            mean, ratio, cover = figures(rows[method], name)
            print(
                f"  {method:>21} {short}: mean z {mean:+.2f}, SD/SE {ratio:.2f} (1.00 +- 0.05), "
                f"coverage {100 * cover:.1f} % (93-97 %)"
            )
    for method in ("independent", "generalised"):
        within = rows[f"controls {method}"]
        print(f"  controls within their 95 % PI, {method}: {100 * np.mean(within):.1f} %")
        rejected = 100 * np.mean(rows[f"rejected {method}"])
        print(f"  Fisher's test rejects model 1.1 (true here), {method}: {rejected:.1f} % (5 %)")
        failed = rows[f"failed {method}"]
        print(f"  fits failed, {method}: {len(failed)}" + (f" ({failed[0]})" if failed else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
