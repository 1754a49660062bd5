"""`gyrostand analyze`: text and JSON output, plans, and one-line failures."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app

CSV = Path(__file__).resolve().parents[2] / "examples" / "paper.csv"
PLAN = """
[instrument]
model = "test"
serial = "0001"
lp_gcm2s2 = 6.57e6
h1_gcm2s = 1.55e8
[site]
latitude_deg = 46.5
earth_rate_rad_s = 7.3e-5
gravity_cm_s2 = 981.0
[analysis]
q = 0.05
start_c = 7e7
start_t_s = 0.55
admissible_c = [2e7, 12e7]
admissible_t_s = [0.1, 1.5]
[forecast]
roll_deg = 5.0
arm_cm = 750.0
period_s = 7.0
course_deg = 45.0
latitude_deg = 57.0
motion = "pitch"
"""

runner = CliRunner()


def test_text_output_without_plan_uses_the_paper() -> None:
    result = runner.invoke(app, ["analyze", "--csv", str(CSV)])
    assert result.exit_code == 0, result.output
    assert "example constants, start values and ship forecast of Potemkin (1982)" in result.stderr
    for heading in ("TRIALS", "COCHRAN", "FIT", "ADEQUACY", "CONTROL", "FORECAST"):
        assert heading in result.stdout
    assert "-2.328 ± 0.534" in result.stdout


def test_json_output_is_one_document() -> None:
    result = runner.invoke(app, ["analyze", "--csv", str(CSV), "--json"])
    assert result.exit_code == 0
    data = json.loads(result.stdout)
    assert data["adequacy"]["f_p"] == pytest.approx(1.409, abs=1e-3)
    assert data["forecasts"][0]["alpha_deg"] == pytest.approx(-2.328, abs=1e-3)


def test_plan_supplies_constants_region_and_forecast(tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN)
    result = runner.invoke(app, ["analyze", "--csv", str(CSV), "--plan", str(plan), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    forecast = data["forecasts"][0]
    assert forecast["direction_deg"] == 45.0  # pitching: K = course
    assert forecast["amplitude_cm"] == pytest.approx(65.45, abs=1e-2)  # theta0 h, unrounded
    assert not any("admissible" in w for w in data["warnings"])  # T = 1.151 inside [0.1, 1.5]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([], "no source given"),
        (["--csv", "/nonexistent.csv"], "cannot read the CSV"),
    ],
)
def test_failures_are_one_line(args: list[str], message: str) -> None:
    result = runner.invoke(app, ["analyze", *args])
    assert result.exit_code == 2
    assert message in result.stderr
    assert "Traceback" not in result.output


def test_bad_plan_and_bad_data(tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN.replace("h1_gcm2s = 1.55e8", 'h1_gcm2s = "big"'))
    result = runner.invoke(app, ["analyze", "--csv", str(CSV), "--plan", str(plan)])
    assert (
        result.exit_code == 2 and "[instrument] h1_gcm2s: must be a finite number" in result.stderr
    )
    data = tmp_path / "trials.csv"
    data.write_text(CSV.read_text().replace("4.64e-4", "0"))
    result = runner.invoke(app, ["analyze", "--csv", str(data)])
    assert result.exit_code == 2 and "trial 2" in result.stderr and "zero" in result.stderr


def test_a_trial_left_out_of_a_stored_analysis_is_named(tmp_path: Path) -> None:
    """A failed trial is not analysed, and `analyze` says which and why (it fits with fewer
    degrees of freedom: the user must know)."""
    import sqlite3

    db = str(tmp_path / "c.sqlite")
    assert CliRunner().invoke(app, ["import", str(CSV), "--db", db]).exit_code == 0
    with sqlite3.connect(db) as conn:
        conn.execute(
            "UPDATE trial SET status = 'failed', failure_reason = 'stand refused: amplitude'"
            ' WHERE "index" = 2'
        )
    result = CliRunner().invoke(app, ["analyze", "1", "--db", db])
    assert result.exit_code == 0, result.stderr
    assert (
        "warning: trial 2 left out of the analysis (trial failed: stand refused: amplitude)\n"
        in result.stderr
    )
    assert result.stderr.count("left out") == 1
