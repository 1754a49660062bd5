"""Prediction from the fitted model (Potemkin 1982, eqs 2.10-2.11) at stand or ship conditions,
and its worst case over a box of ship motion (`envelope_worst`).

Sign convention (ship): K is the direction of the horizontal acceleration of the compass base,
measured clockwise from the meridian (north), in degrees. Rolling (side to side) accelerates the
compass athwartships, so K = course + 90 deg; pitching accelerates it along the keel, so
K = course. alpha depends on sin 2K, so K and K + 180 deg (port or starboard) give the same error.
The amplitude is the arc A = theta0 (rad) x h of the compass at distance h from the rocking axis.
"""

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from gyrostand.analysis.errors import AnalysisError, NonFiniteError
from gyrostand.analysis.gyro_model import Conditions, KnownConstants, RollingErrorModel
from gyrostand.analysis.quantiles import t_quantile

if TYPE_CHECKING:
    import pandas as pd

MOTIONS = ("roll", "pitch")
SIGN_CONVENTION = (
    "K = direction of the base's horizontal acceleration, clockwise from north; "
    "rolling: K = course + 90 deg, pitching: K = course; A = roll angle (rad) x arm"
)


@dataclass(frozen=True)
class Prediction:
    """Predictions at m points (arrays of one shape): alpha (1.1), the prediction variance of a
    single future trial (2.10) and of the mean of N repeats (1 replaced by 1/N), the t quantile
    and the (1 - q) half-widths of eq 2.11."""

    alpha_deg: np.ndarray
    var_deg2: np.ndarray
    var_mean_deg2: np.ndarray
    t: float
    half_width_deg: np.ndarray
    half_width_mean_deg: np.ndarray


@dataclass(frozen=True)
class Predictor:
    """A fitted model 1.1 with what eqs 2.10-2.11 need: the estimates, (X^T X)^-1 at them, the
    adequacy variance S^2_r (2.7) with its dof n - m, the level q and the repeat count N."""

    constants: KnownConstants
    C_gcm2s2: float
    T_s: float
    xtx_inv: tuple[tuple[float, float], tuple[float, float]]
    s2_r: float
    dof: int
    q: float
    n_repeat: int

    def predict(self, conditions: Conditions) -> Prediction:
        """Vectorised over any broadcastable condition arrays."""
        model = RollingErrorModel(self.constants)
        alpha = model(conditions, self.C_gcm2s2, self.T_s)
        x_p = model.jacobian(conditions, self.C_gcm2s2, self.T_s)
        leverage = np.einsum("...i,ij,...j->...", x_p, np.asarray(self.xtx_inv), x_p)
        var = self.s2_r * (1 + leverage)  # eq 2.10
        var_mean = self.s2_r * (1 / self.n_repeat + leverage)  # eq 2.10 with 1/N
        t = t_quantile(1 - self.q / 2, self.dof)  # eq 2.11, two-sided (1 - q)
        return Prediction(alpha, var, var_mean, t, t * np.sqrt(var), t * np.sqrt(var_mean))

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["xtx_inv"] = [list(row) for row in self.xtx_inv]
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Predictor":
        fields = dict(data)
        fields["constants"] = KnownConstants(**fields["constants"])
        fields["xtx_inv"] = tuple(tuple(float(v) for v in row) for row in fields["xtx_inv"])
        return cls(**fields)


@dataclass(frozen=True)
class ShipConditions:
    """Ship rocking conditions for a forecast. ``amplitude_cm`` overrides theta0 x h when given
    (the paper rounds 5 deg x 750 cm = 65.45 cm to 65 cm)."""

    roll_deg: float
    arm_cm: float
    period_s: float
    course_deg: float
    latitude_deg: float
    motion: str = "roll"
    amplitude_cm: float | None = None

    def __post_init__(self) -> None:
        if self.motion not in MOTIONS:
            raise AnalysisError(f"forecast motion {self.motion!r} must be one of {MOTIONS}")
        for name, value in asdict(self).items():
            if name != "motion" and value is not None and not np.isfinite(value):
                raise NonFiniteError(f"forecast {name} = {value} is not finite")
        if self.period_s <= 0 or self.arm_cm < 0:
            raise AnalysisError("forecast period must be > 0 and arm >= 0")
        if not abs(self.latitude_deg) < 90:
            raise AnalysisError(f"forecast latitude {self.latitude_deg} deg must lie in (-90, 90)")

    @property
    def direction_deg(self) -> float:
        """K of eq 1.1 (see the module's sign convention)."""
        return acceleration_direction_deg(self.course_deg, self.motion)

    @property
    def amplitude_from_roll_cm(self) -> float:
        return float(np.radians(self.roll_deg) * self.arm_cm)

    @property
    def effective_amplitude_cm(self) -> float:
        return self.amplitude_from_roll_cm if self.amplitude_cm is None else self.amplitude_cm


