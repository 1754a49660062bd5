"""The random part of a stationary reading (seed 004, Sveshnikov §8.3): correlation function and
spectral density, fitted correlation models with their correlation time, hidden harmonics, the
sampling interval, and a one-call characterisation for the report. Readings are uniformly
sampled every ``dt_s`` seconds; values keep the reading's unit (deg for heading)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from gyrostand.analysis.allan import AllanDeviation, allan_deviation
from gyrostand.analysis.effective import MAX_CORRELATION
from gyrostand.analysis.errors import AnalysisError


def _lists(obj: object) -> dict:
    """Dataclass fields as JSON-ready values (arrays to lists, nested results to dicts)."""
    out = {}
    for name, value in vars(obj).items():
        if isinstance(value, np.ndarray):
            value = value.tolist()
        elif isinstance(value, tuple):
            value = [v.to_dict() if hasattr(v, "to_dict") else v for v in value]
        elif hasattr(value, "to_dict"):
            value = value.to_dict()
        out[name] = value
    return out


BIAS_ITERATIONS = 50  # fits of `fit_correlation`: 4-20 were needed on simulated records

# --- correlation function ------------------------------------------------------------------


@dataclass(frozen=True)
class CorrelationEstimate:
    """K^(tau) at lags ``lag_s`` (unit^2), from ``n`` readings every ``dt_s`` from which the
    polynomial of degree ``trend_degree`` in time was removed (0: the mean); ``lengths``: the
    readings of each record when several were pooled (empty: one record of ``n``)."""

    lag_s: np.ndarray
    covariance: np.ndarray
    dt_s: float
    n: int
    trend_degree: int = 0
    lengths: tuple[int, ...] = ()

    @property
    def records(self) -> tuple[int, ...]:
        """The readings of each record behind the estimate."""
        return self.lengths or (self.n,)

    def to_dict(self) -> dict:
        return _lists(self)


def correlation_function(
    reading: np.ndarray,
    dt_s: float,
    max_lag_s: float | None = None,
    trend_degree: int = 0,
    others: Sequence[np.ndarray] = (),
) -> CorrelationEstimate:
    """K^(l dt) = 1/(N - l) sum_j r_j r_(j+l) (seed 004 eq 8.92, the sampled form of 8.93), by
    FFT, r the reading less its least-squares polynomial of degree ``trend_degree`` (0: the
    mean x_mean, as in 8.92). Default lags up to a tenth of the record, where it is still
    steady. ``others``: further records of the same stationary reading (every ``dt_s``, each
    less its own trend), pooled: sum over the records of sum_j r_j r_(j+l), over the sum of
    their N - l (a correlation function is an average over realisations, 8.92 the time average
    standing in for it; a record shorter than a lag adds nothing there)."""
    from scipy import signal

    records = [np.asarray(x, dtype=float).reshape(-1) for x in (reading, *others)]
    n = records[0].size
    max_lag = n // 10 if max_lag_s is None else int(round(max_lag_s / dt_s))
    if not 1 <= max_lag < n:
        raise ValueError(f"max lag of {max_lag} readings needs 1 <= lag < {n}")
    lags = np.arange(max_lag + 1)
    products, pairs = np.zeros(max_lag + 1), np.zeros(max_lag + 1)
    for x in records:
        basis = _trend_basis(x.size, trend_degree)
        xc = x - basis @ (basis.T @ x)
        full = signal.correlate(xc, xc, mode="full", method="fft")[x.size - 1 :]
        products[: min(full.size, lags.size)] += full[: lags.size]
        pairs += np.maximum(x.size - lags, 0)
    lengths = tuple(x.size for x in records) if others else ()
    return CorrelationEstimate(
        lags * dt_s, products / pairs, float(dt_s), sum(map(len, records)), trend_degree, lengths
    )


def _trend_basis(n: int, degree: int) -> np.ndarray:
    """Orthonormal basis Q (n x (degree + 1)) of the polynomials of ``degree`` on n equally
    spaced times: the trend removed is Q Q^T x."""
    q, _ = np.linalg.qr(np.vander(np.linspace(-1.0, 1.0, n), degree + 1))
    return q


def expected_covariance(model: CorrelationModel, est: CorrelationEstimate) -> np.ndarray:
    """E[K^] at the lags of ``est`` for a reading with correlation ``model`` (its white part
    included): what `correlation_function` gives on average. K^ is of r = M x, M = I - Q Q^T the
    removal of the trend (`_trend_basis`), so with Sigma the readings' covariance and P = Sigma Q

        E[r_j r_(j+l)] = K(l dt) - (Q P^T + P Q^T - Q (Q^T P) Q^T)_(j, j+l),

    summed over j and divided by N - l as in eq 8.92 (pooled records: each record's sums over
    the sum of their N - l, as `correlation_function` pools them). The removed part matters
    over a record a few correlation times long: on 420 s of an exponential reading with
    1/mu = 20 s, less the line, K^ at 20 s came out 0.27 sigma^2 where K is 0.37 sigma^2
    (fitted mu 0.087 for 0.05). Fitting this expectation, not K itself, to K^ (as the debiased
    Whittle likelihood of Sykulski et al. 2019 fits the expected periodogram) removes that
    bias."""
    from scipy import signal
    from scipy.linalg import matmul_toeplitz

    last = est.lag_s.size
    lags = np.arange(last)
    total, pairs = np.zeros(last), np.zeros(last)
    for n in sorted(set(est.records)):
        q = _trend_basis(n, est.trend_degree)
        column = model(np.arange(n) * est.dt_s)
        column[0] += model.white_variance
        p = matmul_toeplitz(column, q)  # Sigma Q: Sigma is Toeplitz (a stationary reading)
        qg = q @ (q.T @ p)

        def lagged(a: np.ndarray, b: np.ndarray, n: int = n) -> np.ndarray:
            """sum_j a_j b_(j+l) for l = 0 .. last - 1 (0 beyond the record)."""
            full = signal.correlate(b, a, mode="full", method="fft")[n - 1 :]
            return np.pad(full, (0, max(last - full.size, 0)))[:last]

        removed = sum(
            lagged(q[:, c], p[:, c]) + lagged(p[:, c], q[:, c]) - lagged(qg[:, c], q[:, c])
            for c in range(q.shape[1])
        )
        count = est.records.count(n)
        within = np.maximum(n - lags, 0)
        total += count * (np.pad(column, (0, max(last - n, 0)))[:last] * within - removed)
        pairs += count * within
    return total / pairs


@dataclass(frozen=True)
class CorrelationModel:
    """Correlation function of the reading (unit^2):

    exponential, ``frequency_rad_s`` None: K = sigma^2 e^(-mu|tau|) (seed 004, before 8.79);
    smooth: K = sigma^2 e^(-mu|tau|) (cos(beta tau) + mu/beta sin(beta |tau|)), the correlation of
    a damped second-order system driven by white noise, differentiable at 0 as Rice's formula
    needs (the exponential is not: its derivative has infinite variance).
    ``white_variance`` is the extra variance at lag 0 alone (uncorrelated reading noise)."""

    variance: float
    decay_per_s: float
    frequency_rad_s: float | None = None
    white_variance: float = 0.0

    @property
    def is_smooth(self) -> bool:
        return self.frequency_rad_s is not None

    def __call__(self, tau_s: np.ndarray | float) -> np.ndarray:
        tau = np.abs(np.asarray(tau_s, dtype=float))
        envelope = self.variance * np.exp(-self.decay_per_s * tau)
        if not self.is_smooth:
            return envelope
        beta = self.frequency_rad_s
        # mu/beta sin(beta tau) = mu tau sinc(beta tau / pi): finite as beta -> 0
        sine = self.decay_per_s * tau * np.sinc(beta * tau / np.pi)
        return envelope * (np.cos(beta * tau) + sine)

    @property
    def derivative_variance(self) -> float:
        """sigma_v^2 = -K''(0) of the derivative (seed 004 eq 8.86): sigma^2 (mu^2 + beta^2) for
        the smooth model, infinite for the exponential."""
        if not self.is_smooth:
            return float("inf")
        return self.variance * (self.decay_per_s**2 + self.frequency_rad_s**2)

    @property
    def correlation_time_s(self) -> float:
        """tau_k = (1/sigma^2) integral_0^inf |K(tau)| d tau (seed 004 eq 8.89); 1/mu for the
        exponential, for the smooth model K's closed-form integral between its zeros."""
        if not self.is_smooth or self.frequency_rad_s == 0:
            return (1.0 if not self.is_smooth else 2.0) / self.decay_per_s
        mu, beta = self.decay_per_s, self.frequency_rad_s
        # K changes sign at beta tau = pi - arctan(beta / mu) + k pi; e^(-50) is negligible
        end = 50.0 / mu
        zeros = np.arange((np.pi - np.arctan(beta / mu)) / beta, end, np.pi / beta)
        edges = np.concatenate([[0.0], zeros, [end]])
        return float(np.sum(np.abs(np.diff(self._primitive(edges)))))

    def _primitive(self, tau: np.ndarray) -> np.ndarray:
        """F with F' = K / sigma^2 of the smooth model (eq 8.89's integrand, tau >= 0):
        F = e^(-mu tau) (a cos(beta tau) + b sin(beta tau)), a = -2 mu / (mu^2 + beta^2),
        b = (beta^2 - mu^2) / (beta (mu^2 + beta^2)); b sin(beta tau) written with sinc, finite
        as beta -> 0. In closed form rather than scipy's quad: the same value to rounding,
        without importing scipy.integrate into the report (0.2 s of CPU)."""
        mu, beta = self.decay_per_s, self.frequency_rad_s or 0.0
        w2 = mu**2 + beta**2
        sine = (beta**2 - mu**2) / w2 * tau * np.sinc(beta * tau / np.pi)
        return np.exp(-mu * tau) * (-2 * mu / w2 * np.cos(beta * tau) + sine)

    def to_dict(self) -> dict[str, float | None]:
        return {
            "variance": self.variance,
            "decay_per_s": self.decay_per_s,
            "frequency_rad_s": self.frequency_rad_s,
            "white_variance": self.white_variance,
            "correlation_time_s": self.correlation_time_s,
            "derivative_variance": self.derivative_variance,
        }


