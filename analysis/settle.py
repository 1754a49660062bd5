"""Settle point of a damped gyro oscillation from a short record (seed 003, Bezvesilna & Gura).

The reading after a step is modelled as (seed 003 eqs 2-4, time tau = t - t0 from the first
sample)

    alpha(t) = R + e^(-xi tau) (A_c sin(omega tau) + A_s cos(omega tau)),

linear in the state (R, A_c, A_s) when omega and xi are known. ``estimate_settle_point`` solves
the least-squares problem (eqs 5-6) on the record so far; it is cheap (one 3-column SVD) so the
acquisition layer can call it again on every new block of readings. The seed's eq 4 names the
sine coefficient A_s but its eq 5 and A_c = A cos(phi), A_s = A sin(phi) make it A_c; we follow
eq 5, so A sin(omega tau + phi) = A_c sin(omega tau) + A_s cos(omega tau).

The error terms of eqs 12-13 (third harmonic, damping, non-isochronism, frequency mismatch and a
deterministic disturbance) are in ``settle_error_terms``; ``SettleErrorTerms.compensate`` applies
alpha^ = R^ - sum dR^ (the equation after 13). The seed's equation 1 reads ``omega_0 sin alpha``;
its own non-isochronism p = omega_0 (1 - A^2/16) is that of ``omega_0^2 sin alpha``, which we use.
"""

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Self

import numpy as np

from gyrostand.analysis.errors import NonFiniteError, SingularDesignError
from gyrostand.analysis.nlsq import fit_nonlinear

_PHASE_TOL_RAD = 1e-9
SETTLE_CRITERIA = ("band", "estimate")


