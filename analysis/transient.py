"""The compass's transient over a campaign: one damped precession whose equilibrium steps each
time the stand starts or stops rocking (Bezvesilna & Gura eqs 1-3; seed 003).

Between two steps, s_j <= t < s_(j+1), the noise-free reading is the small-angle solution of
eq 1 in initial-value form (eq 2 with A, phi replaced by the state at the step):

    y(t) = R_j + x_j a(tau) + v_j b(tau),  tau = t - s_j,
    a = e^(-xi tau) (cos w tau + xi/w sin w tau),  b = w0 e^(-xi tau) sin(w tau) / w,

with w = sqrt(w0^2 - xi^2), R_j the settle point of the series and v_j the velocity in units of
w0 (deg). The sensitive element does not jump at a step, only its equilibrium does, so the state
carries over: x_(j+1) = y(s_(j+1)) - R_(j+1), v_(j+1) = y'(s_(j+1)) / w0. The whole record is
therefore LINEAR in theta = (R_1, ..., R_S, and x_j, v_j of each segment whose state at its step
is unknown: the first one, or one after an unobserved change). Least squares on the window means
of the settle record and of the observations (each weighted by its window length) gives every
R_j with its covariance, and the transient y - R_j left in any window with its standard error.

A series starting right after a step is then pinned by the series before it: its state at the
step is known from that series' record, and only R_j is new. That is what lets a series be
observed during its transient and compensated (`TransientFit.transient`), and what bounds the
transient left in a series whatever criterion started it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from gyrostand.analysis.effective import window_means_covariance
from gyrostand.analysis.errors import SingularDesignError
from gyrostand.analysis.settle import variance_inflation

COVERAGE_K = 2.0  # a bound is |estimate| + 2 SE (about 95 %)


@dataclass(frozen=True)
class TransientModel:
    """The precession's undamped period 2 pi / w0 (s) and damping ratio xi / w0."""

    undamped_period_s: float
    damping_ratio: float

    @property
    def w0(self) -> float:
        return 2.0 * math.pi / self.undamped_period_s

    @property
    def xi(self) -> float:
        return self.damping_ratio * self.w0

    @property
    def w(self) -> float:
        return self.w0 * math.sqrt(1.0 - self.damping_ratio**2)

    def basis(self, tau_s: np.ndarray, width_s: np.ndarray | float = 0.0) -> tuple[np.ndarray, ...]:
        """a, b (position per unit x, v at the step) and their derivatives / w0 (eq 2), each
        averaged over a window of ``width_s`` centred on tau (0: the value at tau). With
        s = -xi + i w, e^(-xi tau) (cos, sin)(w tau) = (Re, Im) e^(s tau), whose mean over the
        window is e^(s tau) sinh(s W / 2) / (s W / 2): so a window mean is exact, not its middle."""
        tau = np.asarray(tau_s, dtype=float)
        s = complex(-self.xi, self.w)
        half = s * np.asarray(width_s, dtype=float) / 2
        safe = np.where(half == 0, 1.0, half)
        z = np.exp(s * tau) * np.where(half == 0, 1.0, np.sinh(safe) / safe)
        c, sin = z.real, z.imag
        r, k = self.xi / self.w, self.w0 / self.w
        return c + r * sin, k * sin, -k * sin, c - r * sin


@dataclass(frozen=True)
class Segments:
    """The steps of the equilibrium: stand seconds ``step_s`` (increasing) and which segments
    start from an unknown state (``free``; the first always does)."""

    step_s: tuple[float, ...]
    free: tuple[bool, ...]

    def __post_init__(self) -> None:
        if not self.step_s or len(self.free) != len(self.step_s):
            raise ValueError("segments need one free flag per step, and at least one step")
        if not self.free[0]:
            raise ValueError("the first segment's state is unknown: it must be free")
        if any(b < a for a, b in zip(self.step_s, self.step_s[1:], strict=False)):
            raise ValueError("segment steps must be in time order")

    @property
    def n_params(self) -> int:
        return len(self.step_s) + 2 * sum(self.free)


