"""Benchmark: 10 000 trials x 2 series x 50 readings through trial statistics (eqs 2.1-2.4),
Cochran (2.5-2.6) and the Gauss-Newton fit of model 1.1, on one core. Target: under 1 s.

Run: .venv/bin/python bench/bench_analysis.py
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, set before numpy loads its BLAS

import time  # noqa: E402

import numpy as np  # noqa: E402

from gyrostand.analysis import cochran_test, fit_nonlinear  # noqa: E402
from gyrostand.analysis.campaign import analyze_campaign  # noqa: E402
from gyrostand.analysis.gyro_model import RollingErrorModel  # noqa: E402
from gyrostand.analysis.paper_example import CONSTANTS  # noqa: E402
from gyrostand.analysis.synthetic import Design, synthetic_readings, synthetic_trials  # noqa: E402
from gyrostand.analysis.trials import difference_statistics  # noqa: E402

TRIALS, READINGS, REPEATS = 10_000, 50, 7


def pipeline(design: Design, before: np.ndarray, under: np.ndarray) -> tuple[float, float]:
    """Statistics, Cochran and the fit: the timed part."""
    stats = difference_statistics(before, under)
    cochran_test(stats.var_deg2, stats.dof)
    model = RollingErrorModel(CONSTANTS)
    fit = fit_nonlinear(
        model,
        design.conditions,
        stats.delta_deg,
        {"C_gcm2s2": 7e7, "T_s": 0.55},
        jacobian=model.jacobian,
        eps_se=1e-3,
    )
    return fit.estimates["C_gcm2s2"], fit.estimates["T_s"]


def main() -> None:
    rng = np.random.default_rng(2024)
    design = Design(
        direction_deg=rng.choice([20.0, 35.0, 60.0, 110.0, 140.0, 160.0], TRIALS),
        amplitude_cm=rng.uniform(15.0, 25.0, TRIALS),
        period_s=rng.uniform(3.5, 8.0, TRIALS),
    )
    before, under = synthetic_readings(
        CONSTANTS,
        design,
        C_gcm2s2=6e7,
        T_s=1.15,
        sigma_deg=0.01,
        n_obs=(READINGS, READINGS),
        rng=rng,
    )
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        c, t = pipeline(design, before, under)
        times.append(time.perf_counter() - start)
    best, median = min(times), float(np.median(times))
    print(f"trials x series x readings: {TRIALS} x 2 x {READINGS} ({before.size * 2:,} readings)")
    print(f"estimates: C = {c:.5g} g cm^2 s^-2 (true 6e7), T = {t:.5f} s (true 1.15)")
    verdict = "PASS" if median < 1.0 else "FAIL"
    print(
        f"statistics + Cochran + fit, one core: median {median * 1e3:.1f} ms, best "
        f"{best * 1e3:.1f} ms over {REPEATS} runs (target < 1000 ms): {verdict}"
    )
    # for information: the object API with every check (20 000 Shapiro-Wilk tests included)
    trials = synthetic_trials(
        CONSTANTS, design, ["fit"] * TRIALS, C_gcm2s2=6e7, T_s=1.15, sigma_deg=0.01,
        n_obs=READINGS, rng=rng,
    )  # fmt: skip
    start = time.perf_counter()
    analyze_campaign(trials, CONSTANTS)
    print(
        f"analyze_campaign on {TRIALS} TrialInput objects (all checks): "
        f"{time.perf_counter() - start:.2f} s"
    )


if __name__ == "__main__":
    main()
