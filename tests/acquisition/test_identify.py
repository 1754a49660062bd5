"""The compass's period and damping identified from the record while the campaign runs
(`acquisition.early_settle.identify`): a plan 10 % short on the period is contradicted by the
record, said in a "plan contradicted" event, and the settle criteria use the record's values.

- On exact block means of the damped transient (seed 003 eq 2) with fixed-seed noise: the free
  fit finds the true period within its SE, contradicts a plan 10 % short and confirms a right one.

On the simulated stand: test_identify_campaign.py.
"""

import numpy as np

from gyrostand.acquisition.early_settle import TransientRecord, identify
from gyrostand.plan.model import EstimatePlan

from .test_early_settle import T0_S, ZETA, block_mean_deg

WINDOW_S, NOISE_DEG = 60.0, 0.004  # a 60 s window mean of the simulated compass: ~0.004 deg


def record_of(span_s: float, seed: int = 3) -> TransientRecord:
    """Window means after one step of the equilibrium, with white noise of a window mean."""
    rng = np.random.default_rng(seed)
    record = TransientRecord()
    record.step(0.0)
    for k in range(int(span_s // WINDOW_S)):
        start, end = k * WINDOW_S, (k + 1) * WINDOW_S
        record.add(start, end, block_mean_deg(start, end) + NOISE_DEG * rng.standard_normal())
    return record


def plan_with(period_s: float) -> EstimatePlan:
    return EstimatePlan(period_s, ZETA, 0.015, 0.5, 3, 0.05, compensated=True)


def test_a_plan_period_10_percent_short_is_contradicted_and_a_right_one_confirmed() -> None:
    record = record_of(2 * T0_S)
    short = identify(record, plan_with(0.9 * T0_S))
    assert short is not None and short.contradicted
    assert abs(short.undamped_period_s - T0_S) < 3 * short.period_se_s
    assert abs(short.damping_ratio - ZETA) < 3 * short.damping_ratio_se
    assert short.period_se_s < 0.03 * T0_S  # 10 % is > 3 SE away
    applied = short.applied(plan_with(0.9 * T0_S))
    assert applied.undamped_period_s == short.undamped_period_s and applied.compensated
    assert "the record contradicts the plan: period" in short.describe(plan_with(0.9 * T0_S))
    right = identify(record, plan_with(T0_S))
    assert right is not None and not right.contradicted
    assert right.applied(plan_with(T0_S)) == plan_with(T0_S)


def test_a_record_shorter_than_a_period_identifies_nothing() -> None:
    assert identify(record_of(0.8 * T0_S), plan_with(0.9 * T0_S)) is None
