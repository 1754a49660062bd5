"""validation/misstated_plan.py's table (issue 34's figures) on rows built with known errors:
the SD/SE ratios, the coverages, the trial-mean figures and the warning rate are those computed
here by hand, and each is flagged against its target."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import stats

ROOT = Path(__file__).resolve().parents[2]


def load_script():
    sys.path.insert(0, str(ROOT / "validation"))
    spec = importlib.util.spec_from_file_location(
        "misstated", ROOT / "validation/misstated_plan.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules["misstated"] = module  # (its dataclasses look their module up there)
    spec.loader.exec_module(module)
    return module


def rows_of(rel_err: np.ndarray, rel_se: np.ndarray, warned: int) -> list[dict[str, Any]]:
    """Campaigns whose C and T have the given relative errors and SEs (t(2) intervals), six trial
    means each with error err_k and SE 0.01 deg, and two controls, one of them outside."""
    rows = []
    for i, (e, s) in enumerate(zip(rel_err, rel_se, strict=True)):
        row: dict[str, Any] = {"criterion": "compensated damping +0.05", "index": i, "error": None}
        half = stats.t.ppf(0.975, 2) * s
        for p, true in (("C", 6e7), ("T", 1.1)):
            row[p] = {
                "true": true,
                "estimate": true * (1 + e),
                "se": true * s,
                "ci": [true * (1 + e - half), true * (1 + e + half)],
                "z": e / s,
            }
        row["trials"] = [
            {"index": k, "error_deg": 0.01 * (k - 3.5) / 2, "se_deg": 0.01, "dof": 8}
            for k in range(1, 7)
        ]
        row["controls"] = [{"within_interval": True}, {"within_interval": False}]
        row["warnings"] = ["the record contradicts the plan: ..."] if i < warned else []
        rows.append(row)
    return rows


def test_the_table_states_the_figures_computed_here() -> None:
    script = load_script()
    rng = np.random.default_rng(34)
    rel_err = 0.02 * rng.standard_normal(60)
    rel_se = np.full(60, 0.02)
    rows = rows_of(rel_err, rel_se, warned=15)
    text = script.table("compensated damping +0.05", rows)

    ratio = rel_err.std(ddof=1) / 0.02
    covered = np.mean(np.abs(rel_err) <= stats.t.ppf(0.975, 2) * 0.02)
    (c_line,) = [line for line in text.splitlines() if line.strip().startswith("C:")]
    assert f"mean z {np.mean(rel_err / rel_se):+.2f}" in c_line
    assert f"SD/SE {ratio:.2f}" in c_line
    assert f"coverage {100 * covered:.1f}" in c_line
    assert "warned (the record contradicts the plan): 25 % of 60 (no target)" in text

    # trial means: errors -0.0125 ... +0.0125 deg against SE 0.01 (dof 8): RMS ratio, all covered
    err = 0.01 * (np.arange(1, 7) - 3.5) / 2
    (t_line,) = [line for line in text.splitlines() if "trial means (360)" in line]
    assert f"SD/SE {np.sqrt(np.mean(err**2)) / 0.01:.2f}" in t_line
    assert "coverage 100.0" in t_line and re.search(
        r"coverage 100.0 \+- 0.0 % \(93-97 %: MISS\)", t_line
    )
    assert "controls within their 95 % prediction interval: 50.0" in text and "MISS" in text


def test_honest_figures_are_flagged_ok_and_the_shipped_plan_s_false_alarms_have_a_target() -> None:
    script = load_script()
    rng = np.random.default_rng(7)
    # relative errors of exactly the stated spread: SD/SE 1, coverage of t(2) intervals ~95 %
    rel_err = 0.02 * stats.norm.ppf((np.arange(400) + 0.5) / 400)
    rng.shuffle(rel_err)
    rows = rows_of(rel_err, np.full(400, 0.02), warned=4)
    for r in rows:
        r["criterion"] = "estimate"
    text = script.table("estimate", rows)
    (c_line,) = [line for line in text.splitlines() if line.strip().startswith("C:")]
    assert "SD/SE 1.00" in c_line and "(1.00 +- 0.05: ok)" in c_line
    assert "warned (the record contradicts the plan): 1 % of 400 (<= 5 %: ok)" in text


def test_the_sd_se_spread_stated_is_the_spread_over_repeated_runs() -> None:
    """The +- printed beside an SD/SE of C or T against the SD of that SD/SE over 400 runs of
    200 campaigns each, computed here: each campaign's relative error N(0, sigma_i^2), its SE
    sigma_i sqrt(chi2(2) / 2) (the fit's 2 residual dof), sigma_i spread as the draws' designs
    spread theirs (log-SD 0.5), so the stated SEs are right and SD/SE is 1 in the mean. Its
    spread is 0.095; the table's bootstrap states 0.07-0.09 (it errs low on so heavy a tail);
    before, the table stated 0.05 (that of an SD from n normal values)."""
    script = load_script()
    rng = np.random.default_rng(2034)
    n = 200

    def campaigns() -> tuple[np.ndarray, np.ndarray]:
        sigma = 0.02 * np.exp(0.5 * rng.standard_normal(n))
        return sigma * rng.standard_normal(n), sigma * np.sqrt(rng.chisquare(2, n) / 2)

    runs = [campaigns() for _ in range(400)]
    ratios = np.array([e.std(ddof=1) / np.sqrt(np.mean(s**2)) for e, s in runs])
    spread = ratios.std(ddof=1)
    assert 0.08 < spread < 0.12
    stated, intervals = [], []
    for rel_err, rel_se in runs[:6]:
        text = script.table("estimate", rows_of(rel_err, rel_se, warned=0))
        (c_line,) = [line for line in text.splitlines() if line.strip().startswith("C:")]
        found = re.search(r"SD/SE (\d+\.\d+) \+- (\d+\.\d+)( \[(\d+\.\d+), (\d+\.\d+)\])?", c_line)
        assert found is not None, c_line
        stated.append(float(found[2]))
        intervals.append((float(found[4]), float(found[1]), float(found[5])) if found[3] else None)
    assert np.mean(stated) == pytest.approx(spread, rel=0.25)
    assert all(i is not None and i[0] < i[1] < i[2] for i in intervals)  # and its 95 % interval