def acceleration_direction_deg(course_deg: Any, motion: str) -> Any:
    """K from the ship's course: course + 90 deg when rolling, the course when pitching."""
    if motion not in MOTIONS:
        raise AnalysisError(f"motion {motion!r} must be one of {MOTIONS}")
    return np.mod(np.asarray(course_deg) + (90.0 if motion == "roll" else 0.0), 360.0)


@dataclass(frozen=True)
class Forecast:
    """A forecast at ship conditions: alpha_p (1.1) with its (1 - q) interval (2.10-2.11)."""

    conditions: ShipConditions
    direction_deg: float
    amplitude_cm: float
    alpha_deg: float
    se_deg: float
    se_mean_deg: float
    t: float
    half_width_deg: float
    half_width_mean_deg: float

    @property
    def interval_deg(self) -> tuple[float, float]:
        return (self.alpha_deg - self.half_width_deg, self.alpha_deg + self.half_width_deg)


def forecast_ship(predictor: Predictor, ship: ShipConditions) -> Forecast:
    """alpha_p at one set of ship conditions, with its prediction interval."""
    k, a = ship.direction_deg, ship.effective_amplitude_cm
    p = predictor.predict(Conditions(k, a, ship.period_s, ship.latitude_deg))
    return Forecast(
        conditions=ship,
        direction_deg=float(k),
        amplitude_cm=float(a),
        alpha_deg=float(p.alpha_deg),
        se_deg=float(np.sqrt(p.var_deg2)),
        se_mean_deg=float(np.sqrt(p.var_mean_deg2)),
        t=p.t,
        half_width_deg=float(p.half_width_deg),
        half_width_mean_deg=float(p.half_width_mean_deg),
    )


@dataclass(frozen=True)
class ForecastGrid:
    """Forecasts over the outer product of the axes: arrays of shape
    (len(course_deg), len(roll_deg), len(period_s), len(latitude_deg))."""

    course_deg: np.ndarray
    roll_deg: np.ndarray
    period_s: np.ndarray
    latitude_deg: np.ndarray
    arm_cm: float
    motion: str
    q: float
    alpha_deg: np.ndarray
    half_width_deg: np.ndarray

    def to_frame(self) -> "pd.DataFrame":
        """Long table: one row per grid point, with the interval bounds."""
        import pandas as pd  # here: pandas costs every command that forecasts 0.3 s to import

        axes = np.meshgrid(
            self.course_deg, self.roll_deg, self.period_s, self.latitude_deg, indexing="ij"
        )
        frame = pd.DataFrame(
            {
                "course_deg": axes[0].ravel(),
                "roll_deg": axes[1].ravel(),
                "period_s": axes[2].ravel(),
                "latitude_deg": axes[3].ravel(),
                "alpha_deg": self.alpha_deg.ravel(),
                "half_width_deg": self.half_width_deg.ravel(),
            }
        )
        frame["lower_deg"] = frame.alpha_deg - frame.half_width_deg
        frame["upper_deg"] = frame.alpha_deg + frame.half_width_deg
        return frame


