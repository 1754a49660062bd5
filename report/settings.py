"""What a campaign plan contributes to the analysis: known constants B, level q, start values,
admissible region and the ship forecast, from the parsed plan (`gyrostand.plan.model`).

A whole plan has every table the analysis needs. The partial form (an import's stored plan,
`analyze --plan` with the instrument tables alone) may lack [analysis] and [forecast]: those then
come from the example of Potemkin (1982), and `fallback_notes` says so.
"""

from dataclasses import dataclass

from gyrostand.analysis import paper_example
from gyrostand.analysis.campaign import AdmissibleRegion
from gyrostand.analysis.forecast import ShipConditions
from gyrostand.analysis.gyro_model import KnownConstants
from gyrostand.plan.model import AnalysisPlan, ForecastPlan, PartialPlan, Plan


@dataclass(frozen=True)
class AnalysisSettings:
    """What a plan contributes to the analysis."""

    constants: KnownConstants
    q: float
    start: tuple[float, float]
    admissible: AdmissibleRegion | None
    forecast: ShipConditions | None


SEED_000_SETTINGS = AnalysisSettings(
    constants=paper_example.CONSTANTS,
    q=0.05,
    start=paper_example.START,
    admissible=paper_example.ADMISSIBLE,
    forecast=paper_example.FORECAST,
)
"""The settings of the worked example of Potemkin (1982) (`analysis.paper_example`)."""


def _admissible(analysis: AnalysisPlan) -> AdmissibleRegion | None:
    c_range, t_range = analysis.admissible_c, analysis.admissible_t_s
    if c_range is None and t_range is None:
        return None
    unbounded = (0.0, float("inf"))
    return AdmissibleRegion(c_range or unbounded, t_range or unbounded)


def _ship(forecast: ForecastPlan) -> ShipConditions:
    return ShipConditions(
        roll_deg=forecast.roll_deg,
        arm_cm=forecast.arm_cm,
        period_s=forecast.period_s,
        course_deg=forecast.course_deg,
        latitude_deg=forecast.latitude_deg,
        motion=forecast.motion,
        amplitude_cm=forecast.amplitude_cm,
    )


def settings_from_plan(plan: Plan | PartialPlan) -> AnalysisSettings:
    """The analysis settings of a parsed plan; a partial plan without [analysis] or [forecast]
    takes those from `SEED_000_SETTINGS` (see `fallback_notes`)."""
    instrument, site = plan.instrument, plan.site
    constants = KnownConstants(
        lP_gcm2s2=instrument.lp_gcm2s2,
        H1_gcm2s=instrument.h1_gcm2s,
        earth_rate_rad_s=site.earth_rate_rad_s,
        gravity_cm_s2=site.gravity_cm_s2,
        latitude_deg=site.latitude_deg,
    )
    fallback = SEED_000_SETTINGS
    analysis = plan.analysis
    return AnalysisSettings(
        constants=constants,
        q=fallback.q if analysis is None else analysis.q,
        start=fallback.start if analysis is None else (analysis.start_c, analysis.start_t_s),
        admissible=fallback.admissible if analysis is None else _admissible(analysis),
        forecast=fallback.forecast if plan.forecast is None else _ship(plan.forecast),
    )


def fallback_notes(plan: Plan | PartialPlan, source: str = "The stored plan") -> tuple[str, ...]:
    """What `settings_from_plan` took from the example of Potemkin (1982), one sentence each."""
    notes = []
    if plan.analysis is None:
        notes.append(
            f"{source} has no [analysis] table: q, the start values and the admissible region "
            "of the example of Potemkin (1982) were used."
        )
    if plan.forecast is None:
        notes.append(
            f"{source} has no [forecast] table: the ship conditions of the example of "
            "Potemkin (1982) were forecast."
        )
    return tuple(notes)
