"""The standard's procedures (IMO A.424(XI), A.821(19), ISO 8728 / 22090-1): each measured value
with its uncertainty, from the readings of the run-ups.

- settling time: the compass's settling from switch-on fitted by the settle model of
  Bezvesilna & Gura (eq 3, omega and xi free: `estimate_settle_point_free`); the settling time
  is the last time the fitted reading lies outside +-half band of its settle point. Its
  standard uncertainty by the law of propagation (GUM, JCGM 100:2008, eq 10) from the fit's
  covariance, the sensitivities by central differences;
- settle point: the mean of the readings (the standard's 10 at 20 min), its error against the
  reference heading, U = k u with k = t(0.975, nu_eff) by Welch-Satterthwaite (GUM G.4.1);
  the RMS of the readings about it, U = 2 RMS / sqrt(2 (N - 1)) (GUM E.4.3);
- repeatability: the range of the settle points of the run-ups, u from theirs.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from gyrostand.analysis.quantiles import t_quantile
from gyrostand.analysis.settle import _damped_jacobian, estimate_settle_point_free

GRID_S = 1.0  # the fitted reading's grid when searching the last band exit, s
MAX_HORIZON = 10.0  # the fitted transient is followed past the record to at most 10x its length
MAX_FIT_READINGS = 20_000  # a longer record is thinned evenly to about this many readings
COVERAGE = 0.95  # expanded uncertainties: about 95 %
PROGRESS = "progress"  # the key of a stored procedure record of stages done, not results


@dataclass(frozen=True)
class SettlingTime:
    """Stand seconds from switch-on until the reading stays within +-half_band_deg of its
    settle point; u: standard uncertainty, U = 2 u; the fitted settle point with its SE, the
    fitted damped period and damping and the part of the record fitted."""

    value_s: float
    u_s: float
    half_band_deg: float
    settle_point_deg: float
    settle_point_se_deg: float
    period_s: float
    damping_per_s: float
    fit_from_s: float
    record_s: float

    @property
    def expanded_s(self) -> float:
        return 2.0 * self.u_s

    @property
    def settled(self) -> bool:
        """Whether the fitted reading settles at all (value_s is infinite otherwise)."""
        return math.isfinite(self.value_s)

    @property
    def extrapolated(self) -> bool:
        """Whether the settling time lies after the record's end (predicted by the fit)."""
        return self.value_s > self.record_s

    def to_dict(self) -> dict[str, Any]:
        """As stored (JSON: a settling time not reached is null)."""
        return {**asdict(self), "value_s": self.value_s if self.settled else None}

    @classmethod
    def from_dict(cls, record: dict[str, Any]) -> SettlingTime:
        value = record["value_s"]
        return cls(**{**record, "value_s": math.inf if value is None else value})


def _last_exit_s(theta: np.ndarray, t_s: np.ndarray, half_band_deg: float) -> float:
    """The last time the transient of the settle model (eq 3, parameters theta = R, A_c, A_s,
    omega, xi, time from the fit's start) lies outside +-half band; interpolated."""
    _, a_c, a_s, omega, xi = theta
    decay = np.exp(-xi * t_s)
    x = np.abs(decay * (a_c * np.sin(omega * t_s) + a_s * np.cos(omega * t_s))) - half_band_deg
    outside = np.flatnonzero(x > 0)
    if outside.size == 0:
        return float(t_s[0])
    i = int(outside[-1])
    if i + 1 >= t_s.size:
        return math.inf
    return float(t_s[i] + (t_s[i + 1] - t_s[i]) * x[i] / (x[i] - x[i + 1]))


