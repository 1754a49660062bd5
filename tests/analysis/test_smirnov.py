"""analysis.smirnov: Smirnov's two-sample statistic and exact p-value equal scipy.stats.ks_2samp's
(its exact mode, the one it takes for these sizes) on many random pairs of samples, with ties,
equal and unequal sizes; and a closed-form case."""

import math

import numpy as np
import pytest
from scipy import stats

from gyrostand.analysis.smirnov import smirnov_p_value, smirnov_test


def test_equals_scipy_ks_2samp_on_many_cases() -> None:
    rng = np.random.default_rng(33)
    for case in range(300):
        n1, n2 = (int(n) for n in rng.integers(1, 36, 2))
        if case % 7 == 0:
            n2 = n1  # scipy takes another formula for equal sizes: the same exact value
        a = rng.normal(size=n1)
        b = rng.normal(rng.uniform(0.0, 2.0), rng.uniform(0.5, 2.0), size=n2)
        if case % 5 == 0:
            a, b = np.round(a, 1), np.round(b, 1)  # ties
        expected = stats.ks_2samp(a, b, method="exact")
        found = smirnov_test(a, b)
        assert found.statistic == pytest.approx(float(expected.statistic), abs=1e-12)
        assert found.p_value == pytest.approx(float(expected.pvalue), abs=1e-12)


def test_complete_separation_has_its_closed_form() -> None:
    # D = 1 only when every value of one sample lies below the other's: 2 of C(m+n, n) orders
    for m, n in [(3, 3), (3, 5), (4, 9)]:
        p = smirnov_test(np.arange(m, dtype=float), np.arange(n, dtype=float) + 100).p_value
        assert p == pytest.approx(2 / math.comb(m + n, n), rel=1e-12)


def test_identical_samples_give_p_one() -> None:
    assert smirnov_p_value(4, 6, 0.0) == 1.0
    with pytest.raises(ValueError, match="non-empty"):
        smirnov_test(np.array([]), np.array([1.0]))