def forecast_grid(
    predictor: Predictor,
    *,
    course_deg: Any = np.arange(0.0, 361.0, 5.0),
    roll_deg: Any = (5.0,),
    period_s: Any = (7.0,),
    latitude_deg: Any = (57.0,),
    arm_cm: float = 750.0,
    motion: str = "roll",
) -> ForecastGrid:
    """Vectorised forecasts with (1 - q) half-widths (2.10-2.11) over a grid of ship conditions."""
    course, roll, period, lat = (
        np.atleast_1d(np.asarray(v, dtype=float))
        for v in (course_deg, roll_deg, period_s, latitude_deg)
    )
    for name, axis in (("course", course), ("roll", roll), ("period", period), ("lat", lat)):
        if not np.all(np.isfinite(axis)):
            raise NonFiniteError(f"forecast grid axis {name} has non-finite values")
    if np.any(period <= 0) or np.any(np.abs(lat) >= 90):
        raise AnalysisError("forecast grid: periods must be > 0 and latitudes in (-90, 90)")
    k = acceleration_direction_deg(course, motion)[:, None, None, None]
    amplitude = (np.radians(roll) * arm_cm)[None, :, None, None]
    p = predictor.predict(
        Conditions(k, amplitude, period[None, None, :, None], lat[None, None, None, :])
    )
    shape = (course.size, roll.size, period.size, lat.size)
    return ForecastGrid(
        course_deg=course,
        roll_deg=roll,
        period_s=period,
        latitude_deg=lat,
        arm_cm=float(arm_cm),
        motion=motion,
        q=predictor.q,
        alpha_deg=np.broadcast_to(p.alpha_deg, shape).copy(),
        half_width_deg=np.broadcast_to(p.half_width_deg, shape).copy(),
    )


def horizontal_acceleration_m_s2(amplitude_cm: Any, period_s: Any) -> Any:
    """Peak horizontal acceleration A p^2 of harmonic rocking of arc amplitude A (p = 2 pi / tau,
    eq 1.1), in m/s^2."""
    return np.asarray(amplitude_cm) * (2 * np.pi / np.asarray(period_s)) ** 2 / 100.0


@dataclass(frozen=True)
class Extrapolation:
    """How far a forecast lies beyond the tested range: the largest ``factor`` over amplitude,
    period and acceleration (value / largest tested, or smallest tested period / period) and
    ``text`` naming each quantity beyond it with its factor."""

    factor: float
    text: str


@dataclass(frozen=True)
class TestedRange:
    """The motion the stand's analysed trials covered: amplitude A (cm), period tau (s) and
    peak horizontal acceleration A p^2 (m/s^2), each as (smallest, largest)."""

    amplitude_cm: tuple[float, float]
    period_s: tuple[float, float]
    acceleration_m_s2: tuple[float, float]

    def describe(self) -> str:
        (a0, a1), (t0, t1), (g0, g1) = self.amplitude_cm, self.period_s, self.acceleration_m_s2
        return f"A {a0:.4g}-{a1:.4g} cm, tau {t0:.4g}-{t1:.4g} s, A p^2 {g0:.3g}-{g1:.3g} m/s^2"

    def beyond(self, amplitude_cm: float, period_s: float) -> Extrapolation | None:
        """None when the motion lies inside the tested range, else how far beyond it."""
        accel = float(horizontal_acceleration_m_s2(amplitude_cm, period_s))
        (_, a1), (t0, t1), (_, g1) = self.amplitude_cm, self.period_s, self.acceleration_m_s2
        factors = {
            f"A = {amplitude_cm:.4g} cm": amplitude_cm / a1,
            f"tau = {period_s:.4g} s": max(period_s / t1, t0 / period_s),
            f"A p^2 = {accel:.3g} m/s^2": accel / g1,
        }
        outside = {what: f for what, f in factors.items() if f > 1 + 1e-9}
        if not outside:
            return None
        return Extrapolation(
            max(outside.values()),
            "extrapolation: " + ", ".join(f"{w} (\u00d7{f:.3g})" for w, f in outside.items()),
        )


def tested_range(amplitude_cm: Any, period_s: Any) -> TestedRange:
    """The range of the trials' motion (arrays of A and tau)."""
    a, t = np.asarray(amplitude_cm, dtype=float), np.asarray(period_s, dtype=float)
    g = horizontal_acceleration_m_s2(a, t)
    return TestedRange(
        (float(a.min()), float(a.max())),
        (float(t.min()), float(t.max())),
        (float(g.min()), float(g.max())),
    )


@dataclass(frozen=True)
class MotionBox:
    """The ship motion a forecast is bounded over: the angle of the plan's motion (roll or pitch)
    up to ``max_angle_deg``, periods in ``period_s``, the compass's peak horizontal acceleration
    up to ``max_acceleration_m_s2``, any course, latitudes 0 to ``max_latitude_deg`` (alpha and
    its interval depend on |phi| only)."""

    max_angle_deg: float
    period_s: tuple[float, float]
    max_acceleration_m_s2: float
    max_latitude_deg: float

    def angle_cap_deg(self, period_s: Any, arm_cm: float) -> Any:
        """The largest angle inside the box at this period: the angle limit, or the angle whose
        arc A = theta0 h gives A p^2 = the acceleration limit, whichever is smaller."""
        p2 = (2 * np.pi / np.asarray(period_s, dtype=float)) ** 2
        if arm_cm <= 0:
            return np.full_like(p2, self.max_angle_deg)
        by_acceleration = np.degrees(self.max_acceleration_m_s2 * 100.0 / (arm_cm * p2))
        return np.minimum(self.max_angle_deg, by_acceleration)


