"""Adequacy of the fitted model (seed 000 eqs 2.7-2.8) and the judgement of control trials.

Two error bases are computed. The paper's (eq 2.8) divides S^2_r by the pooled
single-observation variance S^2_e (2.6) with nu_e = n (N - 1) dof, as its example does. The trial
means <delta_i> that S^2_r scatters about have variance S^2_e / N, so the ratio on that basis is
N times larger. The decision stands on the trial means (`ADEQUACY_BASIS`, `Adequacy.decision`):
S^2_r and its error variance then describe the same quantity; the paper's basis is kept to
compare with its example.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.forecast import Predictor
from gyrostand.analysis.gyro_model import Conditions
from gyrostand.analysis.quantiles import f_cdf, f_quantile, f_sf

ADEQUACY_BASIS = "trial means"
ADEQUACY_BASIS_TEXT = (
    "Fisher's F on the trial means: F_p = S_r^2 / (S_e^2 / N), the residual variance of the fit "
    "against the variance of a trial mean <delta_i> (the quantity the residuals scatter); the "
    "paper's eq 2.8 divides by S_e^2, the variance of one observation, and is shown only to "
    "compare with its example"
)


@dataclass(frozen=True)
class Adequacy:
    """F test of the model (2.7-2.8) on the paper's basis and on the trial-mean basis.

    ``adequate`` / ``adequate_mean_basis`` are None when the trial variances are not homogeneous
    (Cochran rejected), since S^2_e is then not a valid error estimate."""

    s2_r: float
    dof_r: int
    s2_e: float
    dof_e: int
    f_p: float
    f_critical: float
    p_value: float
    adequate: bool | None
    s2_e_mean: float
    f_p_mean: float
    p_value_mean: float
    adequate_mean_basis: bool | None
    q: float
    dof_e_mean: float  # nu of s2_e_mean: nu_e, or a generalised fit's (inf: V known)
    f_critical_mean: float  # F_T(1 - q; dof_r, dof_e_mean), what the decision is against

    @property
    def decision(self) -> bool | None:
        """Is the model adequate, on the basis the decision stands on (`ADEQUACY_BASIS`)?
        None: not tested (Cochran rejected homogeneity)."""
        return self.adequate_mean_basis


def adequacy_test(
    s2_r: float,
    dof_r: int,
    s2_e: float,
    s2_e_mean: float,
    dof_e: int,
    *,
    q: float,
    homogeneous: bool,
    generalised: bool = False,
    dof_e_mean: float | None = None,
) -> Adequacy:
    """F_p = S^2_r / S^2_e (2.8) against F_T(1 - q; n - m, nu_e), and the trial-mean variant.
    Not homogeneous (Cochran): S^2_e is not valid and neither decision is made, unless the fit
    is ``generalised`` (`analysis.gls`): its S^2_r and s2_e_mean (the mean variance of V) weigh
    each trial by its own variance, so the trial-mean decision does not rest on S^2_e, and its
    F_T takes s2_e_mean's own degrees of freedom ``dof_e_mean`` (`generalised_dof`; None:
    nu_e)."""
    f_p = s2_r / s2_e  # eq 2.8
    f_p_mean = s2_r / s2_e_mean
    f_crit = f_quantile(1 - q, dof_r, dof_e)
    dof_mean = float(dof_e if dof_e_mean is None else dof_e_mean)
    f_crit_mean = f_quantile(1 - q, dof_r, dof_mean)
    return Adequacy(
        s2_r=s2_r,
        dof_r=dof_r,
        s2_e=s2_e,
        dof_e=dof_e,
        f_p=f_p,
        f_critical=f_crit,
        p_value=f_sf(f_p, dof_r, dof_e),
        adequate=bool(f_p < f_crit) if homogeneous else None,
        s2_e_mean=s2_e_mean,
        f_p_mean=f_p_mean,
        p_value_mean=f_sf(f_p_mean, dof_r, dof_mean),
        adequate_mean_basis=bool(f_p_mean < f_crit_mean) if homogeneous or generalised else None,
        q=q,
        dof_e_mean=dof_mean,
        f_critical_mean=f_crit_mean,
    )


def generalised_dof(estimated: Sequence[tuple[float, float]], total: float) -> float:
    """Degrees of freedom of the mean variance of V (`adequacy_test`'s s2_e_mean), ``total`` =
    sum of diag V: Welch-Satterthwaite, (sum V_ii)^2 / sum (P_i^2 / nu_i), over the parts P_i
    estimated from a trial's own few observations (S^2 / N_eff, nu_i by eq 2.4 with N_eff);
    a compensation's variance comes from the fit of the whole record and counts as known.
    Infinite when no part is estimated: F_p then follows chi^2(n - m) / (n - m), where F(n - m,
    nu_e) made the generalised test reject a true model 2.6 % of the time at q = 5 % (2000
    draws of validation/shared_error.py's structure; 4.9 % with this)."""
    spread = sum(part**2 / dof for part, dof in estimated if part > 0)
    return math.inf if spread == 0 else total**2 / spread


@dataclass(frozen=True)
class ErrorAgreement:
    """Whether the residual variance S^2_r (2.7) is implausibly small against the error of the
    trial means S^2_e/N: the lower tail of F = S^2_r / (S^2_e/N) ~ F(n - m, nu_e) (eq 2.8 read
    the other way). ``p_low`` = P(F <= F_p); ``too_small`` when below q (the two estimates of
    error disagree: the t(n - m) intervals, which rest on S^2_r, may be too narrow)."""

    f_p: float
    dof_r: int
    dof_e: float  # of the trial means' error variance (`Adequacy.dof_e_mean`)
    p_low: float
    q: float
    too_small: bool


def error_agreement(adequacy: Adequacy) -> ErrorAgreement:
    """The lower-tail F test of S^2_r against the trial-mean error S^2_e/N of ``adequacy``."""
    f_p = adequacy.f_p_mean  # eq 2.8 on the trial-mean basis
    p_low = f_cdf(f_p, adequacy.dof_r, adequacy.dof_e_mean)
    return ErrorAgreement(
        f_p, adequacy.dof_r, adequacy.dof_e_mean, p_low, adequacy.q, p_low < adequacy.q
    )


@dataclass(frozen=True)
class ControlResult:
    """A control trial (not fitted): observed <delta>, the model's prediction, residual
    v = <delta> - alpha, judged against S_e (bound t(1 - q/2; nu_e) S_e) and against the
    (1 - q) prediction interval of eq 2.11."""

    index: int
    direction_deg: float
    amplitude_cm: float
    period_s: float
    observed_deg: float
    predicted_deg: float
    residual_deg: float
    residual_over_s_e: float
    s_e_bound_deg: float
    within_s_e_bound: bool
    half_width_deg: float
    within_interval: bool


def judge_controls(
    predictor: Predictor,
    conditions: Conditions,
    observed_deg: np.ndarray,
    indices: list[int],
    *,
    s_e: float,
    dof_e: int,
    variance_deg2: np.ndarray | None = None,
) -> tuple[ControlResult, ...]:
    """Predict each control trial and judge its residual; ``variance_deg2``: the residuals'
    variances when they are not eq 2.10's (a generalised fit: `analysis.gls.control_variances`)."""
    from scipy import stats

    if not indices:
        return ()
    p = predictor.predict(conditions)
    half_widths = p.half_width_deg if variance_deg2 is None else p.t * np.sqrt(variance_deg2)
    bound = float(stats.t.ppf(1 - predictor.q / 2, dof_e)) * s_e
    results = []
    for i, index in enumerate(indices):
        residual = float(observed_deg[i] - p.alpha_deg[i])
        results.append(
            ControlResult(
                index=index,
                direction_deg=float(conditions.direction_deg[i]),
                amplitude_cm=float(conditions.amplitude_cm[i]),
                period_s=float(conditions.period_s[i]),
                observed_deg=float(observed_deg[i]),
                predicted_deg=float(p.alpha_deg[i]),
                residual_deg=residual,
                residual_over_s_e=residual / s_e,
                s_e_bound_deg=bound,
                within_s_e_bound=abs(residual) <= bound,
                half_width_deg=float(half_widths[i]),
                within_interval=abs(residual) <= float(half_widths[i]),
            )
        )
    return tuple(results)