@dataclass(frozen=True)
class SettleOutcome:
    """How a series settled, as acquisition records it with the series: by the plan's band
    criterion (``criterion`` "band": it waited ``settle_s``) or by the compass's transient model
    ("estimate"; "compensated": observed during the transient, Bezvesilna & Gura). ``settle_s``
    counts stand seconds from the settle start; ``estimate_deg`` is the settle point the series
    starts from. For the model criteria: the estimate's standard error, since when it was stable
    and where, and when the band criterion held on the readings (``band_measured``) or is
    predicted to hold on the fitted transient (None: not within the plan's max_wait_s).
    ``step_ms`` is the stand time of the start/stop that began the series' transient (None: not
    seen in this run) and ``blocks`` the settle record, (start ms, end ms, mean heading deg) per
    block, so the analysis can fit the transient afterwards whatever the criterion."""

    criterion: str
    settle_s: float
    estimate_deg: float
    standard_error_deg: float | None = None
    stable_since_s: float | None = None
    stable_estimate_deg: float | None = None
    band_s: float | None = None
    band_measured: bool = True
    step_ms: int | None = None
    blocks: tuple[tuple[int, int, float], ...] = ()

    @property
    def saved_s(self) -> float | None:
        """Stand seconds saved against waiting for the band criterion (None: unknown)."""
        return None if self.band_s is None else self.band_s - self.settle_s

    def to_dict(self) -> dict[str, object]:
        """The stored record (the series' settle_outcome JSON column)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, record: dict[str, object]) -> Self:
        blocks = tuple(tuple(b) for b in record.get("blocks", ()))  # type: ignore[attr-defined]
        return cls(**{**record, "blocks": blocks})  # type: ignore[arg-type]


@dataclass(frozen=True)
class SettleEstimate:
    """Least-squares state of the settle model (seed 003 eqs 3-6), angles in degrees.

    ``settle_point_deg`` is R^ on the branch of the record's first reading (heading is unwrapped
    first, so near north it may lie outside [0, 360)). ``standard_error_deg`` is the standard
    error of R^ from S^2 (X^T X)^-1, multiplied by ``se_inflation`` for correlated reading noise
    (see ``variance_inflation``). ``amplitude_deg`` and
    ``phase_rad`` describe the oscillation at ``t0_s``; ``omega_se_rad_s`` and
    ``damping_se_per_s`` are set only when omega and xi were estimated too."""

    settle_point_deg: float
    standard_error_deg: float
    amplitude_deg: float
    phase_rad: float
    omega_rad_s: float
    damping_per_s: float
    t0_s: float
    record_s: float
    n: int
    residual_sd_deg: float
    se_inflation: float
    omega_se_rad_s: float | None = None
    damping_se_per_s: float | None = None

    def predict(self, t_s: np.ndarray) -> np.ndarray:
        """Model reading (deg) at the times ``t_s`` (seed 003 eq 3)."""
        tau = np.asarray(t_s, dtype=float) - self.t0_s
        return self.settle_point_deg + self.amplitude_deg * np.exp(
            -self.damping_per_s * tau
        ) * np.sin(self.omega_rad_s * tau + self.phase_rad)

    def to_dict(self) -> dict[str, float | int | None]:
        return asdict(self)


def observation_rows(tau_s: np.ndarray, omega_rad_s: float, damping_per_s: float) -> np.ndarray:
    """Rows [1, e^(-xi tau) sin(omega tau), e^(-xi tau) cos(omega tau)] (seed 003 eqs 3-5)."""
    tau = np.asarray(tau_s, dtype=float)
    decay = np.exp(-damping_per_s * tau)
    return np.column_stack(
        [np.ones_like(tau), decay * np.sin(omega_rad_s * tau), decay * np.cos(omega_rad_s * tau)]
    )


def check_solvability(tau_s: np.ndarray, omega_rad_s: float) -> None:
    """Raise SingularDesignError unless eq 6 has a unique solution (seed 003 eq 7).

    Eq 7 asks n >= 3 and lambda = omega Delta t != pi k. (Its extra value pi(1/2 + 2k) comes from
    a slip in the printed determinant, which is 2 sin(lambda)(cos(lambda) - 1), not
    2 sin(lambda) cos(2 lambda).) For any sampling the rows are independent exactly when the
    phases omega t_i hit at least three distinct points of the circle: a line meets it twice."""
    n = len(tau_s)
    if n < 3:
        raise SingularDesignError(
            f"settle estimate needs n >= 3 readings (Bezvesilna & Gura, eq 7), got {n}"
        )
    phases = omega_rad_s * np.asarray(tau_s, dtype=float)
    away_from_first = _circular_distance(phases, phases[0]) > _PHASE_TOL_RAD
    second = phases[np.argmax(away_from_first)]
    if not np.any(away_from_first & (_circular_distance(phases, second) > _PHASE_TOL_RAD)):
        lam = omega_rad_s * float(np.median(np.diff(tau_s)))
        raise SingularDesignError(
            f"readings fall on at most two phases of the oscillation: lambda = omega*dt = "
            f"{lam:.6g} rad is a multiple of pi (Bezvesilna & Gura, eq 7); change the sampling "
            "interval"
        )


def _circular_distance(phases: np.ndarray, reference: float) -> np.ndarray:
    return np.abs(np.mod(phases - reference + np.pi, 2 * np.pi) - np.pi)


def _lsq(rows: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solution of eq 6 and the unscaled covariance (X^T X)^-1, by SVD of X."""
    u, s, vt = np.linalg.svd(rows, full_matrices=False)
    if s[-1] <= s[0] * rows.shape[0] * np.finfo(float).eps:
        raise SingularDesignError(
            "settle model columns are linearly dependent (Bezvesilna & Gura, eq 7): record too "
            "short or sampled at a forbidden interval"
        )
    coef = vt.T @ ((u.T @ y) / s)
    return coef, (vt.T / s**2) @ vt


