"""A stored campaign's plan as the reports read it: the whole plan (None for a partial or
unreadable one) and whether the campaign ran on the simulated stand. Apart from `report.stored`
so that the fleet report, which asks only the latter, does not import the stand report's
analysis and signal modules (a fifth of its CPU)."""

from gyrostand.db.models import Campaign
from gyrostand.plan.model import PartialPlan, Plan, PlanError, parse_any_plan


def whole_plan(campaign: Campaign) -> Plan | None:
    """The stored plan when it is a whole one (an import may store the partial form)."""
    try:
        plan = parse_any_plan(campaign.plan_toml)
    except PlanError:
        return None
    return plan if isinstance(plan, Plan) else None


def is_simulated(campaign: Campaign, plan: Plan | PartialPlan | None = None) -> bool:
    """The campaign ran on the simulated stand (its stored plan, parsed unless given, says so;
    an import never did)."""
    if plan is None:
        plan = whole_plan(campaign)
    return campaign.source != "import" and isinstance(plan, Plan) and plan.bus.simulated
