"""The roll a stand really made, measured from a sampled angle (a drive's actual position, an
inclinometer's slope): amplitude, period and phase per cycle by a fitted sinusoid, and their
scatter over the cycles.

Each window of one nominal period is fitted (scipy's curve_fit, Levenberg-Marquardt) with
    y(t) = a sin(w (t - t0)) + b cos(w (t - t0)) + c,
started from the linear least-squares fit at the nominal w. Per cycle: A = hypot(a, b),
tau = 2 pi / w, phase = atan2(b, a) (rad, of sin at the window's start t0 on the record's
clock), each with its standard error from the fit's covariance. Over the cycles: the mean, and
its standard error from the scatter, s / sqrt(n) (cycle-to-cycle variation included), never
smaller than the mean fit SE / sqrt(n).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class RollFitError(ValueError):
    """Too few samples for a fit (one line)."""


@dataclass(frozen=True)
class CycleFit:
    t0_s: float  # the window's start
    amplitude: float  # in the units of the samples
    amplitude_se: float
    period_s: float
    period_se_s: float
    phase_rad: float
    phase_se_rad: float


@dataclass(frozen=True)
class MeasuredRoll:
    cycles: tuple[CycleFit, ...]
    amplitude: float  # mean over cycles
    amplitude_se: float
    amplitude_sd: float  # cycle-to-cycle scatter
    period_s: float
    period_se_s: float
    period_sd_s: float


def _fit_window(t: np.ndarray, y: np.ndarray, w0: float) -> CycleFit:
    from scipy.optimize import curve_fit  # here: scipy.optimize's import is slow (CLI start)

    t0 = float(t[0])
    x = t - t0
    design = np.column_stack([np.sin(w0 * x), np.cos(w0 * x), np.ones_like(x)])
    start = np.linalg.lstsq(design, y, rcond=None)[0]

    def model(x: np.ndarray, a: float, b: float, c: float, w: float) -> np.ndarray:
        return a * np.sin(w * x) + b * np.cos(w * x) + c

    def jac(x: np.ndarray, a: float, b: float, c: float, w: float) -> np.ndarray:
        s, co = np.sin(w * x), np.cos(w * x)
        return np.column_stack([s, co, np.ones_like(x), x * (a * co - b * s)])

    p, cov = curve_fit(model, x, y, p0=[*start, w0], jac=jac)
    a, b, _, w = p
    amp = math.hypot(a, b)
    # first-order propagation of the (a, b, w) covariance
    ja = np.array([a / amp, b / amp, 0.0, 0.0])
    jphi = np.array([b / amp**2, -a / amp**2, 0.0, 0.0])  # d atan2(b, a)
    return CycleFit(
        t0,
        amp,
        math.sqrt(ja @ cov @ ja),
        float(2.0 * math.pi / w),
        float(2.0 * math.pi / w**2 * math.sqrt(cov[3, 3])),
        math.atan2(b, a),
        math.sqrt(jphi @ cov @ jphi),
    )


def measure_roll(
    t_s: np.ndarray, angle: np.ndarray, nominal_period_s: float, *, min_samples: int = 8
) -> MeasuredRoll:
    """Fit every whole nominal period of the record (t from its first sample)."""
    t, y = np.asarray(t_s, dtype=float), np.asarray(angle, dtype=float)
    n_cycles = int((t[-1] - t[0]) // nominal_period_s) if len(t) else 0
    fits = []
    for k in range(n_cycles):
        lo = t[0] + k * nominal_period_s
        sel = (t >= lo) & (t < lo + nominal_period_s)
        if sel.sum() >= min_samples:
            fits.append(_fit_window(t[sel], y[sel], 2.0 * math.pi / nominal_period_s))
    if not fits:
        raise RollFitError(
            f"no whole cycle of {nominal_period_s:g} s with {min_samples} samples to fit"
        )
    amp = np.array([f.amplitude for f in fits])
    per = np.array([f.period_s for f in fits])
    n = len(fits)

    def se(values: np.ndarray, fit_se: list[float]) -> float:
        scatter = float(values.std(ddof=1)) if n > 1 else 0.0
        return max(scatter, float(np.mean(fit_se))) / math.sqrt(n)

    return MeasuredRoll(
        tuple(fits),
        float(amp.mean()),
        se(amp, [f.amplitude_se for f in fits]),
        float(amp.std(ddof=1)) if n > 1 else 0.0,
        float(per.mean()),
        se(per, [f.period_se_s for f in fits]),
        float(per.std(ddof=1)) if n > 1 else 0.0,
    )