@functools.lru_cache(maxsize=8)  # the online settle check asks for the same ones per block
def _state_maps(model: TransientModel, seg: Segments) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per segment, x_j and v_j as linear forms in theta (carried over the steps; read-only,
    shared by the calls with equal arguments)."""
    s = len(seg.step_s)
    maps: list[tuple[np.ndarray, np.ndarray]] = []
    extra = s
    for j in range(s):
        x, v = np.zeros(seg.n_params), np.zeros(seg.n_params)
        if seg.free[j]:
            x[extra], v[extra + 1] = 1.0, 1.0
            extra += 2
        else:
            px, pv = maps[j - 1]
            a, b, da, db = model.basis(np.array(seg.step_s[j] - seg.step_s[j - 1]))
            x = px * a + pv * b
            x[j - 1] += 1.0  # the position y(s_j) = R_(j-1) + x a + v b ...
            x[j] -= 1.0  # ... measured from the new equilibrium R_j
            v = px * da + pv * db
        x.flags.writeable = v.flags.writeable = False
        maps.append((x, v))
    return maps


def design(
    model: TransientModel,
    seg: Segments,
    segment: np.ndarray,
    t_s: np.ndarray,
    width_s: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Rows d y / d theta for the means of the reading over windows of ``width_s`` centred on
    ``t_s`` in segments ``segment`` (indices)."""
    segment = np.asarray(segment, dtype=int)
    t = np.asarray(t_s, dtype=float)
    maps = _state_maps(model, seg)
    steps = np.asarray(seg.step_s)
    a, b, _, _ = model.basis(t - steps[segment], width_s)
    x = np.array([m[0] for m in maps])[segment]
    v = np.array([m[1] for m in maps])[segment]
    rows = x * a[:, None] + v * b[:, None]
    rows[np.arange(t.size), segment] += 1.0
    return rows


@dataclass(frozen=True)
class Windows:
    """Window means of the reading: segment index, middle and length (stand seconds), value
    (deg, on one branch), in time order. Weighted by length: the variance of a window mean of
    noise correlated over much less than a window falls as 1 / length."""

    segment: np.ndarray
    mid_s: np.ndarray
    width_s: np.ndarray
    value_deg: np.ndarray

    @classmethod
    def of(cls, rows: Sequence[tuple[int, float, float, float]]) -> Windows:
        """From (segment, mid_s, width_s, value_deg) rows."""
        a = np.array(rows, dtype=float).reshape(-1, 4)
        return cls(a[:, 0].astype(int), a[:, 1], a[:, 2], a[:, 3])


