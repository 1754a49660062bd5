"""Acceptance of an instrument by excursions of its reading out of a tolerance band (Sveshnikov
§8.3 item 1, eqs 8.79-8.89).

The reading Y(t) = a + X(t) is Gaussian with correlation function K of X; alpha is the
probability that Y stays inside (b1, b2) for the whole control time T. How it is found depends
on K, and the result says which method gave it and how far it can be trusted:

- exponential K = sigma^2 e^(-mu|tau|): X is a Markov (Ornstein-Uhlenbeck) process and alpha
  follows exactly from the Kolmogorov equation with absorbing bounds, the route §8.3 names for
  this correlation (Rice's formula does not apply: the reading crosses a level infinitely often);
- smooth K = sigma^2 e^(-mu|tau|)(cos(beta tau) + mu/beta sin(beta |tau|)): Rice's mean numbers
  of crossings (8.80-8.88). The Poisson law e^(-n) (8.84) treats excursions as independent; a
  narrow-band reading crosses in clusters and Poisson then understates alpha (2.5x in case a of
  validation/excursions_mc.py), while Vanmarcke's (1975) correction, which counts the first
  crossing of each cluster, overstates it as n grows. Against that simulation grid (damping
  0.02-1, nearer bound 2-3.5 sigma from the mean, n 0.1-3), P(start inside) e^(-n) came within
  10 % for a broad band (q >= 0.5) up to n = 1 and Vanmarcke's value for any band up to n = 0.3.
  Beyond n = 1, up to n = 3, a broad band's P(start inside) e^(-n) is the best estimate: within
  17 % of simulation either way (20000 paths per case, q 0.64-0.77, bounds 2-3 sigma, n 1.5-3),
  where the guaranteed bound P(start inside) - n is the vacuous 0. Elsewhere alpha is given as a
  lower bound (the risk 1 - alpha as an upper bound).
"""

from dataclasses import asdict, dataclass

import numpy as np

from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.noise import CorrelationModel

# Regions of the smooth model checked by validation/excursions_mc.py (damping
# mu / sqrt(mu^2 + beta^2) 0.02-1, i.e. q 0.16-0.77; nearer bound 2-3.5 sigma from the mean):
CHECKED_MIN_LEVEL = 2.0  # nearer bound from the mean, in sigma, for every region
# P(start inside) e^(-n) within 10 % of simulation: a broad band, crossings nearly independent
POISSON_MIN_BANDWIDTH = 0.5
POISSON_MAX_EXCURSIONS = 1.0
# Vanmarcke's alpha within 10 % of simulation
VANMARCKE_MIN_BANDWIDTH = 0.15
VANMARCKE_MAX_EXCURSIONS = 0.3
# P(start inside) e^(-n) within 17 % of simulation, either way, for a broad band up to this n
POISSON_ESTIMATE_MAX_EXCURSIONS = 3.0
POISSON_ESTIMATE_ERROR = 0.17
# P(start inside) e^(-n) below the simulated alpha for every n: a narrow band, crossings cluster
CLUSTERING_MAX_BANDWIDTH = 0.35

_GRID_STEP = 0.01  # finite-difference step in sigma: alpha within ~1e-5 (relative) of the limit
_MIN_NODES = 16
_MAX_MODES = 400  # enough for s >= 1e-4; below, the left-out modes change alpha by < 1e-4
_NEGLIGIBLE = 60.0  # modes decayed by e^(-60) are left out
_FAR = 8.0  # a bound beyond 8 sigma is reached at a rate below e^(-32): moved in to 8 sigma


@dataclass(frozen=True)
class RiceCrossings:
    """Rice's expected crossings of a differentiable reading in the control time (8.80-8.88)
    and the two estimates of alpha built on them: Poisson's e^(-n) (8.84) and Vanmarcke's.
    ``bandwidth`` is Vanmarcke's q = sqrt(1 - lambda_1^2 / (lambda_0 lambda_2)) of the spectral
    moments: near 0 for a narrow-band (ringing) reading, whose crossings cluster."""

    sigma_dot: float
    upcrossings_upper: float
    downcrossings_lower: float
    mean_excursions: float
    bandwidth: float
    p_poisson: float
    p_vanmarcke: float


