"""report.settings: a parsed plan -> analysis settings; the partial form's fallback and notes."""

from pathlib import Path

import pytest

from gyrostand.plan.model import EARTH_RATE_RAD_S, PlanError, load_plan, parse_any_plan, parse_plan
from gyrostand.report.settings import SEED_000_SETTINGS, fallback_notes, settings_from_plan

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "examples" / "paper.toml"


def test_example_plan_gives_the_papers_constants_and_forecast() -> None:
    plan = load_plan(PAPER)
    settings = settings_from_plan(plan)
    assert settings.constants == SEED_000_SETTINGS.constants
    assert settings.start == (7.0e7, 0.55)
    assert settings.admissible is not None and settings.admissible.T_s == (0.1, 1.5)
    assert settings.forecast is not None
    assert (settings.forecast.roll_deg, settings.forecast.course_deg) == (5.0, 45.0)
    assert settings.forecast.amplitude_cm is None  # theta0 h, not the paper's rounded 65 cm
    assert fallback_notes(plan) == ()


def test_plan_without_earth_rate_gets_the_plans_default() -> None:
    """Regression: parse_plan defaulted [site] earth_rate_rad_s while the analysis settings
    re-read the TOML and failed ("earth_rate_rad_s must be a number, got None")."""
    plan = parse_plan(PAPER.read_text().replace("earth_rate_rad_s = 7.3e-5\n", ""))
    assert plan.site.earth_rate_rad_s == EARTH_RATE_RAD_S
    assert settings_from_plan(plan).constants.earth_rate_rad_s == EARTH_RATE_RAD_S


def test_forecast_amplitude_is_accepted_and_used() -> None:
    """Regression: the analysis read [forecast] amplitude_cm that the plan model refused."""
    text = PAPER.read_text().replace('motion = "roll"', 'motion = "roll"\namplitude_cm = 65.0')
    forecast = settings_from_plan(parse_plan(text)).forecast
    assert forecast is not None and forecast.effective_amplitude_cm == 65.0


METADATA_ONLY = """
[instrument]
model = "m"
serial = "s"
lp_gcm2s2 = 6.0e6
h1_gcm2s = 1.5e8
[site]
latitude_deg = 50.0
earth_rate_rad_s = 7.29e-5
gravity_cm_s2 = 981.0
"""


def test_partial_plan_takes_analysis_and_forecast_from_the_paper_and_says_so() -> None:
    plan = parse_any_plan(METADATA_ONLY)
    settings = settings_from_plan(plan)
    assert settings.constants.lP_gcm2s2 == 6.0e6 and settings.constants.latitude_deg == 50.0
    assert settings.start == SEED_000_SETTINGS.start
    assert settings.forecast == SEED_000_SETTINGS.forecast
    notes = fallback_notes(plan)
    assert [n.split(":")[0] for n in notes] == [
        "The stored plan has no [analysis] table",
        "The stored plan has no [forecast] table",
    ]
    assert all("Potemkin (1982)" in n for n in notes)
    with_analysis = parse_any_plan(METADATA_ONLY + "[analysis]\nstart_c = 6e7\nstart_t_s = 1.0\n")
    assert settings_from_plan(with_analysis).start == (6e7, 1.0)
    assert len(fallback_notes(with_analysis)) == 1


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("[instrument", "TOML syntax: "),
        (
            METADATA_ONLY.replace("6.0e6", '"big"'),
            "[instrument] lp_gcm2s2: must be a finite number",
        ),
        (
            METADATA_ONLY + "[analysis]\nstart_c = 7e7\nstart_t_s = 0.5\nadmissible_c = [2, 1]\n",
            "[analysis] admissible_c: must be [low, high] with 0 < low < high",
        ),
        (METADATA_ONLY.replace("50.0", "95.0"), "[site] latitude_deg: must be < 90"),
        (
            METADATA_ONLY + "[campaign]\noperator = 'x'\nn_obs = 5\n",
            "[campaign] n_obs: unknown key",
        ),
    ],
)
def test_bad_partial_plans_name_the_key(text: str, problem: str) -> None:
    with pytest.raises(PlanError) as caught:
        parse_any_plan(text)
    assert caught.value.problems[0].startswith(problem)


def test_an_imports_stored_plan_is_the_partial_form() -> None:
    """What `import` stores without a plan file (db.io.metadata_toml) reads as a partial plan."""
    from gyrostand.db.io import SEED_000_METADATA, metadata_toml
    from gyrostand.plan.model import PartialPlan

    plan = parse_any_plan(metadata_toml(SEED_000_METADATA))
    assert isinstance(plan, PartialPlan)
    assert settings_from_plan(plan).constants == SEED_000_SETTINGS.constants
    assert len(fallback_notes(plan)) == 2
