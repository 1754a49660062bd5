"""analysis.quantiles: Student's t quantile by scipy.special equals scipy.stats' (the report's
t values are the ones the analysis used)."""

import pytest
from scipy import stats

from gyrostand.analysis.quantiles import t_quantile


@pytest.mark.parametrize("dof", [1, 2, 3.5, 8, 16, 1000])
@pytest.mark.parametrize("p", [0.5, 0.95, 0.975, 0.025])
def test_t_quantile_is_scipy_stats_t_ppf(p: float, dof: float) -> None:
    assert t_quantile(p, dof) == float(stats.t.ppf(p, dof))


def test_the_textbook_value() -> None:
    assert t_quantile(0.975, 8) == pytest.approx(2.306004, abs=1e-6)  # t(0.975; 8), tables
