"""Fleet statistics (analysis/fleet.py) against independent computations: scipy's f_oneway and
ks_2samp, a hand-computed analysis of variance and prediction interval."""

import math

import numpy as np
import pytest
from scipy import stats

from gyrostand.analysis.fleet import FleetError, FleetUnit, analyze_fleet

T_BY_GROUP = {"A": [1.10, 1.05, 1.12, 1.08], "B": [1.02, 1.09, 1.04], "C": [1.30, 1.26, 1.33]}


def fleet(t_by_group: dict[str, list[float]] = T_BY_GROUP) -> list[FleetUnit]:
    units, i = [], 0
    for group, values in t_by_group.items():
        for t in values:
            i += 1
            c = 6e7 * (1 + 0.01 * ((i * 7) % 5 - 2))  # C: no group effect
            units.append(FleetUnit(i, f"S{i}", group, c, 2e6, t, 0.02 + 0.001 * i))
    return units


def test_anova_equals_scipy_and_a_hand_computation() -> None:
    result = analyze_fleet(fleet(), factor="factory")
    c, t = result.parameters
    assert (c.symbol, t.symbol) == ("C", "T")
    expected = stats.f_oneway(*(np.array(v) for v in T_BY_GROUP.values()))
    assert t.anova.f == pytest.approx(expected.statistic, rel=1e-12)
    assert t.anova.p_value == pytest.approx(expected.pvalue, rel=1e-9)
    # by hand: 10 units, 3 groups
    means = {g: sum(v) / len(v) for g, v in T_BY_GROUP.items()}
    grand = sum(sum(v) for v in T_BY_GROUP.values()) / 10
    q1 = sum(len(v) * (means[g] - grand) ** 2 for g, v in T_BY_GROUP.items())
    q2 = sum((x - means[g]) ** 2 for g, v in T_BY_GROUP.items() for x in v)
    assert (t.anova.dof_between, t.anova.dof_within) == (2, 7)
    assert t.anova.q_between == pytest.approx(q1) and t.anova.q_within == pytest.approx(q2)
    assert t.anova.f == pytest.approx((q1 / 2) / (q2 / 7))
    assert t.anova.f_critical == pytest.approx(4.737, abs=1e-3)  # F table, 0.95; 2, 7
    assert t.anova.groups_differ and not c.anova.groups_differ
    assert t.anova.verdict.endswith("the groups differ")
    ses = [0.02 + 0.001 * i for i in range(1, 11)]
    sizes = [4] * 4 + [3] * 6  # each unit's group size: A, then B and C
    share = sum((1 - 1 / n) * se**2 for n, se in zip(sizes, ses, strict=True)) / 7  # E[Q2]/(N-k)
    assert t.anova.s2_measurement == pytest.approx(share)
    assert t.anova.s2_type == pytest.approx(max(0.0, q2 / 7 - share))


def test_smirnov_each_group_against_the_rest() -> None:
    t = analyze_fleet(fleet(), factor="factory").parameters[1]
    for test in t.smirnov:
        rest = [x for g, v in T_BY_GROUP.items() if g != test.group for x in v]
        expected = stats.ks_2samp(T_BY_GROUP[test.group], rest)
        assert (test.statistic, test.p_value) == pytest.approx(
            (expected.statistic, expected.pvalue)
        )
        assert test.q_each == pytest.approx(0.05 / 3)
    assert [s.statistic for s in t.smirnov if s.group == "C"] == [1.0]


def test_prediction_interval_leaves_the_unit_out() -> None:
    units = fleet({"A": [1.1, 1.12, 1.09, 1.11, 1.10], "B": [1.08, 1.11, 1.6]})
    t = analyze_fleet(units, factor="lot").parameters[1]
    assert [u.serial for u in t.outliers] == ["S8"]
    others = np.array([1.1, 1.12, 1.09, 1.11, 1.10, 1.08, 1.11])
    check = t.units[-1]
    scale = others.std(ddof=1) * math.sqrt(1 + 1 / 7)
    assert check.center == pytest.approx(others.mean())
    assert check.half_width == pytest.approx(stats.t.ppf(1 - 0.05 / 8 / 2, 6) * scale)
    assert check.t_statistic == pytest.approx((1.6 - others.mean()) / scale)


def test_json_has_every_verdict() -> None:
    document = analyze_fleet(fleet(), factor="factory").to_dict()
    t = document["parameters"][1]
    assert document["factor"] == "factory" and document["n_units"] == 10
    assert t["anova"]["verdict"].startswith("F = ")
    assert {s["group"] for s in t["smirnov"]} == {"A", "B", "C"}
    assert len(t["units"]) == 10 and "outside" in t["units"][0]


@pytest.mark.parametrize(
    ("units", "message"),
    [
        (fleet({"A": [1.0, 1.1, 1.2]}), "the fleet has 1 group by factory: at least 2"),
        (fleet({"A": [1.0, 1.1], "B": [1.2]}), "3 units in 2 groups by factory"),
    ],
)
def test_unusable_fleets_are_refused_in_one_line(units: list[FleetUnit], message: str) -> None:
    with pytest.raises(FleetError, match=message):
        analyze_fleet(units, factor="factory")


def test_a_unit_without_a_standard_error_is_refused() -> None:
    units = fleet()
    units[0] = FleetUnit(1, "S1", "A", 6e7, math.nan, 1.1, 0.02)
    with pytest.raises(FleetError, match=r"campaign 1 \(serial S1\): C = 60000000.0 ± nan"):
        analyze_fleet(units, factor="factory")


def test_each_group_against_the_rest_names_the_shifted_one() -> None:
    t = analyze_fleet(fleet(), factor="factory").parameters[1]
    assert [g.group for g in t.groups if g.differs] == ["C"]
    s2_within = t.anova.s2_within
    rest = T_BY_GROUP["A"] + T_BY_GROUP["B"]
    expected = (np.mean(T_BY_GROUP["C"]) - np.mean(rest)) / math.sqrt(s2_within * (1 / 3 + 1 / 7))
    (c,) = [g for g in t.groups if g.group == "C"]
    assert c.t_vs_rest == pytest.approx(expected)
    # step down: C set apart; A and B alone do not differ (F with the fleet's S² within)
    a, b = np.array(T_BY_GROUP["A"]), np.array(T_BY_GROUP["B"])
    grand = np.concatenate([a, b]).mean()
    f = (4 * (a.mean() - grand) ** 2 + 3 * (b.mean() - grand) ** 2) / s2_within
    assert f < stats.f.ppf(0.95, 1, 7)


def test_two_groups_that_differ_are_both_set_apart() -> None:
    """Two groups that differ from each other do not tell which one is odd: both are named,
    whichever is listed first (the F test of the two is the square of their t)."""
    t_by_group = {"A": T_BY_GROUP["A"], "C": T_BY_GROUP["C"]}
    for order in (t_by_group, dict(reversed(t_by_group.items()))):
        t = analyze_fleet(fleet(order), factor="factory").parameters[1]
        assert t.anova.groups_differ
        assert sorted(g.group for g in t.groups if g.differs) == ["A", "C"]
        a, c = (g.t_vs_rest for g in sorted(t.groups, key=lambda g: g.group))
        assert a == pytest.approx(-c)
        assert t.anova.f == pytest.approx(a**2)
    same = {"A": T_BY_GROUP["A"], "B": T_BY_GROUP["B"]}
    assert not any(g.differs for g in analyze_fleet(fleet(same), factor="f").parameters[1].groups)