@dataclass(frozen=True)
class ExcursionAcceptance:
    """alpha = P(no excursion out of (lower, upper) during ``duration_s``) = ``p_no_excursion``.

    ``method``: "kolmogorov" (exponential correlation, exact to ~1e-5); for the smooth one an
    approximation that came within 10 % of simulation in this region, "poisson" (P(start inside)
    e^(-n), broad band) or "vanmarcke"; "poisson-estimate", the same law where it came within
    17 % (a broad band, 1 < n <= 3: the best estimate where the guaranteed bound is the vacuous
    P(start inside) - n < 0); or, when ``is_bound``, a lower bound: "poisson" (narrow
    band: below every simulated value) or "rice" (P(start inside) - n, which always holds: the
    probability of any exit is at most the expected number of exits). ``rice`` holds Rice's
    numbers for the smooth model (None for the exponential one)."""

    lower: float
    upper: float
    mean: float
    duration_s: float
    sigma: float
    p_start_inside: float
    p_no_excursion: float
    method: str
    is_bound: bool
    rice: RiceCrossings | None

    @property
    def risk(self) -> float:
        """P(at least one excursion) = 1 - alpha; an upper bound when alpha is a lower one."""
        return 1.0 - self.p_no_excursion

    @property
    def method_note(self) -> str:
        """What the number is, in words for the report."""
        return _METHOD_NOTES[self.method, self.is_bound]

    def to_dict(self) -> dict:
        return {**asdict(self), "risk": self.risk, "method_note": self.method_note}


_METHOD_NOTES = {
    ("kolmogorov", False): "exact: Kolmogorov equation for the exponential correlation",
    ("poisson", False): "Poisson law with P(start inside), within 10 % of simulation here",
    ("vanmarcke", False): "Vanmarcke's clustering correction, within 10 % of simulation here",
    ("poisson-estimate", False): (
        "best estimate: Poisson law with P(start inside), within "
        f"{100 * POISSON_ESTIMATE_ERROR:.0f} % of simulation either way for a broad band up to "
        f"n = {POISSON_ESTIMATE_MAX_EXCURSIONS:g} (the guaranteed lower bound, P(start inside) "
        "minus Rice's expected excursions, is below 0 here)"
    ),
    ("poisson", True): "lower bound: P(start inside) e^(-n), below every simulated narrow band",
    ("rice", True): "lower bound: P(start inside) minus Rice's expected excursions",
}


def spectral_bandwidth(model: CorrelationModel) -> float:
    """Vanmarcke's q of the smooth model, in closed form. Its spectral density is that of a
    damped oscillator driven by white noise, S(w) ~ 1 / ((w0^2 - w^2)^2 + 4 mu^2 w^2),
    w0^2 = mu^2 + beta^2, whose moments are lambda_0 = sigma^2, lambda_2 = sigma^2 w0^2 (8.86) and
    lambda_1 = sigma^2 w0^2 (2 / pi) arctan(beta / mu) / beta (-> 2 sigma^2 mu / pi at beta = 0)."""
    if not model.is_smooth:
        raise AnalysisError("the exponential correlation has no finite spectral moment lambda_2")
    mu, beta = model.decay_per_s, model.frequency_rad_s
    arc = np.arctan(beta / mu) / beta if beta > 0 else 1.0 / mu
    mean_frequency = 2 / np.pi * arc * (mu**2 + beta**2)  # lambda_1 / lambda_0
    return float(np.sqrt(max(1.0 - mean_frequency**2 / (mu**2 + beta**2), 0.0)))