@dataclass(frozen=True)
class TransientFit:
    """Least-squares state of the transient: theta, its covariance (s^2 (X^T W X)^-1, times
    the correlated-noise inflation), the residual s.d. of a window mean of unit weight; the
    period and damping ratio's SE when they were estimated too."""

    model: TransientModel
    segments: Segments
    theta: np.ndarray = field(repr=False)
    covariance: np.ndarray = field(repr=False)
    residual_sd_deg: float
    n: int
    period_se_s: float | None = None
    damping_ratio_se: float | None = None
    pd_covariance: np.ndarray | None = field(default=None, repr=False)  # of (period, ratio)

    def settle_point(self, j: int) -> tuple[float, float]:
        """R_j and its standard error (deg)."""
        return float(self.theta[j]), float(math.sqrt(self.covariance[j, j]))

    def _transient_rows(self, j: int, t_s: np.ndarray, width_s: np.ndarray | float) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        rows = design(self.model, self.segments, np.full(t.size, j), t, width_s)
        rows[:, j] -= 1.0
        return rows

    def transient(
        self, j: int, t_s: np.ndarray, width_s: np.ndarray | float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Mean of y - R_j over windows of segment j, and the standard errors."""
        rows = self._transient_rows(j, t_s, width_s)
        se = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", rows, self.covariance, rows), 0.0))
        return rows @ self.theta, se

    def mean_transient(
        self, j: int, t_s: np.ndarray, width_s: np.ndarray | float
    ) -> tuple[float, float]:
        """The transient averaged over a series' windows, and its standard error."""
        g = self._transient_rows(j, t_s, width_s).mean(axis=0)
        return float(g @ self.theta), float(math.sqrt(max(g @ self.covariance @ g, 0.0)))

    def bound(self, j: int, t_s: np.ndarray, width_s: np.ndarray | float) -> float:
        """Largest |transient| + 2 SE over the windows, deg."""
        value, se = self.transient(j, t_s, width_s)
        return float(np.max(np.abs(value) + COVERAGE_K * se))


def _weighted_rows(
    model: TransientModel, seg: Segments, data: Windows, rows: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    sw = np.sqrt(data.width_s / np.mean(data.width_s))
    if rows is None:
        rows = design(model, seg, data.segment, data.mid_s, data.width_s)
    return rows * sw[:, None], data.value_deg * sw


def fit_transient(
    model: TransientModel, seg: Segments, data: Windows, rows: np.ndarray | None = None
) -> TransientFit:
    """Weighted least squares of the window means on the transient model; ``rows``: their
    `design` if already known (the online check extends it by the new windows)."""
    rows, y = _weighted_rows(model, seg, data, rows)
    n, p = rows.shape
    if n <= p:
        raise SingularDesignError(f"transient fit needs more than {p} window means, got {n}")
    u, s, vt = np.linalg.svd(rows, full_matrices=False)
    if s[-1] <= s[0] * 1e-12:
        raise SingularDesignError("transient model columns are linearly dependent")
    theta = vt.T @ ((u.T @ y) / s)
    resid = y - rows @ theta
    s2 = float(resid @ resid) / (n - p)
    cov = (vt.T / s**2) @ vt * s2 * variance_inflation(resid)
    return TransientFit(model, seg, theta, cov, math.sqrt(s2), n)


def fit_transient_free(start: TransientModel, seg: Segments, data: Windows) -> TransientFit:
    """``fit_transient`` with the period and damping ratio estimated too (variable projection:
    theta is solved for each (period, ratio), scipy's least_squares moves the pair). The
    covariance is the joint one of theta and (period, ratio), times the correlated-noise
    inflation as in `fit_transient`: a settle point or transient taken from this fit carries
    the uncertainty of the period and damping the record gave (with them held fixed, a
    compensation with a period a few per cent off came out several SE wrong)."""
    from scipy.optimize import least_squares

    def residuals(q: np.ndarray) -> np.ndarray:
        model = TransientModel(start.undamped_period_s * q[0], q[1])
        rows, y = _weighted_rows(model, seg, data)
        return y - rows @ np.linalg.lstsq(rows, y, rcond=None)[0]

    result = least_squares(
        residuals, [1.0, start.damping_ratio], bounds=([0.2, 0.05], [5.0, 0.99]), x_scale=0.1
    )
    if not result.success:
        raise SingularDesignError(f"transient fit with free period and damping: {result.message}")
    model = TransientModel(start.undamped_period_s * float(result.x[0]), float(result.x[1]))
    fit = fit_transient(model, seg, data)
    rows, y = _weighted_rows(model, seg, data)
    n, p = rows.shape
    if n <= p + 2:
        raise SingularDesignError(f"free transient fit needs more than {p + 2} window means")
    jac = np.column_stack([rows, *_model_columns(model, seg, data, fit.theta)])
    resid = y - rows @ fit.theta
    s2 = float(resid @ resid) / (n - p - 2)
    cov = np.linalg.pinv(jac.T @ jac) * s2 * variance_inflation(resid)
    return replace(
        fit,
        covariance=cov[:p, :p],
        residual_sd_deg=math.sqrt(s2),
        period_se_s=float(math.sqrt(cov[p, p])),
        damping_ratio_se=float(math.sqrt(cov[p + 1, p + 1])),
        pd_covariance=cov[p:, p:],
    )


def compensated_mean_se(
    fit: TransientFit,
    data: Windows,
    j: int,
    t_s: np.ndarray,
    width_s: np.ndarray,
    correlation_time_s: float | None = None,
) -> float:
    """Standard error (deg) of the mean of segment j's windows at ``t_s`` (middles) each less
    the transient ``fit`` gives over it: a compensated series' mean, when ``data`` (the record
    ``fit`` was fitted to) includes those windows. Each compensated value is y_k - (row_k -
    e_j) theta = R_j + r_k, r_k the fit's residual, so the mean is R_j + r_bar: linear in the
    record, c^T y with c = J (J^T J)^-1 e_j + (I - H) a (weighted rows; J with the period and
    damping columns when they were estimated, H = J (J^T J)^-1 J^T, a the mean over the
    windows). Not SE(R_j)^2 + S^2/N: R_j is fitted to those same windows, so their scatter is in
    its SE already (adding it overstated a compensated mean's variance ~1.2x, issue 34).

    With the reading's ``correlation_time_s`` (exponential, Sveshnikov eq 8.89) the window
    means' covariance is sigma^2 K (`window_means_covariance`) and Var = sigma^2 c^T K c, sigma^2
    = r^T r / tr((I - H) K) (E[r^T r] under K): the record mixes settle blocks laid end to end
    (neighbours correlated ~0.2-0.4) with observations 30 s apart (~0.05), which one inflation
    factor for the whole record cannot describe. Without it: the fit's own covariance and
    inflation, Var = SE(R_j)^2 + s^2 f a^T (I - H) a (residuals _|_ estimates)."""
    c, k, sigma2 = _compensation_form(fit, data, j, t_s, width_s, correlation_time_s)
    return math.sqrt(sigma2 * float(c @ k @ c))  # Var(m) = s^2 c^T K c


def compensated_covariances(
    fit: TransientFit,
    data: Windows,
    j: int,
    t_s: np.ndarray,
    width_s: np.ndarray,
    means_mid_s: Sequence[np.ndarray],
    n_obs: int,
    correlation_time_s: float | None = None,
) -> tuple[float, ...]:
    """Cov (deg^2) of the compensated mean of `compensated_mean_se` with each plain mean of
    ``n_obs`` observations whose windows in ``data`` have the middles ``means_mid_s`` (the
    others not in this record: independent of it): both are linear in the record's window
    means, c^T y_w and b^T y_w, so Cov = sigma^2 c^T K b (issue 34: an uncompensated series'
    windows are in the record that fixes every later compensation's period, damping and
    carried state)."""
    c, k, sigma2 = _compensation_form(fit, data, j, t_s, width_s, correlation_time_s)
    return tuple(sigma2 * float(c @ k @ b) for b in _plain_means(data, means_mid_s, n_obs))


def _plain_means(data: Windows, means_mid_s: Sequence[np.ndarray], n_obs: int) -> list[np.ndarray]:
    """b with b^T y_w the plain mean of ``n_obs`` observations, of which those with window
    middles ``means_mid_s`` are in ``data`` (y_w: the weighted window means)."""
    sw = np.sqrt(data.width_s / np.mean(data.width_s))
    out = []
    for mids in means_mid_s:
        match = np.abs(data.mid_s[None, :] - np.asarray(mids, dtype=float)[:, None]) < 1e-6
        if not np.all(match.sum(axis=1) == 1):
            raise ValueError("the windows of an earlier mean are not all in the record")
        where = np.flatnonzero(match.any(axis=0))
        b = np.zeros(data.segment.size)
        b[where] = 1.0 / (n_obs * sw[where])  # the plain mean of the unweighted values
        out.append(b)
    return out


def _compensation_form(
    fit: TransientFit,
    data: Windows,
    j: int,
    t_s: np.ndarray,
    width_s: np.ndarray,
    correlation_time_s: float | None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """c, K, sigma^2 with the compensated mean - E = c^T (y_w - E y_w), Cov(y_w) = sigma^2 K
    (`compensated_mean_se`; without a correlation time K = I and sigma^2 = s^2 f)."""
    mid = np.atleast_1d(np.asarray(t_s, dtype=float))
    width = np.broadcast_to(np.asarray(width_s, dtype=float), mid.shape)
    match = (data.segment[None, :] == j) & (np.abs(data.mid_s[None, :] - mid[:, None]) < 1e-6)
    match &= np.abs(data.width_s[None, :] - width[:, None]) < 1e-6
    if not np.all(match.sum(axis=1) == 1):
        raise ValueError(f"the compensated windows are not all in the record of segment {j}")
    rows, y = _weighted_rows(fit.model, fit.segments, data)
    jac = rows
    if fit.pd_covariance is not None:  # the period and damping were estimated too
        jac = np.column_stack([rows, *_model_columns(fit.model, fit.segments, data, fit.theta)])
    sw = np.sqrt(data.width_s / np.mean(data.width_s))
    a = match.sum(axis=0) / (mid.size * sw)  # mean of the unweighted residuals r_w / sw
    pinv = np.linalg.pinv(jac)
    resid = y - rows @ fit.theta
    c = pinv[j] + a - jac @ (pinv @ a)  # m - E[m] = c^T (y_w - E[y_w])
    if correlation_time_s is None:
        # s^2 f c^T c = Var(R_j) + s^2 f a'(I-H)a: the fit's own covariance and inflation
        return c, np.eye(y.size), fit.residual_sd_deg**2 * variance_inflation(resid)
    half = data.width_s / 2
    k = window_means_covariance(data.mid_s - half, data.mid_s + half, correlation_time_s)
    k *= np.outer(sw, sw)  # of the weighted window means
    hk = jac @ (pinv @ k)
    sigma2 = float(resid @ resid) / float(np.trace(k) - np.trace(hk))  # E[r'r] = s^2 tr((I-H)K)
    return c, k, sigma2


def _model_columns(
    model: TransientModel, seg: Segments, data: Windows, theta: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """d (weighted window means) / d period and / d ratio at ``theta`` (central differences;
    the basis is smooth in both)."""
    out = []
    for dp, dr in ((1e-4 * model.undamped_period_s, 0.0), (0.0, 1e-4)):
        up = TransientModel(model.undamped_period_s + dp, model.damping_ratio + dr)
        down = TransientModel(model.undamped_period_s - dp, model.damping_ratio - dr)
        diff = _weighted_rows(up, seg, data)[0] - _weighted_rows(down, seg, data)[0]
        out.append(diff @ theta / (2 * (dp + dr)))
    return out[0], out[1]


WARN_FRACTION = 0.3  # warn when the transient left in a series mean may exceed 0.3 S_e
WELL_DETERMINED = 0.1  # relative SE below which the record is said to determine period, damping
REJECT_SE = 3.0  # ... and to contradict the plan's when these many SE away


PLAN_CONTRADICTED = "plan contradicted"  # the acquisition event: the record's period, damping used


def well_determined(record: TransientFit) -> bool:
    """The record's own period and damping ratio (a `fit_transient_free`) have relative SE
    below WELL_DETERMINED."""
    assert record.period_se_s is not None and record.damping_ratio_se is not None
    return (
        record.period_se_s < WELL_DETERMINED * record.model.undamped_period_s
        and record.damping_ratio_se < WELL_DETERMINED * record.model.damping_ratio
    )


def contradicts(record: TransientFit, plan: TransientModel) -> bool:
    """The record's own period and damping ratio (a `fit_transient_free`) are well determined
    and more than REJECT_SE standard errors from the plan's. Only a warning in the analysis
    (the acquisition uses the record's, `acquisition.early_settle`). With the period and
    damping's SE from the joint covariance and the noise inflation, the whole record of a
    simulated campaign gives the period within its SE (z SD 0.81 over 37 campaigns; held
    covariance without inflation: ~2x low, bench/bench_early_settle.py)."""
    if not well_determined(record):
        return False
    assert record.period_se_s is not None and record.damping_ratio_se is not None
    period, ratio = record.model.undamped_period_s, record.model.damping_ratio
    return (
        max(
            abs(period - plan.undamped_period_s) / record.period_se_s,
            abs(ratio - plan.damping_ratio) / record.damping_ratio_se,
        )
        > REJECT_SE
    )


@dataclass(frozen=True)
class SeriesTransient:
    """The transient left in one series' mean (after its compensation, if compensated) as the
    fit of the whole record gives it, with its standard error; ``bound_deg`` = |left| + 2 SE.
    ``compensation_se_deg``: a compensated series' settle point SE in the whole-record fit
    (None: not compensated)."""

    trial: int
    j: int
    compensation_se_deg: float | None
    left_deg: float
    standard_error_deg: float

    @property
    def bound_deg(self) -> float:
        return abs(self.left_deg) + COVERAGE_K * self.standard_error_deg

    def warning(self, s_e_deg: float) -> str | None:
        """Not compensated: the bound exceeds WARN_FRACTION x S_e (Potemkin 1982, eq 2.6).
        Compensated (its SE is in the series variance already): what is left exceeds 3 SE of
        the compensation and the whole-record fit together."""
        where = f"trial {self.trial} series {self.j}"
        if self.compensation_se_deg is None:
            limit = WARN_FRACTION * s_e_deg
            if self.bound_deg <= limit:
                return None
            return (
                f"{where}: the compass's transient left in the series mean may reach "
                f"{self.bound_deg:.4f} deg (fit {self.left_deg:+.4f} deg, SE "
                f"{self.standard_error_deg:.4f} deg), more than {WARN_FRACTION:g} S_e = "
                f"{limit:.4f} deg"
            )
        se = math.hypot(self.compensation_se_deg, self.standard_error_deg)
        if abs(self.left_deg) <= 3 * se:
            return None
        return (
            f"{where}: the compensation differs from the whole record's transient by "
            f"{self.left_deg:+.4f} deg, more than 3 SE ({3 * se:.4f} deg)"
        )


@dataclass(frozen=True)
class TransientCheck:
    """The transient model fitted to the campaign's whole record (settle blocks and
    observations of every series) with the plan's period and damping ratio, and what it leaves
    in each series; the record's own estimates of those two (None: the fit failed) with their
    SE, and whether they contradict the plan's (`contradicts`)."""

    undamped_period_s: float
    damping_ratio: float
    plan_contradicted: bool
    record_period_s: float | None
    record_period_se_s: float | None
    record_damping_ratio: float | None
    record_damping_ratio_se: float | None
    residual_sd_deg: float
    series: tuple[SeriesTransient, ...]

    def warnings(self, s_e_deg: float) -> tuple[str, ...]:
        found = (s.warning(s_e_deg) for s in self.series)
        plan = (
            [
                f"the record gives the compass's precession period {self.record_period_s:.0f} +/- "
                f"{self.record_period_se_s:.0f} s and damping ratio {self.record_damping_ratio:.3f}"
                f" +/- {self.record_damping_ratio_se:.3f}, more than {REJECT_SE:g} SE from the "
                f"plan's {self.undamped_period_s:g} s and {self.damping_ratio:g}: check the "
                "plan's instrument data (they are used; a wrong period biases the settle points)"
            ]
            if self.plan_contradicted
            else []
        )
        return (*plan, *(w for w in found if w is not None))

    def to_dict(self) -> dict[str, object]:
        return {
            **{k: v for k, v in asdict(self).items() if k != "series"},
            "series": [{**asdict(s), "bound_deg": s.bound_deg} for s in self.series],
        }
