"""The measurement/type split of the within-group variance (analysis/fleet.py) against a Monte
Carlo simulation of a fleet whose type scatter and measurement errors are known: unbiased when
the units' SEs are right, even with unequal groups of unequal precision; biased by the SEs'
shortfall when they understate the error."""

import numpy as np
import pytest

from gyrostand.analysis.fleet import one_way_anova

SIZES = (2, 3, 7)  # N = 12 units, k = 3 groups, N - k = 9
SIGMA_TYPE = 1.0
SIGMA_MEASUREMENT = (3.0, 0.5, 0.5)  # the small group measured far less precisely


def mean_split(se_fraction: float, runs: int = 3000) -> tuple[float, float, float]:
    """Over `runs` simulated fleets (true values: the type's normal scatter; estimates: the true
    value plus a normal measurement error; SEs = se_fraction × the error's true SD): the mean
    of S²_within - measurement share (unfloored), the mean of the type's SD reported and the
    fraction of the fleets whose 95 % interval of the type's variance holds the true one."""
    rng = np.random.default_rng(7)
    type_variance, type_sd, covered = [], [], 0
    for _ in range(runs):
        groups, ses = [], []
        for n, sigma in zip(SIZES, SIGMA_MEASUREMENT, strict=True):
            truth = 5.0 + SIGMA_TYPE * rng.standard_normal(n)
            groups.append(truth + sigma * rng.standard_normal(n))
            ses.append(np.full(n, se_fraction * sigma))
        anova = one_way_anova(groups, ses, 0.05)
        type_variance.append(anova.s2_within - anova.s2_measurement)
        type_sd.append(anova.s2_type**0.5)
        low, high = anova.s2_type_interval
        covered += low <= SIGMA_TYPE**2 <= high
    return float(np.mean(type_variance)), float(np.mean(type_sd)), covered / runs


# the weighted measurement share: Σ (1 - 1/n_j) n_j σ_j² / (N - k)
SHARE = sum((n - 1) * s**2 for n, s in zip(SIZES, SIGMA_MEASUREMENT, strict=True)) / 9  # 11/9


def test_the_type_variance_is_unbiased_when_the_ses_are_right() -> None:
    variance, sd, coverage = mean_split(1.0)
    # the simulation's standard error of the mean is about 0.02: 4 of them
    assert variance == pytest.approx(SIGMA_TYPE**2, abs=0.08)
    # the plain mean of SE² (20.5 / 12 = 1.708, not SHARE = 11 / 9 = 1.222) would give 0.51
    # the SD (square root, floored at 0) is biased low: Jensen, and the floor
    assert 0.5 < sd < SIGMA_TYPE
    # the interval's coverage: 95 % less what the measurement share's own scatter would add
    # (none here: the SEs are exact), with Satterthwaite's degrees of freedom (about 3.6 here, not
    # N - k = 9: the 9 dof interval covers 85 %); binomial SE of 3000 runs 0.4 %
    assert coverage == pytest.approx(0.95, abs=0.025)


def test_ses_that_understate_the_error_move_their_shortfall_into_the_type() -> None:
    variance, _, coverage = mean_split(1 / 1.5)  # SEs 1.5 times too small
    expected = SIGMA_TYPE**2 + (1 - 1 / 1.5**2) * SHARE  # the stated bias
    assert variance == pytest.approx(expected, abs=0.08)
    assert variance > SIGMA_TYPE**2 + 0.5
    assert coverage < 0.9


def test_fleet_simulate_checks_the_split_against_the_truth() -> None:
    """`fleet simulate`'s check: each unit's actual error against its SE, by hand."""
    from gyrostand.analysis.fleet import FleetUnit, analyze_fleet
    from gyrostand.simulated_fleet import FleetDesign, SimulatedUnit, split_check

    truth = [(6.0e7, 1.10), (6.2e7, 1.08), (5.9e7, 1.12), (6.1e7, 1.11), (6.0e7, 1.09)]
    errors = [(0.02, 0.01), (-0.01, -0.02), (0.03, 0.0), (-0.02, 0.01), (0.0, -0.01)]
    made, units = [], []
    for i, ((c, t), (ec, et)) in enumerate(zip(truth, errors, strict=True), start=1):
        made.append(SimulatedUnit(i, f"U{i}", "AB"[i % 2], c, t))
        units.append(FleetUnit(i, f"U{i}", "AB"[i % 2], c * (1 + ec), 0.01 * c, t + et, 0.01))
    analysis = analyze_fleet(units, factor="lot")
    c, t = split_check(made, units, analysis, FleetDesign())
    assert c.rms_error == pytest.approx(np.sqrt(np.mean(np.square([e[0] for e in errors]))))
    assert t.rms_error == pytest.approx(np.sqrt(np.mean(np.square([e[1] for e in errors]))))
    assert c.rms_se == pytest.approx(0.01) and t.rms_se == pytest.approx(0.01)
    a = analysis.parameters[0].anova
    assert c.type_sd == pytest.approx(a.s2_type**0.5 / a.grand_mean)
    assert (c.drawn_sd, t.drawn_sd) == (0.03, 0.03)
    expected = "  T: actual errors RMS 0.0118 s against the fits' SEs RMS 0.01 s (ratio 1.18)"
    assert t.line().startswith(expected)
