"""A plan 10 % short on the period, on the lockstep simulated stand (the compass scaled to a
1200 s period, as in test_early_settle; ~10 s on a loaded machine, so in the slow stage): with
the plan at 1080 s the compensated criterion told nothing and left 0.03-0.04 deg in the series
means before; now a "plan contradicted" event comes at trial 2's first series and the compensated
series' means lie within their SE (+ the noise) of the truth."""

import math

import numpy as np
import pytest

from gyrostand.analysis.transient import PLAN_CONTRADICTED

from .test_early_settle import COMPENSATED_SETTLE, SCALED_T0_S, errors_deg, run, scaled_config


@pytest.mark.parametrize("factor", [0.9])
def test_the_compensated_criterion_uses_the_record_s_period(factor: float) -> None:
    settle = COMPENSATED_SETTLE.replace(
        f"undamped_period_s = {SCALED_T0_S}", f"undamped_period_s = {factor * SCALED_T0_S:g}"
    )
    sink, _, _ = run(settle, scaled_config())
    told = [a for a in sink.of("event") if a[0] == PLAN_CONTRADICTED]
    assert [(a[1], a[3], a[4]) for a in told] == [("warning", 2, 1)]
    assert f"vs the plan's {factor * SCALED_T0_S:g} s" in told[0][2]
    errors = errors_deg(sink, scaled_config())
    done = {(a[0], a[1]): a[2] for a in sink.of("series_completed")}
    for key in ((2, 1), (2, 2)):  # compensated with the record's period
        comp = done[key]
        assert comp is not None
        assert abs(errors[key]) < 3 * comp.standard_error_deg + 0.004  # its SE + the noise


def test_a_damping_the_record_does_not_yet_contradict_is_not_trusted() -> None:
    """The plan's damping ratio 0.05 high or low, seeds 1-8 (the record contradicts it in some
    runs only, and late): each compensated series mean against the truth in units of its SE
    (the compensation's, with the period and damping the record gives, and the observations'
    scatter). RMS z 1.23 over the 32 series; with the plan's damping kept until contradicted
    and the period and damping's uncertainty left out of the SE it was 1.91 (max |z| 4.4)."""
    z = []
    for ratio in (0.65, 0.75):
        settle = COMPENSATED_SETTLE.replace("damping_ratio = 0.7", f"damping_ratio = {ratio}")
        for seed in range(1, 9):
            sink, _, _ = run(settle, scaled_config(seed))
            errors = errors_deg(sink, scaled_config(seed))
            values: dict[tuple[int, int], list[float]] = {}
            for o in sink.observations:
                values.setdefault((o.trial, o.j), []).append(o.value_deg)
            for trial, j, comp, *_ in sink.of("series_completed"):
                if comp is None:
                    continue
                left = np.array(values[(trial, j)]) - np.array(comp.transient_deg)
                se = math.hypot(comp.standard_error_deg, left.std(ddof=1) / math.sqrt(left.size))
                z.append(errors[(trial, j)] / se)
    assert len(z) == 32
    assert math.sqrt(np.mean(np.square(z))) < 1.5
