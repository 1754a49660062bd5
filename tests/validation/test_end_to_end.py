"""validation/end_to_end.py cannot rot silently: its per-campaign function runs one shortened
paper campaign (the paper's six trials, N = 3, short windows, a compass that settles in minutes)
end to end, and its row agrees with the database: the plan stored with the campaign is the one
drawn, the estimates, SEs and control verdicts are those `gyrostand analyze ID --json` reports,
and the stand times are the stored ones. Virtual time: no wall clock involved."""

from __future__ import annotations

import importlib.util
import json
import sqlite3
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gyrostand.analysis.gyro_model import Conditions, KnownConstants, RollingErrorModel
from gyrostand.cli import app
from gyrostand.plan.overrides import with_keys

ROOT = Path(__file__).resolve().parents[2]
SHORT = {  # the paper campaign, quick: a fast compass, heading at 2 Hz, short windows
    "campaign": {"n_obs": 3},
    "observation": {"still_window_s": 30.0, "rocking_window_periods": 4},
    "settle": {"hold_s": 60.0, "max_wait_s": 3600.0},
    "bus.simulator": {"heading_rate_hz": 2.0, "status_rate_hz": 0.5},
    "bus.simulator.compass": {"undamped_period_s": 240.0, "damping_ratio": 0.8},
}


def load_script():
    spec = importlib.util.spec_from_file_location("end_to_end", ROOT / "validation/end_to_end.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


def test_a_campaign_row_agrees_with_the_database(tmp_path: Path) -> None:
    e2e = load_script()
    draw = e2e.draws(1, seed=7)[0]
    base = with_keys((ROOT / "examples" / "paper.toml").read_text(), SHORT)
    row = e2e.campaign_row("band", draw, base=base, folder=tmp_path)
    assert row["error"] is None and row["outcome"] == "completed" and not row["trials_failed"]
    db = tmp_path / "campaign.sqlite"

    connection = sqlite3.connect(db)
    try:
        (plan_toml,) = connection.execute("SELECT plan_toml FROM campaign").fetchone()
        spans = connection.execute(
            'SELECT t."index", MIN(s.settle_started_ms), MAX(o.window_end_ms) FROM trial t '
            "JOIN series s ON s.trial_id = t.id JOIN observation o ON o.series_id = s.id "
            'GROUP BY t."index" ORDER BY t."index"'
        ).fetchall()
    finally:
        connection.close()
    stored = tomllib.loads(plan_toml)
    assert stored["bus"]["seed"] == draw.bus_seed
    assert stored["bus"]["simulator"]["compass"]["c_gcm2s2"] == draw.C_gcm2s2 == row["C"]["true"]
    assert stored["bus"]["simulator"]["compass"]["t_s"] == draw.T_s == row["T"]["true"]
    assert stored["campaign"]["n_obs"] == 3

    result = CliRunner().invoke(
        app, ["analyze", str(row["campaign_id"]), "--db", str(db), "--json"]
    )
    assert result.exit_code == 0, result.stderr
    analysis = json.loads(result.stdout)
    fit = analysis["fit"]
    for name, short in (("C_gcm2s2", "C"), ("T_s", "T")):
        assert row[short]["estimate"] == fit["estimates"][name]
        assert row[short]["se"] == fit["std_errors"][name]
        lo, hi = row[short]["ci"]
        assert lo < fit["estimates"][name] < hi
    assert (row["q"], row["dof"]) == (analysis["q"], fit["dof"])
    assert [(c["index"], c["within_interval"]) for c in row["controls"]] == [
        (c["index"], c["within_interval"]) for c in analysis["controls"]
    ] and len(row["controls"]) == 2

    # each trial mean against model 1.1 at the drawn C and T (the rolling error the simulator
    # settles at), with the SE and dof `analyze` reports
    constants = KnownConstants(lP_gcm2s2=6.57e6, H1_gcm2s=1.55e8, latitude_deg=46.5,
                               earth_rate_rad_s=7.3e-5, gravity_cm_s2=981.0)  # fmt: skip
    trials = analysis["trials"]
    alpha = RollingErrorModel(constants)(
        Conditions(
            *(
                np.array([t[k] for t in trials])
                for k in ("direction_deg", "amplitude_cm", "period_s")
            )
        ),
        C_gcm2s2=draw.C_gcm2s2,
        T_s=draw.T_s,
    )
    assert [t["index"] for t in row["trials"]] == [t["index"] for t in trials]
    for mine, theirs, a in zip(row["trials"], trials, alpha, strict=True):
        assert mine["error_deg"] == pytest.approx(theirs["delta_deg"] - a, abs=1e-12)
        assert mine["se_deg"] == pytest.approx(theirs["var_mean_deg2"] ** 0.5, rel=1e-12)
        assert mine["dof"] == theirs["dof"]

    # a trial's stand time spans at least its settles and windows as stored
    assert sorted(row["stand_s"]) == [str(i) for i in range(1, 7)]
    for index, first_ms, last_ms in spans:
        assert row["stand_s"][str(index)] >= (last_ms - first_ms) / 1000 > 0
