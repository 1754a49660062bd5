"""Cochran's critical value and test (eqs 2.5-2.6) against published tables and simulation."""

import numpy as np
import pytest

from gyrostand.analysis import cochran_critical
from gyrostand.analysis.cochran import cochran_test
from gyrostand.analysis.errors import AnalysisError, UnequalDegreesOfFreedomError, ZeroVarianceError

# q = 0.05, (k variances, nu = n - 1 dof): UK National Measurement System table (3 decimals),
# http://www.nmschembio.org.uk/GenericArticle.aspx?m=395&amid=5622
TABLE_05 = {
    (2, 1): 0.998, (3, 1): 0.967, (4, 1): 0.906, (10, 1): 0.602, (20, 1): 0.389,
    (2, 2): 0.975, (4, 2): 0.768, (6, 2): 0.616, (15, 2): 0.335,
    (3, 3): 0.798, (5, 3): 0.598, (9, 3): 0.403, (20, 3): 0.221,
    (2, 4): 0.906, (4, 4): 0.629, (7, 4): 0.431, (10, 4): 0.331, (20, 4): 0.192,
}  # fmt: skip
# q = 0.01: Eisenhart-Hastay-Wallis table as reprinted at
# http://faculty.washington.edu/heagerty/Books/Biostatistics/TABLES/Cochran/
# (its entries for many variances, e.g. k = 20, nu = 16: .1248, sit up to 1 % above the exact
# value; the simulation below confirms the formula's 0.1244 there).
TABLE_01 = {
    (2, 1): 0.9999, (2, 2): 0.9950, (3, 3): 0.8831, (4, 4): 0.7212, (5, 6): 0.5531,
    (6, 8): 0.4401, (10, 10): 0.2704, (120, 144): 0.0125,
}  # fmt: skip


def test_paper_critical_value() -> None:
    """Seed 000 example: q = 0.05, nu = 8, k = 4 gives G* = 0.5175."""
    assert cochran_critical(0.05, 8, 4) == pytest.approx(0.5175, abs=5e-5)


@pytest.mark.parametrize(("k", "nu"), sorted(TABLE_05))
def test_published_table_q05(k: int, nu: int) -> None:
    assert cochran_critical(0.05, nu, k) == pytest.approx(TABLE_05[(k, nu)], abs=6e-4)


@pytest.mark.parametrize(("k", "nu"), sorted(TABLE_01))
def test_published_table_q01(k: int, nu: int) -> None:
    assert cochran_critical(0.01, nu, k) == pytest.approx(TABLE_01[(k, nu)], abs=1.5e-4)


@pytest.mark.parametrize(
    ("q", "nu", "k"), [(0.05, 8, 4), (0.05, 4, 10), (0.10, 2, 6), (0.01, 16, 20)]
)
def test_monte_carlo_size(q: float, nu: int, k: int) -> None:
    """Under equal true variances, G exceeds G* with probability q (to MC precision)."""
    rng = np.random.default_rng(20240601 + nu * k)
    reps = 200_000
    s2 = rng.chisquare(nu, size=(reps, k))
    g = s2.max(axis=1) / s2.sum(axis=1)
    rate = np.mean(g >= cochran_critical(q, nu, k))
    assert abs(rate - q) < 4 * np.sqrt(q * (1 - q) / reps)


def test_paper_example_test() -> None:
    result = cochran_test([0.80e-4, 4.64e-4, 1.84e-4, 2.12e-4], [8, 8, 8, 8], q=0.05)
    assert result.g_ex == pytest.approx(0.4936, abs=5e-5)
    assert result.homogeneous and result.largest == 2
    assert result.pooled_variance == pytest.approx(2.35e-4)  # eq 2.6
    assert result.s_e == pytest.approx(0.0153, abs=5e-5)


def test_inhomogeneous_names_the_trial() -> None:
    result = cochran_test([1.0, 1.2, 9.0, 0.9], [8] * 4, labels=[11, 12, 13, 14])
    assert not result.homogeneous and result.largest == 13


def test_bad_input() -> None:
    with pytest.raises(UnequalDegreesOfFreedomError, match="trial 3 has 6"):
        cochran_test([1.0, 2.0, 3.0], [8, 8, 6])
    with pytest.raises(ZeroVarianceError):
        cochran_test([0.0, 0.0], [4, 4])
    with pytest.raises(AnalysisError, match="q = 1.5"):
        cochran_critical(1.5, 4, 3)
    with pytest.raises(AnalysisError, match="k = 1"):
        cochran_critical(0.05, 4, 1)