def settling_time(
    t_s: np.ndarray,
    heading_deg: np.ndarray,
    half_band_deg: float,
    omega0_rad_s: float,
    damping0_per_s: float,
    fit_from_s: float,
) -> SettlingTime:
    """The settling time from a run-up's record (t from switch-on). The record from
    `fit_from_s` is fitted (the large first swing, where the precession is not yet isochronous,
    left out); the start values are the compass's damped frequency and damping."""
    keep = np.flatnonzero(t_s >= fit_from_s)
    keep = keep[:: max(1, keep.size // MAX_FIT_READINGS)]
    t, y = t_s[keep], heading_deg[keep]
    est = estimate_settle_point_free(t, y, omega0_rad_s, damping0_per_s)
    tau = t - t[0]
    theta = np.array(
        [
            est.settle_point_deg,
            est.amplitude_deg * math.cos(est.phase_rad),
            est.amplitude_deg * math.sin(est.phase_rad),
            est.omega_rad_s,
            est.damping_per_s,
        ]
    )
    jac = _damped_jacobian(tau, *theta)
    # the fit's covariance S^2 (J^T J)^-1, inflated for correlated noise as the SE of R^ is
    cov = np.linalg.inv(jac.T @ jac) * (est.residual_sd_deg * est.se_inflation) ** 2
    # past the record's end the fitted transient is extrapolated, up to ten decay times
    horizon = tau[-1] + (10.0 / est.damping_per_s if est.damping_per_s > 0 else 0.0)
    grid = np.arange(0.0, min(horizon, MAX_HORIZON * tau[-1]) + GRID_S / 2, GRID_S)
    value = _last_exit_s(theta, grid, half_band_deg)
    grad = np.zeros(5)
    if not math.isfinite(value):  # outside the band at the record's end: not settled in it
        grad[:] = 0.0
    for j in range(1, 5 if math.isfinite(value) else 1):  # R does not move the exit
        h = 1e-4 * max(abs(theta[j]), math.sqrt(cov[j, j]))
        up, down = theta.copy(), theta.copy()
        up[j] += h
        down[j] -= h
        grad[j] = _last_exit_s(up, grid, half_band_deg) - _last_exit_s(down, grid, half_band_deg)
        grad[j] /= 2 * h
    u = math.sqrt(float(grad @ cov @ grad))  # GUM eq 10 with the covariances (eq 13)
    return SettlingTime(
        value_s=float(t[0] + value),
        u_s=u,
        half_band_deg=half_band_deg,
        settle_point_deg=est.settle_point_deg,
        settle_point_se_deg=est.standard_error_deg,
        period_s=2 * math.pi / est.omega_rad_s,
        damping_per_s=est.damping_per_s,
        fit_from_s=float(t[0]),
        record_s=float(t_s[-1]),
    )


@dataclass(frozen=True)
class SettlePoint:
    """The settle point heading (mean of the readings), its standard uncertainty from their
    scatter, the readings' RMS about it (U_rms = 2 u), and, with a reference heading, its
    error with U = k u (k by Welch-Satterthwaite)."""

    readings_deg: tuple[float, ...]
    interval_s: float
    heading_deg: float
    u_heading_deg: float
    rms_deg: float
    rms_expanded_deg: float
    error_deg: float | None
    error_expanded_deg: float | None
    coverage_factor: float | None

    @property
    def n(self) -> int:
        return len(self.readings_deg)

    @classmethod
    def from_dict(cls, record: dict[str, Any]) -> SettlePoint:
        return cls(**{**record, "readings_deg": tuple(record["readings_deg"])})


def settle_point(
    readings_deg: np.ndarray,
    interval_s: float,
    reference_deg: float | None = None,
    u_reference_deg: float | None = None,
) -> SettlePoint:
    """The settle point heading of readings taken `interval_s` apart, and its error against
    the reference heading (with the reference's standard uncertainty)."""
    r = np.asarray(readings_deg, dtype=float)
    n = r.size
    mean = float(r.mean())
    s2 = float(r.var(ddof=1))
    rms = math.sqrt(s2 * (n - 1) / n)  # RMS of the differences from their mean
    rms_u = 2 * rms / math.sqrt(2 * (n - 1))  # U = 2 u, u = RMS / sqrt(2 (N - 1)): GUM E.4.3
    u_mean2 = s2 / n
    error = expanded = k = None
    if reference_deg is not None:
        u_ref2 = (u_reference_deg or 0.0) ** 2
        u2 = u_mean2 + u_ref2
        # nu_eff = u^4 / (u_mean^4 / (n - 1)), the reference's dof infinite: GUM G.4.1
        nu = math.inf if u_mean2 == 0 else u2**2 / (u_mean2**2 / (n - 1))
        k = t_quantile(0.5 + COVERAGE / 2, nu) if math.isfinite(nu) else 1.96
        error = (mean - reference_deg + 180.0) % 360.0 - 180.0
        expanded = k * math.sqrt(u2)
    return SettlePoint(
        readings_deg=tuple(float(v) for v in r),
        interval_s=interval_s,
        heading_deg=mean,
        u_heading_deg=math.sqrt(u_mean2),
        rms_deg=rms,
        rms_expanded_deg=rms_u,
        error_deg=error,
        error_expanded_deg=expanded,
        coverage_factor=k,
    )


@dataclass(frozen=True)
class Repeatability:
    """The range of the run-ups' settle points (largest minus smallest), its expanded
    uncertainty U = 2 sqrt(u_max^2 + u_min^2), and the settle points themselves."""

    settle_points_deg: tuple[float, ...]
    range_deg: float
    expanded_deg: float


def repeatability(points: list[SettlePoint]) -> Repeatability:
    """The repeatability of the settle point from run-up to run-up (at least two run-ups)."""
    if len(points) < 2:
        raise ValueError("repeatability needs the settle points of at least two run-ups")
    headings = np.array([p.heading_deg for p in points])
    hi, lo = int(np.argmax(headings)), int(np.argmin(headings))
    u = math.hypot(points[hi].u_heading_deg, points[lo].u_heading_deg)
    return Repeatability(
        settle_points_deg=tuple(float(h) for h in headings),
        range_deg=float(headings[hi] - headings[lo]),
        expanded_deg=2.0 * u,
    )


@dataclass(frozen=True)
class RollingError:
    """The error at one envelope point: the mean of the readings while rolling minus the
    static settle point, U = k u (k = t(0.975, nu_eff), GUM G.4.1); or, ``forecast``, the
    point lay beyond the stand and model 1.1 predicts it (no measurement)."""

    direction_deg: float
    amplitude_cm: float
    period_s: float
    error_deg: float | None
    expanded_deg: float | None
    forecast: bool = False


def rolling_error(
    direction_deg: float,
    amplitude_cm: float,
    period_s: float,
    readings_deg: np.ndarray,
    static: SettlePoint,
) -> RollingError:
    """The rolling error at a point from its readings (each a mean over whole rocking periods)
    against the static settle point."""
    r = np.asarray(readings_deg, dtype=float)
    u_roll2, u_static2 = float(r.var(ddof=1)) / r.size, static.u_heading_deg**2
    u2 = u_roll2 + u_static2
    # Welch-Satterthwaite (GUM G.4.1) over the two means' variances
    nu = u2**2 / (u_roll2**2 / (r.size - 1) + u_static2**2 / (static.n - 1))
    k = t_quantile(0.5 + COVERAGE / 2, nu)
    return RollingError(
        direction_deg,
        amplitude_cm,
        period_s,
        float(r.mean()) - static.heading_deg,
        k * math.sqrt(u2),
    )


@dataclass(frozen=True)
class ProcedureResults:
    """What the standard's procedures measured: the settling time of the first run-up, its
    settle point (readings after settling), the repeatability over the run-ups, the errors at
    the rolling envelope's points; the reference heading (None: not stated), the site's
    latitude and, per kind, how
    the plan departs from the profile's procedure."""

    settling: SettlingTime | None
    settle_point: SettlePoint | None
    repeatability: Repeatability | None
    rolling: tuple[RollingError, ...]
    reference_deg: float | None
    latitude_deg: float  # the site's, for the limits' sec(latitude)
    departures: tuple[tuple[str, str], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The stored record (JSON: a settling time not reached is null)."""
        record = asdict(self)
        if self.settling is not None:
            record["settling"] = self.settling.to_dict()
        return record

    @classmethod
    def from_dict(cls, record: dict[str, Any]) -> ProcedureResults:
        settling = record["settling"]
        point = record["settle_point"]
        repeat = record["repeatability"]
        return cls(
            settling=None if settling is None else SettlingTime.from_dict(settling),
            settle_point=None if point is None else SettlePoint.from_dict(point),
            repeatability=None
            if repeat is None
            else Repeatability(
                **{**repeat, "settle_points_deg": tuple(repeat["settle_points_deg"])}
            ),
            rolling=tuple(RollingError(**r) for r in record["rolling"]),
            reference_deg=record["reference_deg"],
            latitude_deg=record["latitude_deg"],
            departures=tuple((k, text) for k, text in record["departures"]),
        )

    def departure(self, kind: str) -> str | None:
        """How the plan's procedure of this kind departs from the standard's (None: it does
        not)."""
        found = [text for k, text in self.departures if k == kind]
        return "; ".join(found) if found else None
