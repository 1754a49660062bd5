"""analyze_campaign on simulated campaigns with raw readings, and its typed errors (section 8)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import f as f_distribution

from gyrostand.analysis import paper_example as paper
from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.csv_input import read_trials_csv
from gyrostand.analysis.errors import (
    AnalysisError,
    MissingDataError,
    NonFiniteError,
    SingularDesignError,
    TooFewObservationsError,
    TooFewTrialsError,
    UnequalDegreesOfFreedomError,
    ZeroVarianceError,
)
from gyrostand.analysis.gyro_model import Conditions, RollingErrorModel
from gyrostand.analysis.synthetic import Design, synthetic_trials
from gyrostand.analysis.trials import TrialInput

CSV = Path(__file__).resolve().parents[2] / "examples" / "paper.csv"
TRUE = {"C_gcm2s2": 6e7, "T_s": 1.15}
DESIGN = Design(
    direction_deg=np.array([30, 60, 120, 150, 30, 60, 120, 150, 45, 135]),
    amplitude_cm=np.array([20, 24, 22, 18, 24, 20, 18, 22, 21, 23]),
    period_s=np.array([3.5, 4.5, 5.5, 6.5, 8.0, 3.5, 4.5, 5.5, 6.0, 7.0]),
)
ROLES = ["fit"] * 8 + ["control"] * 2


def simulated(seed: int, sigma_deg: float = 0.01, n_obs: int = 8) -> list[TrialInput]:
    rng = np.random.default_rng(seed)
    return synthetic_trials(
        paper.CONSTANTS, DESIGN, ROLES, **TRUE, sigma_deg=sigma_deg, n_obs=n_obs, rng=rng
    )


def paper_trials(**changes: object) -> list[TrialInput]:
    """The paper's per-trial table, with fields of trial 2 replaced."""
    trials = read_trials_csv(CSV)
    return [TrialInput(**{**t.__dict__, **changes}) if t.index == 2 else t for t in trials]


def test_simulated_campaign_recovers_c_and_t() -> None:
    a = analyze_campaign(simulated(11), paper.CONSTANTS, start=paper.START)
    for name, true in TRUE.items():
        assert abs(a.fit.estimates[name] - true) < 4 * a.fit.std_errors[name]
    assert a.cochran.nu == 14 and a.cochran.k == 8
    assert [c.index for c in a.controls] == [9, 10]
    assert all(c.within_interval for c in a.controls)
    normality, independence, homogeneity = a.assumptions
    assert normality.holds is not None and len(normality.series) == 20
    assert independence.holds is not None and len(independence.series) == 20
    assert homogeneity.holds == a.cochran.homogeneous


def test_far_start_is_rescued_by_the_trust_region() -> None:
    trials = read_trials_csv(CSV)
    a = analyze_campaign(trials, paper.CONSTANTS, start=(1e9, 5.0))
    assert a.fit.path == "trust-region"
    assert "left the bounds" in a.fit.fallback_reason
    assert a.fit.estimates["T_s"] == pytest.approx(1.151, abs=5e-4)
    assert any("Gauss-Newton failed" in w for w in a.warnings)


def test_inhomogeneous_variances_block_the_adequacy_verdict() -> None:
    a = analyze_campaign(paper_trials(delta_var_deg2=40e-4), paper.CONSTANTS)
    assert not a.cochran.homogeneous and a.cochran.largest == 2
    assert a.adequacy.adequate is None and a.adequacy.adequate_mean_basis is None
    assert any("trial 2" in w and "not homogeneous" in w for w in a.warnings)


def test_too_few_trials() -> None:
    trials = read_trials_csv(CSV)
    few = [t for t in trials if t.index in (1, 2, 5)]
    with pytest.raises(TooFewTrialsError, match="2 fit trials for 2 parameters"):
        analyze_campaign(few, paper.CONSTANTS)


def test_n_below_two() -> None:
    with pytest.raises(TooFewObservationsError, match="trial 2"):
        paper_trials(n_obs=1)


