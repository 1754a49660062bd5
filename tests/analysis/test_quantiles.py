"""analysis.quantiles: the t, F and chi-square quantiles and F tail by scipy.special equal
scipy.stats' (the report's values are the ones the analysis used)."""

import pytest
from scipy import stats

from gyrostand.analysis.quantiles import chi2_quantile, f_quantile, f_sf, t_quantile


@pytest.mark.parametrize("dof", [1, 2, 3.5, 8, 16, 1000])
@pytest.mark.parametrize("p", [0.5, 0.95, 0.975, 0.025])
def test_t_quantile_is_scipy_stats_t_ppf(p: float, dof: float) -> None:
    assert t_quantile(p, dof) == float(stats.t.ppf(p, dof))


def test_the_t_table_is_scipy_special_stdtrit() -> None:
    """analysis.t_table, which spares a report scipy's import: every entry is stdtrit's."""
    from scipy.special import stdtrit

    from gyrostand.analysis.t_table import T_DOF_MAX, T_QUANTILES

    assert set(T_QUANTILES) == {0.005, 0.025, 0.05, 0.95, 0.975, 0.995}
    for p, row in T_QUANTILES.items():
        assert len(row) == T_DOF_MAX
        for dof in range(1, T_DOF_MAX + 1):
            assert row[dof - 1] == float(stdtrit(dof, p)) == t_quantile(p, dof), (p, dof)
    assert 1 - 0.05 / 2 in T_QUANTILES and 0.5 + 0.95 / 2 in T_QUANTILES  # as the code asks


def test_the_textbook_value() -> None:
    assert t_quantile(0.975, 8) == pytest.approx(2.306004, abs=1e-6)  # t(0.975; 8), tables


@pytest.mark.parametrize(("dof_num", "dof_den"), [(1, 1), (1, 16), (2, 5), (3, 40), (7.5, 2.2)])
@pytest.mark.parametrize("p", [0.01, 0.5, 0.95, 0.999])
def test_f_quantile_and_tail_are_scipy_stats_f(p: float, dof_num: float, dof_den: float) -> None:
    x = f_quantile(p, dof_num, dof_den)
    assert x == float(stats.f.ppf(p, dof_num, dof_den))
    assert f_sf(x, dof_num, dof_den) == float(stats.f.sf(x, dof_num, dof_den))
    assert f_sf(x, dof_num, dof_den) == pytest.approx(1 - p, rel=1e-9)


@pytest.mark.parametrize("dof", [1, 2, 3.7, 16, 250])
@pytest.mark.parametrize("p", [0.025, 0.5, 0.975])
def test_chi2_quantile_is_scipy_stats_chi2_ppf(p: float, dof: float) -> None:
    assert chi2_quantile(p, dof) == float(stats.chi2.ppf(p, dof))


def test_textbook_f_and_chi2() -> None:
    assert f_quantile(0.95, 3, 16) == pytest.approx(3.2389, abs=1e-4)  # F(0.95; 3, 16), tables
    assert chi2_quantile(0.975, 10) == pytest.approx(20.483, abs=1e-3)  # χ²(0.975; 10), tables
