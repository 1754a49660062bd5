"""The roll a stand really made, measured from a sampled angle (a drive's actual position, an
inclinometer's slope): amplitude, period and phase per cycle by a fitted sinusoid, and their
scatter over the cycles.

Each window of one period is fitted by linear least squares with
    y(t) = a sin(w (t - t0)) + b cos(w (t - t0)) + c
(A = hypot(a, b), phase = atan2(b, a) of sin at the window's start t0, their SEs from the
residual variance). Over a whole period the fit is blind to the harmonics of a non-sinusoidal
roll (profile position's parabolic segments), which a free-frequency fit per window is not. The
frequency comes from the phases: against sin(w t) on the record's clock, a roll at w + s
drifts in phase by s per second, so those phases (phase_k - w t0_k, unwrapped) regressed on t0
give s; the fit is repeated with the corrected w and windows (from the nominal period, until
the drift is negligible). Per cycle, tau_k = 2 pi / (w + dphase_k / dt0_k) between consecutive
windows. Over the cycles: the mean amplitude with its SE from the scatter,
s / sqrt(n) (never below the mean fit SE / sqrt(n)); the period 2 pi / w with its SE from the
regression.
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
    period_s: float  # from the phase advance to the next window (nan for the last)
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


def _fit_window(t: np.ndarray, y: np.ndarray, w: float) -> tuple[float, float, float, float]:
    """Amplitude, its SE, phase, its SE of one window at angular frequency w."""
    t0 = float(t[0])
    design = np.column_stack([np.sin(w * (t - t0)), np.cos(w * (t - t0)), np.ones_like(t)])
    coef, rss, *_ = np.linalg.lstsq(design, y, rcond=None)
    dof = len(t) - 3
    s2 = float(rss[0]) / dof if len(rss) and dof > 0 else 0.0
    cov = s2 * np.linalg.inv(design.T @ design)
    a, b = coef[0], coef[1]
    amp = math.hypot(a, b)
    j_amp = np.array([a / amp, b / amp, 0.0])
    j_phase = np.array([-b / amp**2, a / amp**2, 0.0])  # d atan2(b, a)
    return amp, math.sqrt(j_amp @ cov @ j_amp), math.atan2(b, a), math.sqrt(j_phase @ cov @ j_phase)


def _windows(t: np.ndarray, period_s: float, min_samples: int) -> list[np.ndarray]:
    n_cycles = int((t[-1] - t[0]) / period_s + 1e-9) if len(t) else 0
    out = []
    for k in range(n_cycles):
        lo = t[0] + k * period_s
        sel = (t >= lo - 1e-9) & (t < lo + period_s - 1e-9)
        if sel.sum() >= min_samples:
            out.append(sel)
    return out


def measure_roll(
    t_s: np.ndarray, angle: np.ndarray, nominal_period_s: float, *, min_samples: int = 8
) -> MeasuredRoll:
    """Fit every whole period of the record (windows from its first sample)."""
    t, y = np.asarray(t_s, dtype=float), np.asarray(angle, dtype=float)
    w = 2.0 * math.pi / nominal_period_s
    w_se = 0.0
    for attempt in range(6):  # from the nominal w, corrected until the phases stop drifting
        windows = _windows(t, 2.0 * math.pi / w, min_samples)
        if not windows:
            raise RollFitError(
                f"no whole cycle of {nominal_period_s:g} s with {min_samples} samples to fit"
            )
        t0 = np.array([t[sel][0] for sel in windows])
        fits = [_fit_window(t[sel], y[sel], w) for sel in windows]
        # phase against sin(w t) on the record's clock: drifts at (w_true - w)
        phase = np.unwrap(np.array([f[2] for f in fits]) - w * t0)
        if len(windows) < 2:
            break
        # the phase drift rate: w's correction (weighted by the phases' SEs)
        weights = 1.0 / np.maximum([f[3] ** 2 for f in fits], 1e-30)
        x = t0 - np.average(t0, weights=weights)
        slope = float(np.sum(weights * x * phase) / np.sum(weights * x * x))
        resid = phase - np.average(phase, weights=weights) - slope * x
        chi2 = float(np.sum(weights * resid**2)) / max(1, len(x) - 2)
        w_se = math.sqrt(max(chi2, 1.0) / float(np.sum(weights * x * x)))
        if abs(slope) < 1e-3 * w_se or attempt == 5:
            break  # the fits are at this w
        w += slope
    period_k = 2.0 * math.pi / (w + np.diff(phase) / np.diff(t0)) if len(t0) > 1 else np.array([])
    cycles = tuple(
        CycleFit(
            float(t0[k]),
            fits[k][0],
            fits[k][1],
            float(period_k[k]) if k < len(period_k) else math.nan,
            fits[k][2],
            fits[k][3],
        )
        for k in range(len(fits))
    )
    amp = np.array([f[0] for f in fits])
    n = len(fits)
    scatter = float(amp.std(ddof=1)) if n > 1 else 0.0
    return MeasuredRoll(
        cycles,
        float(amp.mean()),
        max(scatter, float(np.mean([f[1] for f in fits]))) / math.sqrt(n),
        scatter,
        2.0 * math.pi / w,
        2.0 * math.pi / w**2 * w_se,
        float(period_k.std(ddof=1)) if len(period_k) > 1 else 0.0,
    )