def _prepare(t_s: np.ndarray, heading_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t_s, dtype=float).reshape(-1)
    y = np.asarray(heading_deg, dtype=float).reshape(-1)
    if t.shape != y.shape:
        raise ValueError(f"t_s has {t.size} values, heading_deg {y.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise NonFiniteError("settle record contains a non-finite time or heading")
    return t, np.unwrap(y, period=360.0)


def _estimate(
    t: np.ndarray,
    residuals: np.ndarray,
    coef: np.ndarray,
    var_r_unscaled: float,
    omega: float,
    damping: float,
    n_params: int,
    omega_se: float | None = None,
    damping_se: float | None = None,
) -> SettleEstimate:
    dof = t.size - n_params
    s2 = float(np.sum(residuals**2)) / dof if dof > 0 else float("nan")
    inflation = np.sqrt(variance_inflation(residuals))
    se = np.sqrt(s2 * var_r_unscaled) * inflation
    return SettleEstimate(
        settle_point_deg=float(coef[0]),
        standard_error_deg=float(se),
        amplitude_deg=float(np.hypot(coef[1], coef[2])),  # A^ after eq 8
        phase_rad=float(np.arctan2(coef[2], coef[1])),  # phi^ after eq 8 (atan2, not arcsin)
        omega_rad_s=float(omega),
        damping_per_s=float(damping),
        t0_s=float(t[0]),
        record_s=float(t[-1] - t[0]),
        n=int(t.size),
        residual_sd_deg=float(np.sqrt(s2)),
        se_inflation=float(inflation),
        omega_se_rad_s=omega_se,
        damping_se_per_s=damping_se,
    )


def variance_inflation(residuals: np.ndarray) -> float:
    """Long-run variance factor 1 + 2 sum_k rho_k of the residuals, for noise that is
    exponentially correlated plus white (seed 004's model: rho_k = rho_1 phi^(k-1), k >= 1), so
    1 + 2 rho_1 / (1 - phi), phi from the lag where rho falls to rho_1 / 2. For AR(1) noise it is
    (1 + rho_1) / (1 - rho_1); never more than n (all readings equal). The residuals of a fit
    lose part of the slow noise, so the SE comes out low on short records: by ~10 % over 70
    noise correlation times, ~25 % over 20-35 (simulated exponential + white noise).
    Autocorrelation by FFT: BLAS dot products were 200x slower on a loaded machine."""
    from scipy import fft as sp_fft

    n = residuals.size
    power = np.abs(sp_fft.rfft(residuals, sp_fft.next_fast_len(2 * n, real=True))) ** 2
    acf = sp_fft.irfft(power)[: max(n // 4, 3)]
    if acf[0] <= 0 or acf[1] <= 0:
        return 1.0
    rho = acf / acf[0]
    below = np.flatnonzero(rho[2:] <= rho[1] / 2)
    k = below[0] + 2 if below.size else rho.size - 1
    phi = min((max(rho[k], 0.0) / rho[1]) ** (1.0 / (k - 1)), 1.0 - 1.0 / n)
    return float(min(1.0 + 2.0 * rho[1] / (1.0 - phi), n))


def estimate_settle_point(
    t_s: np.ndarray,
    heading_deg: np.ndarray,
    omega_rad_s: float,
    damping_per_s: float | None = None,
) -> SettleEstimate:
    """Settle point R^ of the record by linear least squares (seed 003 eqs 5-6, solvability 7).

    ``omega_rad_s`` is the (damped) angular frequency of the oscillation (eq 2); with
    ``damping_per_s`` (xi of eq 1) the basis is damped (eq 3), so a record shorter than one
    period suffices; without it the undamped model 4 is used."""
    t, y = _prepare(t_s, heading_deg)
    damping = 0.0 if damping_per_s is None else float(damping_per_s)
    tau = t - t[0]
    check_solvability(tau, omega_rad_s)
    rows = observation_rows(tau, omega_rad_s, damping)
    coef, xtx_inv = _lsq(rows, y)
    return _estimate(t, y - rows @ coef, coef, xtx_inv[0, 0], omega_rad_s, damping, 3)


def _damped_model(
    tau: np.ndarray, r: float, a_c: float, a_s: float, omega: float, xi: float
) -> np.ndarray:
    return observation_rows(tau, omega, xi) @ np.array([r, a_c, a_s])  # seed 003 eq 3


def _damped_jacobian(
    tau: np.ndarray, r: float, a_c: float, a_s: float, omega: float, xi: float
) -> np.ndarray:
    decay = np.exp(-xi * tau)
    sin, cos = np.sin(omega * tau), np.cos(omega * tau)
    osc = decay * (a_c * sin + a_s * cos)
    d_omega = decay * tau * (a_c * cos - a_s * sin)
    return np.column_stack([np.ones_like(tau), decay * sin, decay * cos, d_omega, -tau * osc])


def estimate_settle_point_free(
    t_s: np.ndarray,
    heading_deg: np.ndarray,
    omega0_rad_s: float,
    damping0_per_s: float = 0.0,
) -> SettleEstimate:
    """R^ with omega and xi estimated too (seed 003 eq 3 with all five unknowns), by the general
    nonlinear fitter from the linear solution at the start values ``omega0_rad_s``,
    ``damping0_per_s``. Needs a record of about a period or more to separate omega and xi."""
    t, y = _prepare(t_s, heading_deg)
    tau = t - t[0]
    start = estimate_settle_point(t, y, omega0_rad_s, damping0_per_s)
    a_c = start.amplitude_deg * np.cos(start.phase_rad)
    a_s = start.amplitude_deg * np.sin(start.phase_rad)
    fit = fit_nonlinear(
        _damped_model,
        tau,
        y,
        {
            "r": start.settle_point_deg,
            "a_c": a_c,
            "a_s": a_s,
            "omega": omega0_rad_s,
            "xi": damping0_per_s,
        },
        jacobian=_damped_jacobian,
        bounds={"omega": (0.0, np.inf), "xi": (0.0, np.inf)},
    )
    if not fit.converged:
        raise SingularDesignError(f"settle fit with free omega and xi failed: {fit.reason}")
    est = fit.estimates
    coef = np.array([est["r"], est["a_c"], est["a_s"]])
    return _estimate(
        t,
        fit.residuals,
        coef,
        fit.xtx_inv[0, 0],
        est["omega"],
        est["xi"],
        5,
        omega_se=fit.std_errors["omega"],
        damping_se=fit.std_errors["xi"],
    )


# --- error terms, seed 003 eqs 9-13 ----------------------------------------------------------


def d1_limit(u: float) -> float:
    """d1(u), u = omega0 T_c: weight of the t-proportional terms in dR^ (seed 003 eq 13)."""
    den = u * (u + np.sin(u)) - 8 * np.sin(u / 2) ** 2
    return float(((u + np.sin(u)) * np.sin(u / 2) - u**2 * np.cos(u / 2)) / den)


def d2_limit(u: float) -> float:
    """d2(u): weight of the third harmonic A0^3/192 sin 3(...) in dR^ (seed 003 eq 13)."""
    den = u * (u + np.sin(u)) - 8 * np.sin(u / 2) ** 2
    num = 3 * np.cos(u / 2) * np.sin(u) ** 2 - np.sin(1.5 * u) * (u + np.sin(u))
    return float(2 / 3 * num / den)


def settle_response(tau_s: np.ndarray, signal: np.ndarray, omega_rad_s: float) -> float:
    """dR^ caused by an error signal added to the record: the R-component of its least-squares
    fit (seed 003 eq 11; with a disturbance eps(t_i) it is d3 of eq 12)."""
    rows = observation_rows(tau_s, omega_rad_s, 0.0)
    return float(_lsq(rows, np.asarray(signal, dtype=float))[0][0])


def _grid(lam: float, n: int) -> np.ndarray:
    return lam * np.arange(n)  # omega0 t_i = lambda (i - 1), seed 003 eq 5


def d1_discrete(lam: float, n: int) -> float:
    """d1(lambda, n) of seed 003 eq 12, evaluated exactly through eq 11.

    The closed form printed in eq 12 is garbled in the source (it does not reproduce the
    least-squares solution, e.g. 1.148 instead of 1.062 at lambda = 0.5, n = 9), so we take the
    definition: dR^ for the signal -omega0 t cos(omega0 t + phi0) with the phase
    phi0 = pi/2 - (n - 1) lambda / 2 that makes sin(phi0 + (n - 1) lambda / 2) = 1."""
    x = _grid(lam, n)
    return settle_response(x, -x * np.cos(x + np.pi / 2 - x[-1] / 2), 1.0)


def d2_discrete(lam: float, n: int) -> float:
    """d2(lambda, n) of seed 003 eq 12 through eq 11 (printed form garbled, see d1_discrete):
    minus dR^ for sin 3(omega0 t + phi0) with sin 3(phi0 + (n - 1) lambda / 2) = 1."""
    x = _grid(lam, n)
    return -settle_response(x, np.sin(3 * (x + np.pi / 6 - x[-1] / 2)), 1.0)


def disturbance_limit(
    disturbance_deg: Callable[[float], float], omega0_rad_s: float, record_s: float
) -> float:
    """dR5^ for a disturbance eps(t) of the law of motion, Delta t -> 0 (seed 003 eq 13)."""
    from scipy.integrate import quad

    u = omega0_rad_s * record_s

    def integral(weight: Callable[[float], float]) -> float:
        return quad(lambda t: disturbance_deg(t) * weight(t), 0.0, record_s, limit=200)[0]

    i0 = integral(lambda t: 1.0)
    i_sin = integral(lambda t: np.sin(omega0_rad_s * t))
    i_cos = integral(lambda t: np.cos(omega0_rad_s * t))
    num = (u + np.sin(u)) * i0 - 4 * np.sin(u / 2) ** 2 * i_sin - 2 * np.sin(u) * i_cos
    return float(omega0_rad_s * num / (u * (u + np.sin(u)) - 8 * np.sin(u / 2) ** 2))


@dataclass(frozen=True)
class SettleErrorTerms:
    """The systematic errors dR1..dR5 of the settle point (seed 003 eq 13), degrees."""

    third_harmonic_deg: float  # dR1: sin(alpha) ~ alpha - alpha^3/6 (eq 9)
    damping_deg: float  # dR2: xi != 0 not modelled
    nonisochronism_deg: float  # dR3: p = omega0 (1 - A0^2/16)
    frequency_mismatch_deg: float  # dR4: omega used != omega0
    disturbance_deg: float  # dR5: eps(t)

    @property
    def total_deg(self) -> float:
        return (
            self.third_harmonic_deg
            + self.damping_deg
            + self.nonisochronism_deg
            + self.frequency_mismatch_deg
            + self.disturbance_deg
        )

    def compensate(self, settle_point_deg: float) -> float:
        """alpha^ = R^ - sum dR^ (seed 003, equation after 13)."""
        return settle_point_deg - self.total_deg

    def to_dict(self) -> dict[str, float]:
        return {**asdict(self), "total_deg": self.total_deg}


def settle_error_terms(
    amplitude_deg: float,
    phase_rad: float,
    omega0_rad_s: float,
    record_s: float,
    *,
    damping_per_s: float = 0.0,
    omega_used_rad_s: float | None = None,
    n_samples: int | None = None,
    disturbance_deg: Callable[[float], float] | None = None,
) -> SettleErrorTerms:
    """Errors of the undamped settle estimate (model 4) of a record of ``record_s`` seconds that
    starts with the oscillation A0 sin(omega0 t + phi0) (seed 003 eqs 12-13).

    ``omega_used_rad_s`` is the frequency the estimator used (default omega0). With
    ``n_samples`` the finite-n weights d1(lambda, n), d2(lambda, n) of eq 12 are used, else the
    limits d1(u), d2(u) of eq 13. ``disturbance_deg(t)`` is eps(t) (dR5); it is sampled on the
    record's grid when ``n_samples`` is given, integrated otherwise."""
    u = omega0_rad_s * record_s
    if n_samples is None:
        d1, d2 = d1_limit(u), d2_limit(u)
    else:
        lam = u / (n_samples - 1)
        d1, d2 = d1_discrete(lam, n_samples), d2_discrete(lam, n_samples)
    c = phase_rad + u / 2  # phi0 + (n - 1) lambda / 2 = phi0 + u / 2
    a_rad = np.radians(amplitude_deg)
    mismatch = 0.0 if omega_used_rad_s is None else omega_used_rad_s / omega0_rad_s - 1.0
    if disturbance_deg is None:
        d5 = 0.0
    elif n_samples is None:
        d5 = disturbance_limit(disturbance_deg, omega0_rad_s, record_s)
    else:
        tau = np.linspace(0.0, record_s, n_samples)
        d5 = settle_response(tau, np.vectorize(disturbance_deg)(tau), omega0_rad_s)
    return SettleErrorTerms(
        third_harmonic_deg=float(-d2 * amplitude_deg * a_rad**2 / 192 * np.sin(3 * c)),
        damping_deg=float(-d1 * damping_per_s / omega0_rad_s * amplitude_deg * np.cos(c)),
        nonisochronism_deg=float(d1 * amplitude_deg * a_rad**2 / 16 * np.sin(c)),
        frequency_mismatch_deg=float(d1 * mismatch * amplitude_deg * np.sin(c)),
        disturbance_deg=float(d5),
    )


def error_terms_for(
    estimate: SettleEstimate,
    omega0_rad_s: float,
    *,
    damping_per_s: float = 0.0,
    disturbance_deg: Callable[[float], float] | None = None,
) -> SettleErrorTerms:
    """Error terms of an undamped ``estimate`` at its own A^, phi^, record and frequency, for
    compensation with ``SettleErrorTerms.compensate`` (seed 003 eq 13)."""
    return settle_error_terms(
        estimate.amplitude_deg,
        estimate.phase_rad,
        omega0_rad_s,
        estimate.record_s,
        damping_per_s=damping_per_s,
        omega_used_rad_s=estimate.omega_rad_s,
        n_samples=estimate.n,
        disturbance_deg=disturbance_deg,
    )
