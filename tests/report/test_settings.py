"""report.settings: a plan's TOML text -> analysis settings, with typed errors."""

from pathlib import Path

import pytest

from gyrostand.analysis.errors import AnalysisError
from gyrostand.report.settings import SEED_000_SETTINGS, settings_from_plan

ROOT = Path(__file__).resolve().parents[2]


def test_example_plan_gives_the_papers_constants_and_forecast() -> None:
    settings = settings_from_plan((ROOT / "examples" / "paper.toml").read_text())
    assert settings.constants == SEED_000_SETTINGS.constants
    assert settings.start == (7.0e7, 0.55)
    assert settings.admissible is not None and settings.admissible.T_s == (0.1, 1.5)
    assert settings.forecast is not None
    assert (settings.forecast.roll_deg, settings.forecast.course_deg) == (5.0, 45.0)
    assert settings.forecast.amplitude_cm is None  # theta0 h, not the paper's rounded 65 cm


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


def test_missing_analysis_and_forecast_use_the_fallback_but_keep_the_constants() -> None:
    settings = settings_from_plan(METADATA_ONLY, fallback=SEED_000_SETTINGS)
    assert settings.constants.lP_gcm2s2 == 6.0e6 and settings.constants.latitude_deg == 50.0
    assert settings.start == SEED_000_SETTINGS.start
    assert settings.forecast == SEED_000_SETTINGS.forecast
    with pytest.raises(AnalysisError, match=r"table \[analysis\] is missing"):
        settings_from_plan(METADATA_ONLY)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[instrument", "not valid TOML"),
        (METADATA_ONLY.replace("6.0e6", '"big"'), r"\[instrument\] lp_gcm2s2 must be a number"),
        (
            METADATA_ONLY + "[analysis]\nstart_c = 7e7\nstart_t_s = 0.5\nadmissible_c = [2, 1]\n",
            r"\[analysis\] admissible_c must be \[low, high\]",
        ),
        (METADATA_ONLY.replace("50.0", "95.0"), "latitude"),
    ],
)
def test_bad_plans_raise_analysis_errors_naming_the_key(text: str, message: str) -> None:
    with pytest.raises(AnalysisError, match=message):
        settings_from_plan(text, fallback=SEED_000_SETTINGS)