def _efolding_decay(est: CorrelationEstimate) -> float:
    """Rough mu: inverse of the first lag where K drops below K(dt)/e."""
    below = np.flatnonzero(est.covariance[1:] < est.covariance[1] / np.e)
    lag = est.lag_s[1 + below[0]] if below.size else est.lag_s[-1]
    return 1.0 / max(lag, est.dt_s)


def fit_correlation(est: CorrelationEstimate, smooth: bool = False) -> CorrelationModel:
    """Least-squares fit of the exponential (seed 004, before 8.79 and 8.89) or smooth model to
    K^ at lags dt .. 5/mu, allowing for the share of K that the removed mean or trend took
    (`expected_covariance`): K is fitted to K^ plus that share at the previous fit until the
    model repeats, where K^ equals its expectation under the model. (Fitting the expectation
    itself did as well over 200 simulated 420 s records, median mu 0.057 against 0.056 here,
    at 15x the cost on a 10 h record: the expectation is a pass over the whole record, needed
    here once an iteration.)
    The correlation time is at most the longest lag estimated: beyond it a slow component is
    not told from the trend removed. Lag 0 is left out: its excess over the fit is
    ``white_variance`` (of which the removed trend took (degree + 1) / N)."""
    from scipy.optimize import curve_fit

    mu0 = _efolding_decay(est)
    last = min(est.lag_s.size - 1, max(5, int(np.ceil(5.0 / (mu0 * est.dt_s)))))
    tau, k = est.lag_s[1 : last + 1], est.covariance[1 : last + 1]
    var0 = max(float(est.covariance[1]), np.finfo(float).tiny)
    lags = replace(est, lag_s=est.lag_s[: last + 1], covariance=est.covariance[: last + 1])
    lower = [0.0, 1.0 / est.lag_s[-1]] + ([0.0] if smooth else [])

    def model(t: np.ndarray, *params: float) -> np.ndarray:
        return CorrelationModel(*params)(t)

    # several start values of beta: the smooth fit has local minima
    starts = [(var0, mu0, b * mu0) for b in (0.0, 0.5, 2.0, 5.0)] if smooth else [(var0, mu0)]
    removed, previous = np.zeros(last + 1), None
    for _ in range(BIAS_ITERATIONS):
        target = k + removed[1:]
        fits = []
        for p0 in starts:
            try:
                params, _ = curve_fit(
                    model, tau, target, p0=p0, bounds=(lower, np.inf), maxfev=5000
                )
            except RuntimeError:
                continue
            fits.append((float(np.sum((model(tau, *params) - target) ** 2)), params))
        if not fits:
            raise AnalysisError("the correlation model did not converge from any start value")
        params = min(fits, key=lambda f: f[0])[1]
        fitted = CorrelationModel(*(float(p) for p in params))
        expected = expected_covariance(fitted, lags)
        removed = fitted(lags.lag_s) - expected
        if previous is not None and np.allclose(params, previous, rtol=1e-4, atol=0.0):
            break
        previous, starts = params, [tuple(params)]
    else:
        raise AnalysisError(
            f"the correlation model did not settle in {BIAS_ITERATIONS} fits allowing for the "
            "removed trend"
        )
    excess = float(est.covariance[0] - expected[0])  # the fit's: its white part is 0
    kept = 1.0 - len(est.records) * (est.trend_degree + 1) / est.n  # the trends took the rest
    white = max(excess / kept, 0.0)
    return CorrelationModel(
        fitted.variance, fitted.decay_per_s, fitted.frequency_rad_s, white_variance=white
    )


