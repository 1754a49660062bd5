"""Acceptance of an instrument by excursions of its reading out of a tolerance band (seed 004,
Sveshnikov §8.3 item 1, eqs 8.79-8.89).

The reading Y(t) = a + X(t) is Gaussian with correlation function K of X. Over a control time T
the mean numbers of up-crossings of the upper bound and down-crossings of the lower bound follow
Rice's formula; if excursions are rare they form a Poisson stream, so the probability of none is
e^(-n). Rice needs a differentiable X (finite variance of dX/dt = -K''(0)): use the smooth
``CorrelationModel`` e^(-mu|tau|)(cos(beta tau) + mu/beta sin(beta |tau|)), not the exponential.
"""

from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import brentq

from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.noise import CorrelationModel


@dataclass(frozen=True)
class ExcursionAcceptance:
    """Expected excursions of the reading out of (lower, upper) during ``duration_s``.

    ``p_no_excursion`` is alpha = P(no excursion) = e^(-n) (8.84). The Poisson assumption behind
    it holds, to first approximation, when the mean time between excursions T / n exceeds the
    correlation time tau_k (8.89): ``poisson_valid``."""

    lower: float
    upper: float
    mean: float
    duration_s: float
    sigma: float
    sigma_dot: float
    upcrossings_upper: float
    downcrossings_lower: float
    mean_excursions: float
    p_no_excursion: float
    mean_time_between_s: float
    correlation_time_s: float
    poisson_valid: bool

    def to_dict(self) -> dict[str, float | bool]:
        return asdict(self)


def _rates(model: CorrelationModel) -> tuple[float, float]:
    if not model.is_smooth:
        raise AnalysisError(
            "Rice's formula needs a differentiable reading: the exponential correlation "
            "sigma^2 e^(-mu|tau|) gives infinitely many excursions; fit the smooth model "
            "(fit_correlation(..., smooth=True))"
        )
    return float(np.sqrt(model.variance)), float(np.sqrt(model.derivative_variance))


def excursion_acceptance(
    model: CorrelationModel,
    lower: float,
    upper: float,
    duration_s: float,
    mean: float | None = None,
) -> ExcursionAcceptance:
    """Mean excursions of a reading with correlation ``model`` and mean ``mean`` (default: the
    middle of the band) out of (``lower``, ``upper``) in ``duration_s`` (seed 004 eqs 8.80-8.88).

    n2 = T sigma_v / (2 pi sigma) e^(-(b2 - m)^2 / 2 sigma^2) up-crossings of b2 (8.80, 8.87),
    n1 likewise down-crossings of b1 (8.81), n = n1 + n2 (8.82; 8.88 when m is mid-band)."""
    if not upper > lower:
        raise ValueError(f"tolerance band ({lower}, {upper}) is empty")
    sigma, sigma_dot = _rates(model)
    m = (lower + upper) / 2 if mean is None else float(mean)
    per_crossing = duration_s * sigma_dot / (2 * np.pi * sigma)  # (8.87) without the Gaussian
    n2 = per_crossing * np.exp(-((upper - m) ** 2) / (2 * sigma**2))
    n1 = per_crossing * np.exp(-((m - lower) ** 2) / (2 * sigma**2))
    n = n1 + n2
    between = duration_s / n if n > 0 else float("inf")
    tau_k = model.correlation_time_s
    return ExcursionAcceptance(
        lower=float(lower),
        upper=float(upper),
        mean=m,
        duration_s=float(duration_s),
        sigma=sigma,
        sigma_dot=sigma_dot,
        upcrossings_upper=float(n2),
        downcrossings_lower=float(n1),
        mean_excursions=float(n),
        p_no_excursion=float(np.exp(-n)),  # (8.84) from the Poisson law (8.83)
        mean_time_between_s=float(between),
        correlation_time_s=tau_k,
        poisson_valid=bool(between > tau_k),
    )


def tolerance_for_risk(
    model: CorrelationModel,
    p_no_excursion: float,
    duration_s: float,
    mean_offset: float = 0.0,
) -> float:
    """Half-width eps of the band (a - eps, a + eps) (8.79) for which a reading with mean
    a + ``mean_offset`` shows no excursion in ``duration_s`` with probability
    ``p_no_excursion`` (the inverse problem of seed 004 eqs 8.84, 8.88; alpha in the seed).

    With mean_offset = 0 this is the seed's setting; an offset at the edge of the technical
    conditions gives the risk of accepting an instrument that is out of them."""
    if not 0 < p_no_excursion < 1:
        raise ValueError(f"p_no_excursion must be in (0, 1), got {p_no_excursion}")
    sigma, _ = _rates(model)

    def gap(eps: float) -> float:
        band = excursion_acceptance(model, -eps, eps, duration_s, mean_offset)
        return band.p_no_excursion - p_no_excursion

    lo = abs(mean_offset) + 1e-9 * sigma  # the band must not be empty
    if gap(lo) > 0:
        raise AnalysisError(
            f"even a band that ends at the mean gives P(no excursion) > {p_no_excursion}: "
            "the control time is too short for this risk"
        )
    hi = lo + sigma
    while gap(hi) < 0:
        hi += sigma
    return float(brentq(gap, lo, hi, xtol=1e-12 * sigma))
