"""One plan model for every reader: what the old readers disagreed on.

(a) A plan without [site] earth_rate_rad_s ran (the plan model has a default) but `analyze` and
    `report` failed: the analysis settings re-read the TOML and found no value.
(b) The analysis read [forecast] amplitude_cm, which the plan model refused as unknown.
"""

import json
from pathlib import Path

from typer.testing import CliRunner

from gyrostand.acquisition.store import CampaignStore
from gyrostand.cli import app
from gyrostand.db.queries import load_campaign
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.plan.model import EARTH_RATE_RAD_S, parse_plan
from gyrostand.report.stored import stored_settings

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "examples" / "paper.toml"
CSV = ROOT / "examples" / "paper.csv"
WITHOUT_EARTH_RATE = PAPER.read_text().replace("earth_rate_rad_s = 7.3e-5\n", "")
runner = CliRunner()


def test_stored_campaign_without_earth_rate_gets_the_default(tmp_path: Path) -> None:
    """(a) as `campaign run` stores it, then as `analyze` and `report` read it."""
    sessions = open_database(sqlite_url(tmp_path / "db.sqlite"))
    store = CampaignStore.create(sessions, parse_plan(WITHOUT_EARTH_RATE))
    with sessions() as session:
        campaign = load_campaign(session, store.campaign_id)
        settings, notes = stored_settings(campaign)
    assert campaign.earth_rate_rad_s == settings.constants.earth_rate_rad_s == EARTH_RATE_RAD_S
    assert notes == ()


def test_analyze_and_import_take_a_plan_without_earth_rate(tmp_path: Path) -> None:
    """(a) through the CLI: `analyze --plan` and `import --plan` then `analyze ID`."""
    plan = tmp_path / "plan.toml"
    plan.write_text(WITHOUT_EARTH_RATE)
    result = runner.invoke(app, ["analyze", "--csv", str(CSV), "--plan", str(plan), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["constants"]["earth_rate_rad_s"] == EARTH_RATE_RAD_S
    db = str(tmp_path / "db.sqlite")
    result = runner.invoke(app, ["import", str(CSV), "--plan", str(plan), "--db", db])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["analyze", "1", "--db", db, "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["constants"]["earth_rate_rad_s"] == EARTH_RATE_RAD_S


def test_forecast_amplitude_is_a_plan_key_and_the_analysis_uses_it(tmp_path: Path) -> None:
    """(b) `campaign run` validates the plan the analysis reads."""
    text = PAPER.read_text().replace('motion = "roll"', 'motion = "roll"\namplitude_cm = 65.0')
    assert parse_plan(text).forecast.amplitude_cm == 65.0
    plan = tmp_path / "plan.toml"
    plan.write_text(text)
    assert runner.invoke(app, ["plan", "check", str(plan)]).exit_code == 0
    result = runner.invoke(app, ["analyze", "--csv", str(CSV), "--plan", str(plan), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["forecasts"][0]["amplitude_cm"] == 65.0