# --- spectrum and hidden harmonics ----------------------------------------------------------


def welch_dof(window: np.ndarray, n_segments: int, step: int) -> float:
    """Equivalent degrees of freedom nu of a Welch estimate (Welch 1967): each frequency is
    distributed as S(f) chi^2_nu / nu, nu = 2K / (1 + 2 sum_j (1 - j/K) rho_j^2), rho_j the
    overlap correlation of the window shifted by j steps."""
    j = np.arange(1, min(n_segments, -(-window.size // step)))  # shifts that still overlap
    rho = np.array([window[k * step :] @ window[: window.size - k * step] for k in j])
    rho /= window @ window
    return float(2 * n_segments / (1 + 2 * np.sum((1 - j / n_segments) * np.square(rho))))


@dataclass(frozen=True)
class Harmonic:
    """A periodic component a cos(nu t + phi) of the reading (seed 004 eq 8.90).

    ``amplitude`` from the spectral peak (its integrated power is a^2/2); ``amplitude_from_
    correlation`` from the cosine a^2/2 cos(nu tau) that K^ keeps at large lags (eq 8.91);
    ``false_alarm_probability``: chance that noise alone gives a peak this high anywhere in the
    spectrum (Bonferroni over the frequencies searched)."""

    frequency_hz: float
    amplitude: float
    amplitude_from_correlation: float
    peak_to_background: float
    false_alarm_probability: float

    def to_dict(self) -> dict[str, float]:
        return _lists(self)


@dataclass(frozen=True)
class HarmonicSearch:
    """Welch spectral density (unit^2/Hz, one-sided), its smooth background (running median),
    the detection threshold for the family-wise ``false_alarm`` level, and what crossed it."""

    frequency_hz: np.ndarray
    psd: np.ndarray
    background: np.ndarray
    threshold: np.ndarray
    dof: float
    false_alarm: float
    harmonics: tuple[Harmonic, ...]

    def to_dict(self) -> dict:
        return _lists(self)


def _refine_frequency(x: np.ndarray, dt_s: float, f0: float, half_width_hz: float) -> float:
    """Peak of the 4x zero-padded Hann periodogram of the whole record within f0 +- half_width,
    with parabolic interpolation of log power: resolution far below the Welch bin."""
    from scipy import signal

    f, p = signal.periodogram(x, fs=1 / dt_s, window="hann", nfft=4 * x.size)
    near = np.flatnonzero(np.abs(f - f0) <= half_width_hz)
    i = near[np.argmax(p[near])]
    if 0 < i < p.size - 1 and np.all(p[i - 1 : i + 2] > 0):
        a, b, c = np.log(p[i - 1 : i + 2])
        shift = 0.5 * (a - c) / (a - 2 * b + c) if a - 2 * b + c < 0 else 0.0
        return float(f[i] + shift * (f[1] - f[0]))
    return float(f[i])


_BACKGROUND_HALF_BINS = 15
_GUARD_BINS = 3  # a Hann peak between bins spreads over +-3 bins: kept out of its background
_MIN_BACKGROUND_BINS = 4
_HANN_ENBW_BINS = 1.5  # equivalent noise bandwidth of the Hann window


def _background(psd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Median of psd over the bins 3..15 away on both sides of each bin (guard band excluded),
    the window shrunk symmetrically near the ends since an off-centre window is biased on a
    sloping spectrum; NaN where fewer than 4 bins remain. Also the number of bins used."""
    n = psd.size
    offsets = np.arange(_GUARD_BINS, _BACKGROUND_HALF_BINS + 1)
    idx = np.arange(n)[:, None] + np.concatenate([-offsets[::-1], offsets])[None, :]
    reach = np.minimum(np.arange(n), n - 1 - np.arange(n))[:, None]
    used = np.abs(idx - np.arange(n)[:, None]) <= reach
    values = np.where(used, psd[np.clip(idx, 0, n - 1)], np.nan)
    counts = used.sum(axis=1)
    median = np.full(n, np.nan)
    enough = counts >= _MIN_BACKGROUND_BINS
    median[enough] = np.nanmedian(values[enough], axis=1)
    return median, counts


def find_harmonics(
    reading: np.ndarray,
    dt_s: float,
    false_alarm: float = 0.01,
    nperseg: int | None = None,
    correlation: CorrelationEstimate | None = None,
) -> HarmonicSearch:
    """Detect periodic components in a stationary reading (seed 004 eqs 8.90-8.91).

    The Welch spectrum (Hann, 50 % overlap, ``nperseg`` default N/8 rounded to a power of 2,
    at least 256) is divided by a running median of the bins around each one (guard band
    excluded), corrected for the median of chi^2_nu / nu. Noise alone makes that ratio
    ~ F(nu, nu_b), nu_b = (2/pi) (bins in the median / 1.5) nu for a median of Hann bins; a bin
    is a detection when the ratio exceeds the F quantile of level ``false_alarm`` / (bins
    searched: those with a background, not zero or Nyquist). On simulated noise records
    (exponential + white, 4096-36000 readings) 5-13 % had a false alarm at a nominal 0.1, 0-2 %
    at 0.01. A detected amplitude comes from the integrated peak (+-3 bins) and, as the seed
    does, from K^(tau) at lags in the second half of ``correlation`` (default:
    ``correlation_function`` of the reading), where the noise part must have died out.
    """
    from scipy import signal, stats

    x = np.asarray(reading, dtype=float).reshape(-1)
    if nperseg is None:
        nperseg = min(x.size, max(256, 2 ** int(np.log2(max(x.size // 8, 1)))))
    step = nperseg // 2
    f, psd = signal.welch(x, fs=1 / dt_s, window="hann", nperseg=nperseg, noverlap=nperseg - step)
    nu = welch_dof(signal.get_window("hann", nperseg), (x.size - nperseg) // step + 1, step)
    # zero and Nyquist bins are chi^2 with half the degrees of freedom: left out
    inner, sizes = _background(psd[1:-1])
    background = np.concatenate([[np.nan], inner / (stats.chi2.median(nu) / nu), [np.nan]])
    nu_b = np.concatenate([[np.nan], 2 / np.pi * sizes / _HANN_ENBW_BINS * nu, [np.nan]])
    searched = int(np.sum(np.isfinite(background)))
    threshold = background * stats.f.isf(false_alarm / searched, nu, nu_b)
    with np.errstate(invalid="ignore"):
        ratio = np.where(np.isfinite(background), psd / background, 0.0)
        peaks, _ = signal.find_peaks(np.where(psd > threshold, ratio, 0.0), height=0.0, distance=4)
    df = f[1] - f[0]
    if correlation is None:
        correlation = correlation_function(x, dt_s)
    freqs = [_refine_frequency(x, dt_s, f[i], df) for i in peaks]
    corr_amps = _amplitudes_from_correlation(correlation, freqs)
    harmonics = []
    for i, freq, corr_amp in zip(peaks, freqs, corr_amps, strict=True):
        lo, hi = max(i - 3, 1), min(i + 4, psd.size - 1)
        power = float((np.sum(psd[lo:hi]) - (hi - lo) * background[i]) * df)
        p_value = min(1.0, searched * float(stats.f.sf(ratio[i], nu, nu_b[i])))
        harmonics.append(
            Harmonic(freq, float(np.sqrt(max(2 * power, 0.0))), corr_amp, float(ratio[i]), p_value)
        )
    return HarmonicSearch(f, psd, background, threshold, nu, false_alarm, tuple(harmonics))


def _amplitudes_from_correlation(est: CorrelationEstimate, freqs: list[float]) -> list[float]:
    """a_j from K^(tau) ~ sum_j a_j^2/2 cos(2 pi f_j tau) at the larger half of the lags (8.91)."""
    if not freqs:
        return []
    far = est.lag_s >= est.lag_s[-1] / 2
    basis = np.cos(2 * np.pi * np.outer(est.lag_s[far], freqs))
    half_sq = np.linalg.lstsq(basis, est.covariance[far], rcond=None)[0]
    return [float(np.sqrt(2 * c)) if c > 0 else float("nan") for c in half_sq]


# --- sampling interval ----------------------------------------------------------------------


def correlation_estimate_variance(
    model: CorrelationModel, record_s: float, lag_s: float = 0.0, interval_s: float | None = None
) -> float:
    """Variance of K^(tau) of a Gaussian reading with correlation ``model`` over ``record_s``:
    of the continuous estimate 8.93 when ``interval_s`` is None, of the sampled estimate 8.92
    (readings every ``interval_s``) otherwise (seed 004, the comparison behind eq 8.94):

    D = (1/L^2) sum/integral over pairs of K^2(t - s) + K(t - s + tau) K(t - s - tau), L = T - tau.
    The white part of the model is left out (it does not depend on the interval)."""
    from scipy.integrate import quad

    length = record_s - lag_s

    def pair_term(eta: np.ndarray | float) -> np.ndarray:
        return model(eta) ** 2 + model(eta + lag_s) * model(eta - lag_s)

    if interval_s is None:
        end = min(length, 60.0 / model.decay_per_s + lag_s)  # K^2 ~ e^(-120) beyond
        points = [lag_s] if 0 < lag_s < end else None
        integral = quad(lambda e: (length - e) * pair_term(e), 0, end, points=points, limit=1000)[0]
        return float(2 * integral / length**2)
    m = int(np.floor(length / interval_s + 1e-9)) + 1
    reach = min(m - 1, int(np.ceil((60.0 / model.decay_per_s + lag_s) / interval_s)))
    r = np.arange(-reach, reach + 1)  # terms beyond are below e^(-120) of the largest
    return float(np.sum((m - np.abs(r)) * pair_term(r * interval_s)) / m**2)


def max_sampling_interval(
    model: CorrelationModel, record_s: float, factor: float = 1.1, lag_s: float = 0.0
) -> float:
    """Largest interval Delta for which the variance of the sampled estimate 8.92 stays within
    ``factor`` of that of the continuous one 8.93 (seed 004 eq 8.94), searched from
    tau_k / 1000 up to a tenth of the record (returned when never exceeded)."""
    from scipy.optimize import brentq

    if factor <= 1:
        raise ValueError(f"variance factor must exceed 1, got {factor}")
    continuous = correlation_estimate_variance(model, record_s, lag_s)

    def excess(interval: float) -> float:
        sampled = correlation_estimate_variance(model, record_s, lag_s, interval)
        return sampled / continuous - factor

    grid = np.geomspace(model.correlation_time_s / 1000, record_s / 10, 120)
    above = [excess(d) > 0 for d in grid]
    if not any(above):
        return float(grid[-1])
    k = above.index(True)
    if k == 0:
        return float(grid[0])
    return float(brentq(excess, grid[k - 1], grid[k], xtol=1e-6 * grid[k]))


@dataclass(frozen=True)
class SamplingAdvice:
    """Recommended reading interval (8.94) and whether successive observations are correlated:
    ``observation_correlation`` = K(interval) / K(0), ``correlated`` when it exceeds
    ``max_correlation``, which breaks the independence Cochran's and Fisher's tests assume."""

    interval_s: float
    factor: float
    observation_interval_s: float | None
    observation_correlation: float | None
    max_correlation: float
    correlated: bool

    def to_dict(self) -> dict:
        return _lists(self)


def sampling_advice(
    model: CorrelationModel,
    record_s: float,
    factor: float = 1.1,
    observation_interval_s: float | None = None,
    max_correlation: float = MAX_CORRELATION,
) -> SamplingAdvice:
    """``max_sampling_interval`` plus the correlation between successive observations."""
    rho = None
    if observation_interval_s is not None:
        rho = float(model(observation_interval_s) / (model.variance + model.white_variance))
    return SamplingAdvice(
        interval_s=max_sampling_interval(model, record_s, factor),
        factor=factor,
        observation_interval_s=observation_interval_s,
        observation_correlation=rho,
        max_correlation=max_correlation,
        correlated=rho is not None and abs(rho) > max_correlation,
    )


# --- one-call characterisation --------------------------------------------------------------


@dataclass(frozen=True)
class NoiseCharacterisation:
    """Everything the report shows about a stationary reading (seed 004 §8.3)."""

    correlation: CorrelationEstimate
    exponential: CorrelationModel
    smooth: CorrelationModel
    harmonics: HarmonicSearch
    allan: AllanDeviation
    sampling: SamplingAdvice

    def to_dict(self) -> dict:
        return _lists(self)


def characterise_noise(
    reading: np.ndarray,
    dt_s: float,
    *,
    false_alarm: float = 0.01,
    variance_factor: float = 1.1,
    observation_interval_s: float | None = None,
    trend_degree: int = 0,
    others: Sequence[np.ndarray] = (),
) -> NoiseCharacterisation:
    """Correlation (8.92), harmonics (8.90-8.91; their a^2/2 cos(nu tau) is removed from K^
    before the models are fitted), exponential and smooth models (8.89), Allan deviation and
    sampling advice (8.94) for one stationary, uniformly sampled reading; ``trend_degree``: the
    polynomial in time removed from it (1: the reading was detrended), which K^ removes again
    and the models' fit allows for (`expected_covariance`); ``others``: further records of the
    same reading, which K^ and so the models pool (the spectrum, harmonics, Allan deviation and
    sampling advice are of ``reading``)."""
    x = np.asarray(reading, dtype=float).reshape(-1)
    corr = correlation_function(x, dt_s, trend_degree=trend_degree, others=others)
    search = find_harmonics(x, dt_s, false_alarm, correlation=corr)
    residual = corr.covariance.copy()
    for h in search.harmonics:
        amp = h.amplitude_from_correlation if np.isfinite(h.amplitude_from_correlation) else 0.0
        residual -= amp**2 / 2 * np.cos(2 * np.pi * h.frequency_hz * corr.lag_s)
    noise_corr = replace(corr, covariance=residual)
    exponential = fit_correlation(noise_corr)
    return NoiseCharacterisation(
        correlation=corr,
        exponential=exponential,
        smooth=fit_correlation(noise_corr, smooth=True),
        harmonics=search,
        allan=allan_deviation(x, dt_s),
        sampling=sampling_advice(
            exponential, x.size * dt_s, variance_factor, observation_interval_s
        ),
    )
