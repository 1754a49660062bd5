"""Trial statistics (eqs 2.1-2.4) in all three input forms, against direct numpy/pandas sums."""

import math

import numpy as np
import pandas as pd
import pytest

from gyrostand.analysis.errors import (
    AnalysisError,
    MissingDataError,
    NonFiniteError,
    TooFewObservationsError,
)
from gyrostand.analysis.trials import (
    SeriesSummary,
    TrialInput,
    TrialStats,
    difference_statistics,
    trial_statistics,
)

BEFORE = (0.512, 0.498, 0.505, 0.521, 0.493)
UNDER = (0.301, 0.322, 0.287, 0.310, 0.296, 0.318, 0.305)  # N2 = 7 != N1 = 5


def trial(**form: object) -> TrialInput:
    return TrialInput(index=7, role="fit", direction_deg=30, amplitude_cm=20, period_s=6, **form)


def test_raw_observations_with_unequal_n() -> None:
    s = trial_statistics(trial(before_deg=BEFORE, under_deg=UNDER))
    b, u = pd.Series(BEFORE), pd.Series(UNDER)
    assert s.delta_deg == pytest.approx(u.mean() - b.mean())
    assert s.var_deg2 == pytest.approx(b.var() + u.var())  # eq 2.3 (pandas var is N-1)
    assert s.var_mean_deg2 == pytest.approx(b.var() / 5 + u.var() / 7)
    assert s.dof == 5 + 7 - 2  # eq 2.4
    assert (s.n_before, s.n_under, s.source) == (5, 7, "observations")
    assert s.under.var_deg2 == pytest.approx(u.var())


def test_series_summaries_give_the_same_result() -> None:
    raw = trial_statistics(trial(before_deg=BEFORE, under_deg=UNDER))
    summarised = trial_statistics(trial(before=raw.before, under=raw.under))
    for field in ("delta_deg", "var_deg2", "var_mean_deg2", "dof"):
        assert getattr(summarised, field) == pytest.approx(getattr(raw, field))
    assert summarised.source == "series"


def test_paper_form_divides_by_n_for_the_mean() -> None:
    s = trial_statistics(trial(delta_mean_deg=0.21, delta_var_deg2=4.64e-4, n_obs=5))
    assert (s.var_deg2, s.dof) == (4.64e-4, 8)
    assert s.var_mean_deg2 == pytest.approx(4.64e-4 / 5)


def test_vectorised_core_matches_per_trial() -> None:
    rng = np.random.default_rng(3)
    before, under = rng.normal(0, 0.01, (6, 5)), rng.normal(0.2, 0.02, (6, 9))
    d = difference_statistics(before, under)
    for i in range(6):
        s = trial_statistics(trial(before_deg=before[i], under_deg=under[i]))
        assert d.delta_deg[i] == pytest.approx(s.delta_deg)
        assert d.var_deg2[i] == pytest.approx(s.var_deg2)
    assert np.all(d.dof == 12)


def test_headings_across_north_differ_by_their_small_angle() -> None:
    """Readings 359.9 deg before and 0.1 deg under rocking differ by +0.2 deg, not -359.8 deg,
    in every input form; a series that itself crosses north has the mean of its readings."""
    before = SeriesSummary(359.9, 1e-4, 5)
    under = SeriesSummary(0.1, 1e-4, 5)
    assert trial_statistics(trial(before=before, under=under)).delta_deg == pytest.approx(0.2)
    raw = trial_statistics(
        trial(before_deg=(359.98, 0.02, 359.99, 0.01), under_deg=(0.21, 0.19, 0.2, 0.2))
    )
    assert raw.delta_deg == pytest.approx(0.2)
    assert raw.before.mean_deg % 360.0 == pytest.approx(0.0, abs=1e-12)
    assert raw.before.var_deg2 == pytest.approx(np.var([-0.02, 0.02, -0.01, 0.01], ddof=1))
    d = difference_statistics(np.array([[359.9, 359.9]]), np.array([[0.1, 0.1]]))
    assert d.delta_deg == pytest.approx([0.2])


def test_bad_trials_name_the_trial() -> None:
    with pytest.raises(TooFewObservationsError, match="trial 7, before_deg: N = 1"):
        trial(before_deg=(0.5,), under_deg=UNDER)
    with pytest.raises(TooFewObservationsError, match="n_obs: N = 1"):
        trial(delta_mean_deg=0.1, delta_var_deg2=1e-4, n_obs=1)
    with pytest.raises(NonFiniteError, match=r"trial 7: under_deg\[2\]"):
        trial(before_deg=BEFORE, under_deg=(0.3, 0.3, float("nan")))
    with pytest.raises(NonFiniteError, match="period_s"):
        TrialInput(7, "fit", 30, 20, float("inf"), delta_mean_deg=0.1)
    with pytest.raises(MissingDataError, match="exactly one"):
        trial(before_deg=BEFORE, under_deg=UNDER, delta_mean_deg=0.1)
    with pytest.raises(MissingDataError, match="under"):
        trial(before=SeriesSummary(0.5, 1e-4, 5))
    with pytest.raises(AnalysisError, match="role 'fitted'"):
        TrialInput(7, "fitted", 30, 20, 6, delta_mean_deg=0.1)
    with pytest.raises(AnalysisError, match="negative"):
        trial(delta_mean_deg=0.1, delta_var_deg2=-1e-4, n_obs=5)


def test_the_dof_of_a_compensated_trials_mean_variance() -> None:
    """`TrialStats.mean_dof`: eq 2.4 for two plain series; Welch-Satterthwaite with a
    compensated series' variance known, nu (V / P)^2; infinite with both compensated (their
    variances come from fits of the whole record, issue 34)."""

    def stats(before_own: float | None, under_own: float | None) -> TrialStats:
        return trial_statistics(
            trial(
                before=SeriesSummary(0.0, 0.0005, 5, var_mean_deg2=before_own),
                under=SeriesSummary(0.1, 0.0005, 5, var_mean_deg2=under_own),
            )
        )

    plain = stats(None, None)
    assert plain.mean_dof == plain.dof == 8
    one = stats(None, 0.0003)  # S^2/N = 0.0001 estimated with 4 dof, 0.0003 known
    assert one.own_variance == pytest.approx((0.0001, 4.0))
    assert one.mean_dof == pytest.approx(4.0 * (0.0004 / 0.0001) ** 2)
    assert math.isinf(stats(0.0002, 0.0003).mean_dof)
