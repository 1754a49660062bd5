"""The transient fit with the period and damping estimated from the record
(`analysis.transient.fit_transient_free`): its settle points' SE carries the uncertainty of the
period and damping (issue 34: held at the record's estimate, a compensation came out several SE
wrong).

Records of the simulated compass's transient (seed 003 eq 2, 5064 s, 0.7) across one step of
the equilibrium, observed as window means with fixed-seed white noise, the second series in
its transient as a compensated one is; the fit starts from a plan 10 % short. Over 100 records
the RMS error of the second settle point over the RMS of its SE is 0.85-1.07 for seeds 1, 2, 3,
34 (joint covariance); with the period and damping held at the fitted values it was 2.8-3.6.
"""

import numpy as np

from gyrostand.analysis.transient import (
    Segments,
    TransientModel,
    Windows,
    design,
    fit_transient,
    fit_transient_free,
)

TRUE = TransientModel(5064.0, 0.7)
WIDTH_S, STEP_S, END_S, NOISE_DEG = 120.0, 4800.0, 7200.0, 0.003
SEGMENTS = Segments((0.0, STEP_S), (True, False))
MIDS = np.arange(WIDTH_S / 2, END_S, WIDTH_S)
SEGMENT = (MIDS > STEP_S).astype(int)
THETA = np.array([0.0, 0.5, 0.3, 0.0])  # R_0, R_1 (deg), x_0, v_0 of the first (free) series
CLEAN = design(TRUE, SEGMENTS, SEGMENT, MIDS, WIDTH_S) @ THETA


def _records(seed: int, n: int = 100) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The second settle point's errors, its SE from the free fit, and from the fit with the
    period and damping held at the free fit's."""
    rng = np.random.default_rng(seed)
    errors, joint, held = [], [], []
    for _ in range(n):
        data = Windows(
            SEGMENT,
            MIDS,
            np.full(MIDS.size, WIDTH_S),
            CLEAN + NOISE_DEG * rng.standard_normal(MIDS.size),
        )
        fit = fit_transient_free(TransientModel(0.9 * TRUE.undamped_period_s, 0.7), SEGMENTS, data)
        errors.append(fit.theta[1] - THETA[1])
        joint.append(fit.settle_point(1)[1])
        held.append(fit_transient(fit.model, SEGMENTS, data).settle_point(1)[1])
    return np.array(errors), np.array(joint), np.array(held)


def _ratio(errors: np.ndarray, ses: np.ndarray) -> float:
    return float(np.sqrt(np.mean(errors**2) / np.mean(ses**2)))


def test_the_settle_point_se_carries_the_period_and_damping_uncertainty() -> None:
    errors, joint, held = _records(seed=2)
    assert 0.8 <= _ratio(errors, joint) <= 1.2  # 0.90 for this seed
    assert _ratio(errors, held) > 2.0  # what the fixed-period covariance claimed (3.0)


def test_the_period_and_damping_are_unbiased_with_honest_se() -> None:
    rng = np.random.default_rng(5)
    z_period, z_ratio = [], []
    for _ in range(40):
        data = Windows(
            SEGMENT,
            MIDS,
            np.full(MIDS.size, WIDTH_S),
            CLEAN + NOISE_DEG * rng.standard_normal(MIDS.size),
        )
        fit = fit_transient_free(TransientModel(0.9 * TRUE.undamped_period_s, 0.7), SEGMENTS, data)
        assert fit.period_se_s is not None and fit.damping_ratio_se is not None
        z_period.append((fit.model.undamped_period_s - TRUE.undamped_period_s) / fit.period_se_s)
        z_ratio.append((fit.model.damping_ratio - TRUE.damping_ratio) / fit.damping_ratio_se)
    for z in (np.array(z_period), np.array(z_ratio)):
        assert abs(z.mean()) < 0.5 and 0.7 < z.std(ddof=1) < 1.3
