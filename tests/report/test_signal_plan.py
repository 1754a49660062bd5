"""The plan's optional [acceptance] table (acceptance by excursions, seed 004 eqs 8.79-8.88)."""

import pytest

from gyrostand.plan.model import AcceptancePlan, PlanError, parse_plan
from tests.acquisition.harness import plan_text


def test_acceptance_table_is_optional_and_read_when_given() -> None:
    assert parse_plan(plan_text()).acceptance is None
    text = plan_text() + "\n[acceptance]\ntolerance_deg = 0.05\nduration_s = 600\nmax_risk = 0.01\n"
    assert parse_plan(text).acceptance == AcceptancePlan(
        tolerance_deg=0.05, duration_s=600.0, max_risk=0.01
    )


def test_every_acceptance_problem_is_reported() -> None:
    text = plan_text() + "\n[acceptance]\ntolerance_deg = -1\nmax_risk = 1.5\nrisk = 0.1\n"
    with pytest.raises(PlanError) as caught:
        parse_plan(text)
    assert caught.value.problems == [
        "[acceptance] tolerance_deg: must be > 0",
        "[acceptance] duration_s: missing",
        "[acceptance] max_risk: must be < 1",
        "[acceptance] risk: unknown key",
    ]
