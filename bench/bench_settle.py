"""Settle-point estimation (seed 003): least squares vs Kalman filter, and the "observe at least
3 T0" guidance reproduced numerically, with what the damped model changes.

Run: .venv/bin/python bench/bench_settle.py   (prints tables; a few minutes)

Dynamics as the stand simulator's defaults: undamped period T0 = 5064 s, damping xi/omega0 = 0.7,
reading noise sigma^2 e^(-mu|tau|) with sigma = 0.01 deg, mu = 0.05 1/s, plus 0.005 deg white,
readings averaged to 1 Hz; initial deviation 5 deg from the settle point. BLAS runs on one thread
so that per-call times measure the algorithm, not thread contention on a shared machine.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.signal import lfilter  # noqa: E402

from gyrostand.analysis.errors import AnalysisError  # noqa: E402
from gyrostand.analysis.kalman import SettleKalman  # noqa: E402
from gyrostand.analysis.settle import estimate_settle_point, estimate_settle_point_free  # noqa: E402

T0_S = 5064.0
OMEGA0 = 2 * math.pi / T0_S
DT_S = 1.0
A0_DEG = 5.0
SETTLE_DEG = 123.0
REPS = 40
FREE_REPS = 10  # the free-omega/xi fit is ~100x slower: fewer records


def noise(rng: np.random.Generator, n: int) -> np.ndarray:
    a = math.exp(-0.05 * DT_S)
    shocks = rng.normal(0, 0.01 * math.sqrt(1 - a * a), n)
    correlated = lfilter([1.0], [1.0, -a], shocks, zi=[a * rng.normal(0, 0.01)])[0]
    return correlated + rng.normal(0, 0.005, n)


def transient(t: np.ndarray, xi_ratio: float, phase: float) -> np.ndarray:
    """R + A0 e^(-xi t) sin(omega t + phi), omega = sqrt(omega0^2 - xi^2) (seed 003 eq 2)."""
    xi = xi_ratio * OMEGA0
    omega = OMEGA0 * math.sqrt(1 - xi_ratio**2)
    return SETTLE_DEG + A0_DEG * np.exp(-xi * t) * np.sin(omega * t + phase)


def lsq_vs_kalman(xi_ratio: float, lengths: list[float]) -> None:
    xi = xi_ratio * OMEGA0
    omega = OMEGA0 * math.sqrt(1 - xi_ratio**2)
    rng = np.random.default_rng(1)
    t = np.arange(0, max(lengths) * T0_S, DT_S)
    cut = [int(length * T0_S / DT_S) for length in lengths]
    err = {k: [[] for _ in lengths] for k in ("lsq", "kf", "free", "undamped")}
    se = {k: [[] for _ in lengths] for k in ("lsq", "kf")}
    kf_us = []
    for rep in range(REPS):
        y = transient(t, xi_ratio, rng.uniform(0, 2 * math.pi)) + noise(rng, t.size)
        kf = SettleKalman(omega, math.sqrt(0.01**2 + 0.005**2), damping_per_s=xi)
        done = 0
        for j, n in enumerate(cut):
            start = time.perf_counter()
            kf.update_many(t[done:n], y[done:n])
            kf_us.append((time.perf_counter() - start) / (n - done) * 1e6)
            done = n
            lsq = estimate_settle_point(t[:n], y[:n], omega, xi)
            err["lsq"][j].append(lsq.settle_point_deg - SETTLE_DEG)
            se["lsq"][j].append(lsq.standard_error_deg)
            err["kf"][j].append(kf.settle_point_deg - SETTLE_DEG)
            se["kf"][j].append(kf.standard_error_deg)
            und = estimate_settle_point(t[:n], y[:n], omega)
            err["undamped"][j].append(und.settle_point_deg - SETTLE_DEG)
            if rep >= FREE_REPS:
                continue
            try:  # omega and xi estimated too, started 10 % and 30 % off
                free = estimate_settle_point_free(t[:n], y[:n], 1.1 * omega, 0.7 * xi)
                err["free"][j].append(free.settle_point_deg - SETTLE_DEG)
            except AnalysisError:
                err["free"][j].append(math.nan)
    lsq_ms = []
    for n in cut:
        y = transient(t[:n], xi_ratio, 0.3) + noise(rng, n)
        start = time.perf_counter()
        for _ in range(20):
            estimate_settle_point(t[:n], y, omega, xi)
        lsq_ms.append((time.perf_counter() - start) / 20 * 1e3)

    def rms(values: list[float]) -> str:
        v = np.asarray(values)
        ok = np.isfinite(v)
        text = f"{math.sqrt(np.mean(v[ok] ** 2)):9.4f}" if ok.any() else f"{'fails':>9}"
        return text + ("*" if not ok.all() else " ")

    print(f"\nxi/omega0 = {xi_ratio}: RMS error of R^ over {REPS} records (deg); mean reported SE")
    print(
        f"{'T_c/T0':>6} {'LSQ damped':>10} {'SE':>7} {'KF damped':>10} {'SE':>7} "
        f"{'LSQ free':>10} {'LSQ model 4':>12} {'LSQ ms/call':>11}"
    )
    for j, length in enumerate(lengths):
        print(
            f"{length:6.2f} {rms(err['lsq'][j])} {np.mean(se['lsq'][j]):7.4f} "
            f"{rms(err['kf'][j])} {np.mean(se['kf'][j]):7.4f} {rms(err['free'][j])} "
            f"{rms(err['undamped'][j]):>12} {lsq_ms[j]:11.2f}"
        )
    print(
        f"KF: {np.median(kf_us):.1f} us per reading (median); LSQ: refit of the whole record "
        f"per call. LSQ free: omega, xi estimated too ({FREE_REPS} records; * = some failed to "
        "converge, RMS over the rest). KF SE assumes white noise, so it is low for this "
        "noise (correlation time 20 s); LSQ SE includes the inflation for correlated noise."
    )


def worst_bias(length: float, xi_ratio: float, damped_model: bool) -> float:
    """max over the initial phase of |R^ - R| / A0, noise-free record of `length` T0."""
    t = np.arange(0, length * T0_S, 10.0)
    omega = OMEGA0 * math.sqrt(1 - xi_ratio**2)
    worst = 0.0
    for phase in np.linspace(0, math.pi, 24, endpoint=False):
        y = transient(t, xi_ratio, phase)
        est = estimate_settle_point(t, y, omega, xi_ratio * OMEGA0 if damped_model else None)
        worst = max(worst, abs(est.settle_point_deg - SETTLE_DEG) / A0_DEG)
    return worst


def three_t0(xi_ratios: list[float], limit: float) -> None:
    lengths = np.arange(0.5, 6.01, 0.25)
    print(
        f"\nModel 4 (undamped) on damped records: worst-case |R^ - R| / A0 over the initial phase; "
        f"first T_c/T0 from which it stays <= {limit:.0%}"
    )
    print(f"{'T_c/T0':>6} " + " ".join(f"{f'xi/w0={r}':>10}" for r in xi_ratios))
    table = np.array([[worst_bias(length, r, False) for r in xi_ratios] for length in lengths])
    for length, row in zip(lengths, table, strict=True):
        print(f"{length:6.2f} " + " ".join(f"{v:10.4f}" for v in row))
    firsts = []
    for col in table.T:
        above = np.flatnonzero(col > limit)
        first = lengths[above[-1] + 1] if above.size and above[-1] + 1 < lengths.size else None
        firsts.append("> 6" if above.size and first is None else f"{first or lengths[0]:.2f}")
    print(f"{'needs':>6} " + " ".join(f"{f:>10}" for f in firsts) + "  (T_c/T0)")
    damped = max(worst_bias(0.5, r, True) for r in xi_ratios)
    print(
        f"Damped model (xi known): worst-case bias {damped:.1e} A0 (0 up to rounding), so the "
        "record only has to beat the noise. Shortest record (T_c/T0) with RMS error within:"
    )
    grid = [0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0]
    for xi_ratio in (0.1, 0.7):
        rms = damped_rms(xi_ratio, grid)
        needs = [
            next((g for g, r in zip(grid, rms, strict=True) if r <= lim), None)
            for lim in (limit * A0_DEG, 0.01, 0.002)
        ]
        print(
            f"  xi/w0={xi_ratio}: {limit:.0%} of A0 ({limit * A0_DEG:.2f} deg): {needs[0]}, "
            f"0.01 deg: {needs[1]}, 0.002 deg: {needs[2]}  (RMS over {REPS} noisy records)"
        )


def damped_rms(xi_ratio: float, lengths: list[float]) -> list[float]:
    """RMS error of the damped-model LSQ over REPS noisy records, per record length."""
    rng = np.random.default_rng(2)
    xi = xi_ratio * OMEGA0
    omega = OMEGA0 * math.sqrt(1 - xi_ratio**2)
    t = np.arange(0, max(lengths) * T0_S, DT_S)
    errors = np.zeros((REPS, len(lengths)))
    for rep in range(REPS):
        y = transient(t, xi_ratio, rng.uniform(0, 2 * math.pi)) + noise(rng, t.size)
        for j, length in enumerate(lengths):
            n = int(length * T0_S / DT_S)
            est = estimate_settle_point(t[:n], y[:n], omega, xi)
            errors[rep, j] = est.settle_point_deg - SETTLE_DEG
    return list(np.sqrt(np.mean(errors**2, axis=0)))


def main() -> None:
    print("== LSQ vs Kalman filter (seed 003): accuracy vs record length, time per update")
    lsq_vs_kalman(0.7, [0.25, 0.5, 1.0, 2.0, 3.0])
    lsq_vs_kalman(0.1, [0.25, 0.5, 1.0, 2.0, 3.0])
    print("\n== The seed's 'observe at least 3 T0' for the undamped model, and the damped model")
    three_t0([0.03, 0.1, 0.2, 0.35, 0.7], 0.05)


if __name__ == "__main__":
    main()
