"""What a campaign plan contributes to the analysis: known constants B, level q, start values,
admissible region and the ship forecast, read from the plan's TOML TEXT.

Tables read: [instrument] (lp_gcm2s2, h1_gcm2s), [site] (latitude_deg, earth_rate_rad_s,
gravity_cm_s2), [analysis] (q, start_c, start_t_s, admissible_c, admissible_t_s) and [forecast]
(roll_deg, arm_cm, period_s, course_deg, latitude_deg, motion, amplitude_cm). Every problem raises
`AnalysisError` naming the table and key. A plan stored with an imported campaign may lack
[analysis] and [forecast]: pass ``fallback`` to take those from other settings instead.
"""

import tomllib
from dataclasses import dataclass
from typing import Any

from gyrostand.analysis import paper_example
from gyrostand.analysis.campaign import AdmissibleRegion
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.forecast import ShipConditions
from gyrostand.analysis.gyro_model import KnownConstants


@dataclass(frozen=True)
class AnalysisSettings:
    """What a plan contributes to the analysis."""

    constants: KnownConstants
    q: float
    start: tuple[float, float]
    admissible: AdmissibleRegion | None
    forecast: ShipConditions | None


def _table(plan: dict[str, Any], name: str) -> dict[str, Any]:
    table = plan.get(name)
    if not isinstance(table, dict):
        raise AnalysisError(f"table [{name}] is missing")
    return table


def _number(table: dict[str, Any], table_name: str, key: str) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise AnalysisError(f"[{table_name}] {key} must be a number, got {value!r}")
    return float(value)


def _range(table: dict[str, Any], key: str) -> tuple[float, float] | None:
    value = table.get(key)
    if value is None:
        return None
    numbers = isinstance(value, list) and len(value) == 2
    numbers = numbers and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    if not (numbers and value[0] < value[1]):
        raise AnalysisError(f"[analysis] {key} must be [low, high], got {value!r}")
    return float(value[0]), float(value[1])


def _constants(plan: dict[str, Any]) -> KnownConstants:
    instrument, site = _table(plan, "instrument"), _table(plan, "site")
    return KnownConstants(
        lP_gcm2s2=_number(instrument, "instrument", "lp_gcm2s2"),
        H1_gcm2s=_number(instrument, "instrument", "h1_gcm2s"),
        earth_rate_rad_s=_number(site, "site", "earth_rate_rad_s"),
        gravity_cm_s2=_number(site, "site", "gravity_cm_s2"),
        latitude_deg=_number(site, "site", "latitude_deg"),
    )


def _forecast(ship: dict[str, Any]) -> ShipConditions:
    return ShipConditions(
        roll_deg=_number(ship, "forecast", "roll_deg"),
        arm_cm=_number(ship, "forecast", "arm_cm"),
        period_s=_number(ship, "forecast", "period_s"),
        course_deg=_number(ship, "forecast", "course_deg"),
        latitude_deg=_number(ship, "forecast", "latitude_deg"),
        motion=str(ship.get("motion", "roll")),
        amplitude_cm=(
            _number(ship, "forecast", "amplitude_cm") if "amplitude_cm" in ship else None
        ),
    )


def settings_from_plan(text: str, *, fallback: AnalysisSettings | None = None) -> AnalysisSettings:
    """The analysis settings of a plan given as TOML text (AnalysisError on any problem).

    With ``fallback``, a missing [analysis] table takes q, start and admissible region from it
    and a missing [forecast] its forecast; the constants always come from the plan."""
    try:
        plan = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise AnalysisError(f"not valid TOML ({exc})") from None
    constants = _constants(plan)
    if "analysis" not in plan and fallback is not None:
        q, start, admissible = fallback.q, fallback.start, fallback.admissible
    else:
        settings = _table(plan, "analysis")
        c_range, t_range = _range(settings, "admissible_c"), _range(settings, "admissible_t_s")
        admissible = (
            None
            if c_range is None and t_range is None
            else AdmissibleRegion(c_range or (0.0, float("inf")), t_range or (0.0, float("inf")))
        )
        q = _number(settings, "analysis", "q") if "q" in settings else 0.05
        start = (
            _number(settings, "analysis", "start_c"),
            _number(settings, "analysis", "start_t_s"),
        )
    ship = plan.get("forecast")
    if ship is None:
        forecast = fallback.forecast if fallback is not None else None
    elif isinstance(ship, dict):
        forecast = _forecast(ship)
    else:
        raise AnalysisError("[forecast] must be a table")
    return AnalysisSettings(
        constants=constants, q=q, start=start, admissible=admissible, forecast=forecast
    )


SEED_000_SETTINGS = AnalysisSettings(
    constants=paper_example.CONSTANTS,
    q=0.05,
    start=paper_example.START,
    admissible=paper_example.ADMISSIBLE,
    forecast=paper_example.FORECAST,
)
"""The seed-000 example's settings (Potemkin 1982), as `analysis.paper_example` states them."""
