"""Generalised least squares of model 1.1 when the trial means share an error (issue 34).

A compensated series (Bezvesilna & Gura; `acquisition.early_settle`) subtracts the transient
fitted with the period and damping ratio the record gave at the series' end, so the error e_s of
that pair moves every compensated mean of the campaign together. Per compensated series the
acquisition stores `SharedError`: g_s = d(compensated mean) / d(period, ratio), the covariance
Sigma_s of (period, ratio) at that time, and which record (run) gave them. The records of one
run are nested (the record only grows), so Cov(e_s, e_t) = Sigma of the later one: the later
estimate is efficient on a superset of the data, Cov(e_s - e_t, e_t) = 0 (Hausman 1978). The
records of different runs are independent.

The covariance of the fit trials' means is then V = diag(var_mean_i) + G C G^T less each
series' own g_s Sigma_s g_s^T, already in var_mean_i (a compensated mean's variance is its
compensation's SE^2, `analysis.transient.compensated_mean_se`, from the joint covariance that
includes the period and damping's), plus the covariance of
adjacent series' settle points at fixed period and damping (the state carried over a step
couples them: correlation about -0.5, so neighbouring trial means covary by about +0.35),
stored as the later one's ``previous_deg2`` (the later fit's, by the same nesting argument),
plus each compensated mean's covariance with the plain means of the uncompensated series before
it in its record (trial 1's: its windows fix every compensation's period, damping and carried
state), stored as ``earlier_deg2``, each naming its series (`analysis.transient.
compensated_covariances`).
Model 1.1 is fitted by Gauss-Newton on the whitened problem: V / v = L L^T (v the mean of
diag V, so the residual variance stays in deg^2 as the paper's S^2), L^-1 y against L^-1 f,
L^-1 X (Aitken 1935).
S^2 and (X^T X)^-1 of eqs 1.9-1.10 become those of the whitened problem: S^2 = r^T (V/v)^-1 r /
(n - m), cov = (X^T (V/v)^-1 X)^-1 S^2, t(n - m) as before. Without a shared error (the paper's
independent means, every criterion but "compensated") nothing here runs.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.nlsq import FitResult, fit_nonlinear

Series = tuple[int, int]  # (trial index, j)


@dataclass(frozen=True)
class SharedError:
    """A compensated series' share in the period and damping error: ``sensitivity`` =
    d(compensated mean) / d(period s, damping ratio) in deg/s and deg, ``covariance`` of
    (period, ratio) the compensation's fit gave, ``record_ms`` the stand ms of its record's
    first window (one run of the acquisition), ``at_ms`` when it was computed (series end).
    ``earlier_deg2``: its covariance with the plain mean of each uncompensated series whose
    observation windows are in the same record, named by that series' (trial index, j); JSON
    [{"trial": k, "j": m, "deg2": v}, ...] (absent before issue 34's fix: none). Only the
    series of the trial attempts acquired in that run are named (a failed trial's are not: a
    retry's attempt is acquired in another run)."""

    sensitivity: tuple[float, float]
    covariance: tuple[tuple[float, float], tuple[float, float]]
    record_ms: int
    at_ms: int
    previous_deg2: float = 0.0  # Cov(its settle point, the previous series') at fixed (P, ratio)
    earlier_deg2: tuple[tuple[Series, float], ...] = ()  # ((trial, j), Cov(its mean, theirs))

    def to_dict(self) -> dict[str, Any]:
        return {
            "sensitivity": list(self.sensitivity),
            "covariance": [list(row) for row in self.covariance],
            "record_ms": self.record_ms,
            "at_ms": self.at_ms,
            "previous_deg2": self.previous_deg2,
            "earlier_deg2": [{"trial": k, "j": m, "deg2": v} for (k, m), v in self.earlier_deg2],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SharedError:
        g = tuple(float(v) for v in data["sensitivity"])
        cov = tuple(tuple(float(v) for v in row) for row in data["covariance"])
        if len(g) != 2 or len(cov) != 2 or any(len(row) != 2 for row in cov):
            raise AnalysisError(f"a shared error needs 2 sensitivities, a 2x2 covariance: {data}")
        previous = float(data.get("previous_deg2", 0.0))
        try:
            earlier = tuple(
                ((int(e["trial"]), int(e["j"])), float(e["deg2"]))
                for e in data.get("earlier_deg2", ())
            )
        except (TypeError, KeyError, ValueError) as exc:
            raise AnalysisError(
                f"a shared error's earlier_deg2 needs {{trial, j, deg2}} entries: {data}"
            ) from exc
        return cls(g, cov, int(data["record_ms"]), int(data["at_ms"]), previous, earlier)  # type: ignore[arg-type]


def shared_covariance(
    shared: Mapping[Series, SharedError], trials: Sequence[int]
) -> np.ndarray | None:
    """(k, k) covariance that the shared period and damping errors add to the means of
    ``trials`` (<delta_i> = m_i2 - m_i1) beyond each series' own part; None when none of their
    series is compensated."""
    keys = [(i, j) for i in trials for j in (1, 2) if (i, j) in shared]
    if not keys:
        return None
    errors = [shared[k] for k in keys]
    g = np.zeros((len(keys), 2 * len(keys)))  # each series' mean against all (period, ratio)
    for a, e in enumerate(errors):
        g[a, 2 * a : 2 * a + 2] = e.sensitivity
    signs = np.zeros((len(trials), len(keys)))
    for c, (i, j) in enumerate(keys):
        signs[list(trials).index(i), c] = 1.0 if j == 2 else -1.0
    # each series' own part is in var_mean already, through its compensation's SE
    own = [float(np.array(e.sensitivity) @ e.covariance @ e.sensitivity) for e in errors]
    shared_g = signs @ g
    carried = np.zeros((len(keys), len(keys)))  # adjacent settle points through the state
    for b, (i, j) in enumerate(keys):
        before = (i, 1) if j == 2 else (i - 1, 2)
        if before in keys and shared[before].record_ms == errors[b].record_ms:
            a = keys.index(before)
            carried[a, b] = carried[b, a] = errors[b].previous_deg2
    covariance = shared_g @ pd_covariance(errors) @ shared_g.T + signs @ carried @ signs.T
    return covariance - np.diag(signs**2 @ own) + _with_uncompensated(shared, trials)


def _with_uncompensated(shared: Mapping[Series, SharedError], trials: Sequence[int]) -> np.ndarray:
    """Cov of the trial means through each compensated series' covariance with the plain means
    of the uncompensated series it names (``earlier_deg2``): both are linear in that record's
    readings. A named series that is not one of ``trials``' uncompensated series (a control
    trial's, a trial left out) adds nothing."""
    out = np.zeros((len(trials), len(trials)))
    where = {i: a for a, i in enumerate(trials)}
    for (i, j), error in shared.items():
        if i not in where:
            continue
        for (k, m), cov in error.earlier_deg2:
            if k not in where or (k, m) in shared:
                continue
            a, b = where[i], where[k]
            value = (1.0 if j == 2 else -1.0) * (1.0 if m == 2 else -1.0) * cov  # <d> = m2 - m1
            out[a, b] += value
            out[b, a] += value
    return out


def pd_covariance(errors: Sequence[SharedError]) -> np.ndarray:
    """Joint covariance of the series' (period, ratio) errors: Sigma of the later within one
    run, 0 across runs. The Sigmas of a growing record need not shrink monotonically, which
    that rule assumes: the nearest positive semi-definite matrix is taken (negative eigenvalues
    set to 0)."""
    n = len(errors)
    cov = np.zeros((2 * n, 2 * n))
    for a, ea in enumerate(errors):
        for b, eb in enumerate(errors):
            if ea.record_ms == eb.record_ms:
                later = ea if ea.at_ms >= eb.at_ms else eb
                cov[2 * a : 2 * a + 2, 2 * b : 2 * b + 2] = later.covariance
    scale = np.sqrt(np.diag(cov))  # period and ratio differ by 1e7 in their variances
    values, vectors = np.linalg.eigh(cov / np.outer(scale, scale))
    return (vectors * np.maximum(values, 0.0)) @ vectors.T * np.outer(scale, scale)


def trial_covariance(var_mean: Sequence[float], shared: np.ndarray) -> np.ndarray:
    """V = diag(var_mean) + the shared part, checked positive definite."""
    v = np.diag(np.asarray(var_mean, dtype=float)) + shared
    if not np.all(np.linalg.eigvalsh(v) > 0):
        raise AnalysisError(
            "the covariance of the trial means with their shared period and damping error is "
            "not positive definite: the stored compensations are inconsistent"
        )
    return v


def control_variances(
    x_fit: np.ndarray,
    x_control: np.ndarray,
    covariance: np.ndarray,
    xtx_inv: np.ndarray,
    s2: float,
) -> np.ndarray:
    """Var(<delta_c> - alpha(x_c, theta)) of each control trial c about the generalised fit
    (deg^2): S^2 [V_cc / v + x_c^T A x_c - 2 x_c^T A X^T W V_fc / v] with W = (V_ff / v)^-1,
    A = (X^T W X)^-1 (`fit_generalised`), v the mean of diag V_ff; eq 2.10 with the control's
    own variance for the 1 and its covariance with the fit trials (Goldberger 1962: the shared
    period and damping error moves a compensated control with the fit trials). ``covariance``
    is V over the n fit trials then the controls."""
    n = x_fit.shape[0]
    v_ff, v_fc = covariance[:n, :n], covariance[:n, n:]
    v = float(np.mean(np.diag(v_ff)))
    a = np.asarray(xtx_inv, dtype=float)
    gain = a @ x_fit.T @ np.linalg.solve(v_ff / v, v_fc / v)  # d theta / d(control's error)
    own = np.diag(covariance)[n:] / v
    leverage = np.einsum("ci,ij,cj->c", x_control, a, x_control)
    cross = np.einsum("ci,ic->c", x_control, gain)
    return s2 * (own + leverage - 2 * cross)  # eq 2.10 generalised


def fit_generalised(
    model: Callable[..., np.ndarray],
    x: Any,
    y: Sequence[float],
    theta0: Mapping[str, float],
    covariance: np.ndarray,
    **kwargs: Any,
) -> FitResult:
    """`fit_nonlinear` of the whitened problem (module docstring); ``fitted`` and ``residuals``
    are returned in deg as observed, ``rss``, ``s2`` and the covariance are the whitened ones
    (eqs 1.9-1.10 generalised: (X^T X)^-1 S^2 -> (X^T (V/v)^-1 X)^-1 S^2_gls)."""
    shape = covariance / float(np.mean(np.diag(covariance)))
    # L^-1 once: a triangular solve per evaluation costs ~10x the whole Gauss-Newton step on
    # these tiny matrices when a multi-threaded BLAS contends for cores (as in `analysis.nlsq`)
    inverse = np.linalg.inv(np.linalg.cholesky(shape))

    def white(values: np.ndarray) -> np.ndarray:
        return inverse @ values

    jacobian = kwargs.pop("jacobian")
    y = np.asarray(y, dtype=float)
    fit = fit_nonlinear(
        lambda x, **th: white(np.asarray(model(x, **th), dtype=float)),
        x,
        white(y),
        theta0,
        jacobian=lambda x, **th: white(jacobian(x, **th)),
        **kwargs,
    )
    fitted = np.asarray(model(x, **fit.estimates), dtype=float)
    return replace(fit, fitted=fitted, residuals=y - fitted, jacobian=jacobian(x, **fit.estimates))
