"""Allan deviation against the closed forms for white and random-walk readings."""

import numpy as np
import pytest

from gyrostand.analysis.allan import allan_deviation


def test_white_reading_falls_as_one_over_root_tau() -> None:
    rng = np.random.default_rng(0)
    adev = allan_deviation(rng.normal(0, 0.3, 2**16), 0.1)
    assert adev.tau_s[:4] == pytest.approx([0.1, 0.2, 0.4, 0.8])
    expected = 0.3 / np.sqrt(adev.tau_s / 0.1)  # sigma / sqrt(m)
    small = adev.tau_s <= 0.1 * 256  # many independent terms: estimate within ~5 %
    assert adev.deviation[small] == pytest.approx(expected[small], rel=0.06)
    assert np.all(adev.n_terms == 2**16 - 2 * (adev.tau_s / 0.1).round().astype(int) + 1)


def test_random_walk_reading_grows_as_root_tau() -> None:
    """Random walk with step s.d. s: AVAR(m) = s^2 (2 m^2 + 1) / (6 m) exactly."""
    rng = np.random.default_rng(1)
    m = np.array([1, 4, 16])
    reps = [allan_deviation(np.cumsum(rng.normal(0, 0.01, 2**14)), 1.0, m) for _ in range(20)]
    avar = np.mean([r.deviation**2 for r in reps], axis=0)
    assert avar == pytest.approx(0.01**2 * (2 * m**2 + 1) / (6 * m), rel=0.1)


def test_bad_averaging_factor_is_refused() -> None:
    with pytest.raises(ValueError, match="2m <"):
        allan_deviation(np.zeros(10), 1.0, np.array([5]))
