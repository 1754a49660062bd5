"""A CiA 402 stand rolls about one axis: the plan asks the operator to set K by hand before
the first trial and each trial whose K differs from the one before."""

from __future__ import annotations

from gyrostand.cmd_plan import summary
from gyrostand.plan.model import parse_plan
from tests.acquisition.harness import plan_text

STAND = """
[stand]
protocol = "cia402"
eds = "drive.eds"
node_id = 5
counts_per_degree = 10000
arm_length_cm = 750

[compass]
protocol = "nmea2000"
"""
TRIALS = [
    (45.0, 24.0, 6.0, "fit"),
    (45.0, 20.0, 5.0, "fit"),
    (135.0, 16.0, 8.0, "fit"),
    (45.0, 16.0, 8.0, "control"),
]


def test_a_prompt_before_each_trial_whose_k_differs():
    plan = parse_plan(plan_text(TRIALS) + STAND)
    assert [(p.id, p.before, p.kind) for p in plan.prompt] == [
        ("k_trial1", 1, "confirm"),
        ("k_trial3", 3, "confirm"),
        ("k_trial4", 4, "confirm"),
    ]
    assert plan.prompt[1].text == (
        "turn the compass on the platform to K = 135 deg (the direction of roll) and confirm"
    )
    assert plan.prompts_before(2) == ()
    assert "CiA 402 drive node 5 (K set by hand: 3 prompts)" in summary(plan)


def test_a_gyrostand_stand_sets_k_itself():
    plan = parse_plan(plan_text(TRIALS))
    assert plan.prompt == () and "CiA 402" not in summary(plan)