def _markov_no_excursion(a: float, b: float, s: float) -> float:
    """alpha of the standardised Ornstein-Uhlenbeck process Z (K = e^(-|s|)) inside (a, b) over
    the dimensionless time s = mu T (Sveshnikov §8.3, before eq 8.80: the Kolmogorov equation).

    The survival u(z, s) = P(no exit | Z(0) = z) obeys the backward equation u_s = -z u_z + u_zz,
    u(a) = u(b) = 0, u(z, 0) = 1, and alpha = integral_a^b phi(z) u(z, s) dz over the stationary
    start. With v = sqrt(phi) u the operator is the symmetric -v'' + (z^2/4 - 1/2) v, so
    alpha = sum_k c_k^2 e^(-lambda_k s), c_k = <sqrt(phi), psi_k>: the eigenpairs of its
    finite-difference matrix (tridiagonal, scipy.linalg.eigh_tridiagonal)."""
    from scipy.linalg import eigh_tridiagonal
    from scipy.stats import norm

    # Kolmogorov's backward equation (Sveshnikov §8.3 before eq 8.80, his eq 1.147), seed 004
    a, b = max(a, -_FAR), min(b, _FAR)
    if not b > a:
        return 0.0
    n = max(int(np.ceil((b - a) / _GRID_STEP)), _MIN_NODES)
    h = (b - a) / n
    z = a + h * np.arange(1, n)
    potential = z**2 / 4 - 0.5
    off = np.full(n - 2, -1 / h**2)
    # lambda_k ~ (k pi / (b - a))^2 + k: the modes below e^(-60) decay, at most _MAX_MODES
    modes = (b - a) / np.pi * np.sqrt(_NEGLIGIBLE / s) + 10
    last = int(min(modes, _MAX_MODES, n - 1)) - 1
    lam, psi = eigh_tridiagonal(2 / h**2 + potential, off, select="i", select_range=(0, last))
    # the 3-point -v'' is -v'' - (h^2/12) v'''' + ...: adding (h^2/12) |psi''|^2 with
    # psi'' = (V - lambda) psi makes lambda O(h^4) (its O(h^2) error would grow with s)
    lam += h**2 / 12 * np.sum(((potential[:, None] - lam) * psi) ** 2, axis=0)
    c = np.sqrt(h) * (np.sqrt(norm.pdf(z)) @ psi)
    return float(np.sum(c**2 * np.exp(-lam * s)))


def _rice(
    model: CorrelationModel, a: float, b: float, duration_s: float, p_inside: float
) -> RiceCrossings:
    """Rice's numbers for the standardised bounds a < b (in sigma from the mean) and Vanmarcke's
    alpha = P(start inside) e^(-T h) with the hazard of first crossings in a cluster

    h T = n (1 - e^(-n_E / n)) / (1 - e^(-r^2 / 2))   (Vanmarcke 1975 eq 29, double barrier;
    with q^1.2 as in Der Kiureghian 1980 eq 2), n_E = sqrt(2 pi) q^1.2 r nu_0 T e^(-r^2 / 2) the
    envelope's up-crossings of the nearer bound r, nu_0 = sigma_v / (2 pi sigma). With a
    symmetric band this is Vanmarcke's formula; with an asymmetric one the clusters are counted
    on the envelope at the nearer bound and n keeps both."""
    sigma_dot = float(np.sqrt(model.derivative_variance))
    nu0_t = duration_s * sigma_dot / (2 * np.pi * np.sqrt(model.variance))  # (8.87) w/o Gaussian
    n2 = nu0_t * np.exp(-(b**2) / 2)  # (8.80, 8.87)
    n1 = nu0_t * np.exp(-(a**2) / 2)  # (8.81)
    n = n1 + n2  # (8.82; 8.88 for a mid-band mean)
    q = spectral_bandwidth(model)
    r = min(-a, b)
    p_vanmarcke = 0.0  # the mean is not inside the band
    if r > 0:
        envelope = np.sqrt(2 * np.pi) * q**1.2 * r * nu0_t * np.exp(-(r**2) / 2)
        # first crossings of clusters (Vanmarcke 1975 eq 29); n underflows 40 sigma out
        clusters = n * -np.expm1(-envelope / n) / -np.expm1(-(r**2) / 2) if n > 0 else 0.0
        p_vanmarcke = p_inside * np.exp(-clusters)
    return RiceCrossings(
        sigma_dot=sigma_dot,
        upcrossings_upper=float(n2),
        downcrossings_lower=float(n1),
        mean_excursions=float(n),
        bandwidth=q,
        p_poisson=float(np.exp(-n)),  # (8.84) from the Poisson law (8.83)
        p_vanmarcke=float(p_vanmarcke),
    )