@dataclass(frozen=True)
class EnvelopeWorst:
    """The point of a `MotionBox` where |alpha_p| + (1 - q) half-width, divided by the limit's
    latitude factor (sec phi for a limit x sec(latitude), else 1), is largest: ``ratio`` is that
    quotient, so a limit L x factor is met everywhere in the box when ``ratio`` <= L."""

    course_deg: float
    direction_deg: float
    angle_deg: float
    period_s: float
    acceleration_m_s2: float
    latitude_deg: float
    amplitude_cm: float
    alpha_deg: float
    half_width_deg: float
    ratio: float
    motion: str
    arm_cm: float
    q: float

    @property
    def bound_deg(self) -> float:
        """|alpha_p| + half-width at the worst point."""
        return abs(self.alpha_deg) + self.half_width_deg


ENVELOPE_GRID = {"course": 73, "angle": 5, "period": 19, "latitude": 13}
"""Points per axis of the coarse search before the local refinement (course every 5 deg)."""


def envelope_worst(
    predictor: Predictor,
    box: MotionBox,
    *,
    arm_cm: float,
    motion: str,
    secant_latitude: bool,
) -> EnvelopeWorst:
    """The worst case of the forecast over the box: a grid over course x angle x period x
    latitude, the angle as a fraction of its cap at each period (so every point obeys the
    acceleration limit), then a bounded Powell search from the grid's worst point."""
    from scipy import optimize

    lo, hi = box.period_s

    def evaluate(course: Any, fraction: Any, period: Any, lat: Any) -> tuple[Any, ...]:
        angle = np.asarray(fraction) * box.angle_cap_deg(period, arm_cm)
        amplitude = np.radians(angle) * arm_cm  # A = theta0 h (module docstring)
        k = acceleration_direction_deg(course, motion)
        p = predictor.predict(Conditions(k, amplitude, period, lat))
        factor = 1 / np.cos(np.radians(lat)) if secant_latitude else np.ones_like(lat)
        ratio = (np.abs(p.alpha_deg) + p.half_width_deg) / factor
        return ratio, angle, amplitude, k, p

    axes = np.meshgrid(
        np.linspace(0.0, 360.0, ENVELOPE_GRID["course"]),
        np.linspace(0.0, 1.0, ENVELOPE_GRID["angle"]),
        np.linspace(lo, hi, ENVELOPE_GRID["period"]),
        np.linspace(0.0, box.max_latitude_deg, ENVELOPE_GRID["latitude"]),
        indexing="ij",
    )
    ratio = evaluate(*axes)[0]
    start = np.array([a[np.unravel_index(int(np.argmax(ratio)), ratio.shape)] for a in axes])
    bounds = [(0.0, 360.0), (0.0, 1.0), (lo, hi), (0.0, box.max_latitude_deg)]
    found = optimize.minimize(
        lambda x: -float(evaluate(*x)[0]),
        start,
        method="Powell",
        bounds=bounds,
        options={"xtol": 1e-10, "ftol": 1e-14},
    )
    best = found.x if -found.fun >= float(np.max(ratio)) else start
    for i, edges in enumerate(bounds):  # a coordinate that ends within xtol of a bound: onto it
        for edge in edges:
            moved = np.where(np.arange(4) == i, edge, best)
            if evaluate(*moved)[0] >= evaluate(*best)[0] * (1 - 1e-12):
                best = moved
    value, angle, amplitude, k, p = evaluate(*best)
    return EnvelopeWorst(
        course_deg=float(best[0]),
        direction_deg=float(k),
        angle_deg=float(angle),
        period_s=float(best[2]),
        acceleration_m_s2=float(horizontal_acceleration_m_s2(amplitude, best[2])),
        latitude_deg=float(best[3]),
        amplitude_cm=float(amplitude),
        alpha_deg=float(p.alpha_deg),
        half_width_deg=float(p.half_width_deg),
        ratio=float(value),
        motion=motion,
        arm_cm=float(arm_cm),
        q=predictor.q,
    )