def test_one_period_is_singular() -> None:
    trials = [TrialInput(**{**t.__dict__, "period_s": 6.0}) for t in paper_trials()]
    with pytest.raises(SingularDesignError, match="one period"):
        analyze_campaign(trials, paper.CONSTANTS)


def test_sin_2k_zero_is_singular() -> None:
    trials = [TrialInput(**{**t.__dict__, "direction_deg": 90.0 * t.index}) for t in paper_trials()]
    with pytest.raises(SingularDesignError, match="sin 2K = 0"):
        analyze_campaign(trials, paper.CONSTANTS)


def test_zero_variance_names_the_trial() -> None:
    with pytest.raises(ZeroVarianceError, match="trial 2"):
        analyze_campaign(paper_trials(delta_var_deg2=0.0), paper.CONSTANTS)


def test_non_finite_input() -> None:
    with pytest.raises(NonFiniteError, match="trial 2: delta_mean_deg"):
        paper_trials(delta_mean_deg=float("inf"))


def test_unequal_dof_for_cochran() -> None:
    with pytest.raises(UnequalDegreesOfFreedomError, match="trial 2 has 12"):
        analyze_campaign(paper_trials(n_obs=7), paper.CONSTANTS)


def test_fit_trial_without_variance() -> None:
    with pytest.raises(MissingDataError, match="trial 2"):
        analyze_campaign(paper_trials(delta_var_deg2=None, n_obs=None), paper.CONSTANTS)


def test_bad_settings() -> None:
    trials = paper_trials()
    with pytest.raises(AnalysisError, match="T > 0"):
        analyze_campaign(trials, paper.CONSTANTS, start=(7e7, 0.0))
    with pytest.raises(AnalysisError, match="q = 0"):
        analyze_campaign(trials, paper.CONSTANTS, q=0.0)
    with pytest.raises(AnalysisError, match="appears more than once"):
        analyze_campaign(trials + trials[:1], paper.CONSTANTS)


def test_errors_share_one_root() -> None:
    for error in (
        MissingDataError,
        NonFiniteError,
        SingularDesignError,
        TooFewObservationsError,
        TooFewTrialsError,
        UnequalDegreesOfFreedomError,
        ZeroVarianceError,
    ):
        assert issubclass(error, AnalysisError)


def test_residual_variance_implausibly_small_is_warned() -> None:
    """Trial means placed on the model (S^2_r ~ 0) while every observation keeps its noise: the
    lower tail of F = S^2_r / (S^2_e/N) flags that the two estimates of error disagree."""
    model = RollingErrorModel(paper.CONSTANTS)
    trials = []
    for t in simulated(11, sigma_deg=0.05):
        alpha = float(model(_conditions_of(t), **TRUE)[0])
        under = np.array(t.under_deg)
        shift = alpha - (under.mean() - np.mean(t.before_deg))  # <delta_i> = alpha_i exactly
        trials.append(replace(t, under_deg=tuple(under + shift)))
    a = analyze_campaign(trials, paper.CONSTANTS, start=paper.START)
    var_means = [s.var_mean_deg2 for s in a.trials if s.role == "fit"]
    ratio = a.fit.s2 / np.mean(var_means)
    assert ratio < 1e-6
    p_low = f_distribution.cdf(ratio, a.fit.dof, a.adequacy.dof_e)
    assert a.error_agreement.p_low == pytest.approx(p_low, rel=1e-6)
    assert a.error_agreement.too_small and a.error_agreement.dof_r == 6
    assert any("implausibly small" in w and "t(6)" in w for w in a.warnings)
    plain = analyze_campaign(simulated(11, sigma_deg=0.05), paper.CONSTANTS, start=paper.START)
    assert plain.error_agreement.p_low > 0.05 and not plain.error_agreement.too_small
    assert not any("implausibly small" in w for w in plain.warnings)


def _conditions_of(t: TrialInput) -> Conditions:
    return Conditions(
        np.array([t.direction_deg]), np.array([t.amplitude_cm]), np.array([t.period_s])
    )