def _smooth_choice(rice: RiceCrossings, level: float, p_inside: float) -> tuple[float, str, bool]:
    """alpha, method and whether it is only a lower bound, by the region checked by simulation."""
    n, q = rice.mean_excursions, rice.bandwidth
    poisson = p_inside * rice.p_poisson  # (8.84) for a start inside the band
    if level >= CHECKED_MIN_LEVEL:
        if q >= POISSON_MIN_BANDWIDTH and n <= POISSON_MAX_EXCURSIONS:
            return poisson, "poisson", False
        if q >= VANMARCKE_MIN_BANDWIDTH and n <= VANMARCKE_MAX_EXCURSIONS:
            return rice.p_vanmarcke, "vanmarcke", False
        if q >= POISSON_MIN_BANDWIDTH and n <= POISSON_ESTIMATE_MAX_EXCURSIONS:
            return poisson, "poisson-estimate", False
        if q <= CLUSTERING_MAX_BANDWIDTH:
            return poisson, "poisson", True
    return max(p_inside - n, 0.0), "rice", True


def excursion_acceptance(
    model: CorrelationModel,
    lower: float,
    upper: float,
    duration_s: float,
    mean: float | None = None,
) -> ExcursionAcceptance:
    """alpha for a reading with correlation ``model`` and mean ``mean`` (default: the middle of
    the band) inside (``lower``, ``upper``) for ``duration_s`` (Sveshnikov §8.3, eqs 8.79-8.89),
    starting from the stationary distribution (a start outside the band counts as an
    excursion). The white part of the model is left out."""
    from scipy.stats import norm

    if not upper > lower:
        raise ValueError(f"tolerance band ({lower}, {upper}) is empty")
    if not duration_s > 0:
        raise ValueError(f"control time must be positive, got {duration_s}")
    sigma = float(np.sqrt(model.variance))
    m = (lower + upper) / 2 if mean is None else float(mean)
    a, b = (lower - m) / sigma, (upper - m) / sigma
    p_inside = float(norm.cdf(b) - norm.cdf(a))  # the band (8.79) at t = 0
    rice = None
    if model.is_smooth:
        rice = _rice(model, a, b, duration_s, p_inside)
        alpha, method, is_bound = _smooth_choice(rice, min(-a, b), p_inside)
    else:
        alpha = _markov_no_excursion(a, b, model.decay_per_s * duration_s)
        method, is_bound = "kolmogorov", False
    return ExcursionAcceptance(
        lower=float(lower),
        upper=float(upper),
        mean=m,
        duration_s=float(duration_s),
        sigma=sigma,
        p_start_inside=p_inside,
        p_no_excursion=float(alpha),
        method=method,
        is_bound=is_bound,
        rice=rice,
    )


def tolerance_for_risk(
    model: CorrelationModel,
    p_no_excursion: float,
    duration_s: float,
    mean_offset: float = 0.0,
) -> float:
    """Half-width eps of the band (a - eps, a + eps) (8.79) for which a reading with mean
    a + ``mean_offset`` shows no excursion in ``duration_s`` with probability
    ``p_no_excursion`` (alpha in Sveshnikov §8.3; the inverse problem of eqs 8.84, 8.88), by the
    same method as ``excursion_acceptance``. Where that method changes with eps (a lower bound
    outside a region checked by simulation, an estimate inside it) alpha jumps upwards and the
    answer may be the edge of that region.

    With mean_offset = 0 this is the book's setting; an offset at the edge of the technical
    conditions gives the risk of accepting an instrument that is out of them."""
    from scipy.optimize import brentq

    if not 0 < p_no_excursion < 1:
        raise ValueError(f"p_no_excursion must be in (0, 1), got {p_no_excursion}")
    sigma = float(np.sqrt(model.variance))

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
