"""General nonlinear least squares: Gauss-Newton exactly as seed 000 (eqs 1.2-1.10), with an
automatic bounded trust-region fallback (`scipy.optimize.least_squares`).

Entry point::

    fit_nonlinear(model, x, y, theta0, *, jacobian=None, bounds=None, x_scale=None,
                  eps=None, eps_se=1e-8, max_iter=100, robust=True) -> FitResult

- ``model(x, **theta) -> ndarray (n,)``: model values at the inputs ``x`` (any object the model
  understands: an array, a tuple of arrays...) for the named parameters ``theta``.
- ``jacobian(x, **theta) -> ndarray (n, m)``: analytic partials, columns in ``theta0`` key order.
  Without it, central finite differences are used.
- ``y``: the n observations. ``theta0``: start values ``{name: value}``; its key order is the
  parameter order everywhere (Jacobian columns, covariance rows, log entries).
- ``bounds``: ``{name: (lo, hi)}`` hard limits (unnamed parameters are unbounded). A Gauss-Newton
  iterate that leaves them hands the fit to the trust-region path, which honours them.
- ``x_scale``: ``{name: typical magnitude}`` for the trust-region path (default: Jacobian-based),
  for badly scaled parameters such as C ~ 1e7 next to T ~ 1.
- ``eps``: ``{name: epsilon_i}`` absolute thresholds of the stopping rule |a_i| < epsilon_i (1.8).
  When omitted, epsilon_i = ``eps_se`` x SE_i at the current iterate (the paper chooses epsilon
  "commensurate with the expected errors of the estimates"), floored at 1e-13 |theta_i|.
- ``max_iter``: Gauss-Newton iterations allowed before the fit is declared stalled.
- ``robust``: when False a Gauss-Newton failure is returned as is (``converged=False``).

Gauss-Newton diverges (non-finite values, residual sum of squares rising three iterations in a
row), stalls (singular linearisation, ``max_iter`` reached) or leaves ``bounds``: then, with
``robust=True``, the trust-region path refits from the start values and ``FitResult.path`` /
``FitResult.fallback_reason`` say so. The trust-region solver's own stop is not trusted: its
point counts as converged only once verified stationary. A Gauss-Newton polish with step halving
(at most ``max_iter`` steps) runs from it until the stopping rule (1.8) holds at a point whose
relative offset (Bates & Watts 1981; scale-invariant first-order optimality) is at most
``OFFSET_TOL``; parameters the descent direction pushes against a bound stay there. Otherwise
``converged=False`` and ``FitResult.reason`` says why. A solution where the Jacobian is (nearly)
rank-deficient is flagged ``converged=False`` ("degenerate"): typically a local minimum on a
flat direction, as NIST BoxBOD from its first start vector.
"""

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrostand.analysis.errors import AnalysisError, NonFiniteError, TooFewTrialsError

Model = Callable[..., np.ndarray]
"""``model(x, **theta) -> (n,)`` array."""

# Condition number of the column-equilibrated Jacobian above which X^T X counts as singular:
# its inverse (1.10) would then carry fewer than ~4 correct digits.
COND_LIMIT = 1e10
# Largest relative offset (Bates & Watts 1981) of a verified stationary point, R's nls default:
# the Gauss-Newton step still to go is then ~1e-5 sqrt(p) standard errors (covariance metric).
OFFSET_TOL = 1e-5
_DIVERGING_RISES = 3
_FD_STEP = np.finfo(float).eps ** (1 / 3)  # optimal relative step of a central difference
_MIN_STEP_FACTOR = 1 / 1024  # step halving gives up below this factor (R's nls minFactor)
_SQRT_EPS = np.sqrt(np.finfo(float).eps)
_TINY = np.finfo(float).tiny


@dataclass(frozen=True)
class IterationRecord:
    """One Gauss-Newton iteration d: theta_d, the step a_d = Delta theta_d (1.6-1.7), and the fit
    quality at theta_d (residual sum of squares and S^2 of eq 1.9)."""

    iteration: int
    theta: dict[str, float]
    step: dict[str, float]
    rss: float
    s2: float


@dataclass(frozen=True)
class FitResult:
    """Estimates and their precision at the solution (eqs 1.6-1.10).

    ``residuals`` are observed minus fitted (y - f). ``xtx_inv`` is the unscaled covariance
    (X^T X)^-1 of the linearisation at the solution, ``covariance`` = ``xtx_inv`` x S^2 (1.10).
    ``path`` is "gauss-newton" or "trust-region"; ``fallback_reason`` says why Gauss-Newton was
    abandoned (None when it was not). ``converged`` means the stopping rule (1.8) was met, on the
    trust-region path at a point verified stationary by the Gauss-Newton polish; ``reason`` says
    how, or why not. ``log`` holds the Gauss-Newton iterations (including those of an abandoned
    attempt); ``iterations`` counts them, or the trust-region solver's function evaluations on
    that path (the polish's steps are given in ``reason``)."""

    names: tuple[str, ...]
    estimates: dict[str, float]
    std_errors: dict[str, float]
    covariance: np.ndarray
    correlation: np.ndarray
    xtx_inv: np.ndarray
    jacobian: np.ndarray
    fitted: np.ndarray
    residuals: np.ndarray
    rss: float
    s2: float
    n: int
    dof: int
    iterations: int
    converged: bool
    reason: str
    path: str
    fallback_reason: str | None
    condition_number: float
    log: tuple[IterationRecord, ...]


class _Problem:
    """The model, data and parameter bookkeeping shared by both solution paths."""

    def __init__(
        self,
        model: Model,
        x: Any,
        y: np.ndarray,
        names: tuple[str, ...],
        jacobian: Callable[..., np.ndarray] | None,
    ) -> None:
        self.model, self.x, self.y, self.names, self.analytic = model, x, y, names, jacobian
        self.dof = y.size - len(names)

    def restricted(self, free: np.ndarray, theta: np.ndarray) -> "_Problem":
        """The problem in the ``free`` parameters alone, the others held at their ``theta``."""
        if free.all():
            return self
        held = {n: float(v) for n, v, f in zip(self.names, theta, free, strict=True) if not f}
        names = tuple(n for n, f in zip(self.names, free, strict=True) if f)

        def full(free_theta: dict[str, float]) -> np.ndarray:
            return np.array([free_theta[n] if n in free_theta else held[n] for n in self.names])

        jacobian = None
        if self.analytic is not None:
            jacobian = lambda x, **th: self.jacobian(full(th))[:, free]  # noqa: E731
        return _Problem(
            lambda x, **th: self.model(x, **th, **held), self.x, self.y, names, jacobian
        )

    def kwargs(self, theta: np.ndarray) -> dict[str, float]:
        return {name: float(v) for name, v in zip(self.names, theta, strict=True)}

    def values(self, theta: np.ndarray) -> np.ndarray:
        # Overflow while exploring is expected and handled (non-finite values end the path).
        with np.errstate(all="ignore"):
            values = self.model(self.x, **self.kwargs(theta))
        return np.asarray(values, dtype=float).reshape(-1)

    def rss(self, theta: np.ndarray) -> float:
        """Residual sum of squares at theta (NaN when the model is not finite there)."""
        with np.errstate(all="ignore"):
            residuals = self.y - self.values(theta)
            return float(residuals @ residuals)

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        if self.analytic is not None:
            jac = np.asarray(self.analytic(self.x, **self.kwargs(theta)), dtype=float)
            return jac.reshape(self.y.size, len(self.names))
        # Central differences: scipy's public approx_fprime is forward-only (error ~1e-8), too
        # coarse to reproduce certified NIST values to 6 digits; central gives ~1e-11.
        columns = []
        for i, value in enumerate(theta):
            h = _FD_STEP * (abs(value) if value != 0 else 1.0)
            up, down = theta.copy(), theta.copy()
            up[i] += h
            down[i] -= h
            with np.errstate(all="ignore"):
                columns.append((self.values(up) - self.values(down)) / (up[i] - down[i]))
        return np.column_stack(columns)


@dataclass(frozen=True)
class _Linearisation:
    """QR solution of the linearised problem (1.5-1.6) at one theta, with its relative offset:
    zero exactly at a stationary point, whatever the scales of the parameters and the data."""

    values: np.ndarray
    jac: np.ndarray
    residuals: np.ndarray
    step: np.ndarray
    xtx_inv: np.ndarray
    cond: float
    offset: float

    @property
    def rss(self) -> float:
        return float(self.residuals @ self.residuals)


def _linearise(problem: _Problem, theta: np.ndarray) -> _Linearisation | str:
    """Solve A = (X^T X)^-1 X^T Y (1.6) by QR of the column-equilibrated X; a string on failure."""
    from scipy import linalg

    values = problem.values(theta)
    jac = problem.jacobian(theta)
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(jac))):
        return "diverged: non-finite model values or Jacobian"
    scale = np.linalg.norm(jac, axis=0)
    if np.any(scale == 0):
        zero = [problem.names[i] for i in np.flatnonzero(scale == 0)]
        return f"singular linearisation: the model does not depend on {', '.join(zero)}"
    q, r = linalg.qr(jac / scale, mode="economic")
    cond = float(np.linalg.cond(r))
    if not cond < COND_LIMIT:
        return f"singular linearisation: condition number {cond:.3g} of X"
    residuals = problem.y - values  # Y of eq 1.4: observed minus computed
    tangent = q.T @ residuals  # the residuals' coordinates in the tangent plane
    step = linalg.solve_triangular(r, tangent) / scale  # eq 1.6
    # Relative offset (Bates & Watts 1981): tangential over orthogonal residual, each per degree
    # of freedom. An exact fit would make it 0/0, so the orthogonal spread is floored at
    # sqrt(eps) x rms(y): a 1e-5 offset then still asks the tangential part for ~1e-13 rms(y).
    spread = max(
        float(np.linalg.norm(residuals - q @ tangent)) / np.sqrt(problem.dof),
        _SQRT_EPS * float(np.sqrt(np.mean(problem.y**2))),
        _TINY,
    )
    offset = float(np.linalg.norm(tangent)) / np.sqrt(len(scale)) / spread
    # LAPACK's triangular inverse: a BLAS-3 solve against the identity costs ~1000x more on tiny
    # matrices when a multi-threaded BLAS contends for cores
    r_inv, info = linalg.lapack.dtrtri(r)
    if info != 0:
        return f"singular linearisation: R[{info - 1}, {info - 1}] = 0"
    xtx_inv = (r_inv @ r_inv.T) / np.outer(scale, scale)
    return _Linearisation(values, jac, residuals, step, xtx_inv, cond, offset)


def _thresholds(
    lin: _Linearisation, theta: np.ndarray, eps: np.ndarray | None, eps_se: float, dof: int
) -> np.ndarray:
    """epsilon_i of the stopping rule (1.8): as given, or eps_se x SE_i at theta (1.9-1.10)
    floored at 1e-13 |theta_i|."""
    if eps is not None:
        return eps
    se = np.sqrt(lin.rss / dof * np.diag(lin.xtx_inv))
    return np.maximum(eps_se * se, 1e-13 * np.abs(theta) + _TINY)


def _gauss_newton(
    problem: _Problem,
    theta0: np.ndarray,
    eps: np.ndarray | None,
    eps_se: float,
    bounds: tuple[np.ndarray, np.ndarray],
    max_iter: int,
) -> tuple[np.ndarray, list[IterationRecord], str | None]:
    """Iterate 1.3-1.8; returns the final theta, the log, and a failure reason (None if met)."""
    theta, log, rises = theta0.astype(float), [], 0
    for d in range(1, max_iter + 1):
        lin = _linearise(problem, theta)
        if isinstance(lin, str):
            return theta, log, f"{lin} at iteration {d}"
        s2 = lin.rss / problem.dof
        log.append(IterationRecord(d, problem.kwargs(theta), problem.kwargs(lin.step), lin.rss, s2))
        rises = rises + 1 if len(log) > 1 and lin.rss > log[-2].rss else 0
        if rises >= _DIVERGING_RISES:
            return theta, log, f"diverged: S^2 rose {rises} iterations in a row (iteration {d})"
        new = theta + lin.step  # eq 1.7
        outside = np.flatnonzero((new < bounds[0]) | (new > bounds[1]))
        if outside.size:
            i = outside[0]
            return (
                theta,
                log,
                f"left the bounds at iteration {d}: {problem.names[i]} = {new[i]:.6g} outside "
                f"[{bounds[0][i]:.6g}, {bounds[1][i]:.6g}]",
            )
        threshold = _thresholds(lin, theta, eps, eps_se, problem.dof)
        theta = new
        if np.all(np.abs(lin.step) < threshold):  # eq 1.8
            return theta, log, None
    return theta, log, f"stalled: stopping rule (1.8) not met in {max_iter} iterations"


def _trust_region(
    problem: _Problem,
    theta0: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    x_scale: np.ndarray | str,
) -> tuple[np.ndarray, int, str]:
    """Bounded trust-region reflective fit from theta0 (clipped into the bounds): the point where
    the solver stopped, its function evaluations and its stopping message (not yet verified)."""
    from scipy.optimize import least_squares

    lo, hi = bounds
    start = np.clip(theta0.astype(float), lo, hi)  # trf moves it strictly inside itself
    jac = "3-point" if problem.analytic is None else (lambda th: -problem.jacobian(th))
    with np.errstate(all="ignore"):
        sol = least_squares(
            lambda th: problem.y - problem.values(th),
            start,
            jac=jac,
            bounds=(lo, hi),
            x_scale=x_scale,
            method="trf",
            ftol=1e-15,
            xtol=1e-15,
            gtol=1e-15,
            max_nfev=2000 * theta0.size,
            # Relative steps as _Problem.jacobian: scipy's default step is at least ~6e-6 in
            # absolute terms, which swamps parameters of 1e-6 (NIST Hahn1's b4..b7).
            diff_step=_FD_STEP,
        )
    return sol.x, int(sol.nfev), f"trust region: {sol.message.rstrip('.')}"


def _held_at(
    problem: _Problem,
    theta: np.ndarray,
    lin: _Linearisation,
    eps: np.ndarray | None,
    eps_se: float,
    bounds: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """The bound each parameter is held at, NaN where it is free. A parameter within its epsilon
    (1.8) of a bound that the descent direction pushes against stays there: an active
    constraint whose multiplier has the right sign (KKT: Nocedal & Wright 2006, Theorem 12.1)."""
    lo, hi = bounds
    near = _thresholds(lin, theta, eps, eps_se, problem.dof)
    descent = lin.jac.T @ lin.residuals  # minus half the gradient of the RSS
    at_lo = (theta - lo <= near) & (descent < 0)
    at_hi = (hi - theta <= near) & (descent > 0)
    return np.where(at_lo, lo, np.where(at_hi, hi, np.nan))


@dataclass(frozen=True)
class _Polish:
    """Outcome of the Gauss-Newton polish: its last point, the steps taken, the relative offsets
    where it started and ended, and why it failed (None when the point is verified)."""

    theta: np.ndarray
    steps: int
    start_offset: float
    offset: float
    failure: str | None
    roundoff: str | None = None  # why (1.8) was waived at a stationary point (see `_polish`)


def _polish(
    problem: _Problem,
    theta: np.ndarray,
    eps: np.ndarray | None,
    eps_se: float,
    bounds: tuple[np.ndarray, np.ndarray],
    max_steps: int,
) -> _Polish:
    """Gauss-Newton (1.6-1.7) with step halving from theta until (1.8) holds at a point whose
    relative offset is at most OFFSET_TOL; that point is returned as is (verified).

    On an ill-conditioned problem (NIST Lanczos2) the steps at a stationary point are round-off:
    they wander by more than (1.8) allows while the offset stays far below OFFSET_TOL. When the
    steps run out so, the stationary point of least RSS met is returned as verified, and
    ``roundoff`` says that (1.8) was waived and by how much the steps missed it."""
    lo, hi = bounds
    start_offset = offset = float("nan")
    best: tuple[float, np.ndarray, float] | None = None  # RSS, theta, offset of a stationary point
    worst_ratio = 0.0  # largest |a_i| / epsilon_i of (1.8) at the stationary points met
    for steps in range(max_steps + 1):
        lin = _linearise(problem, theta)
        if isinstance(lin, str):
            return _Polish(theta, steps, start_offset, offset, f"{lin} after {steps} steps")
        offset = lin.offset
        start_offset = offset if steps == 0 else start_offset
        ratio = float(np.max(np.abs(lin.step) / _thresholds(lin, theta, eps, eps_se, problem.dof)))
        if offset <= OFFSET_TOL and ratio < 1:  # stationary, and eq 1.8
            return _Polish(theta, steps, start_offset, offset, None)
        if offset <= OFFSET_TOL:
            worst_ratio = max(worst_ratio, ratio)
            if best is None or lin.rss < best[0]:
                best = (lin.rss, theta.copy(), offset)
        if steps == max_steps:
            break
        # Step halving: stay inside the bounds and, until stationary, decrease the RSS. Within
        # OFFSET_TOL the predicted decrease (offset^2 p / dof of the RSS) soon sinks to rounding
        # level, where comparing RSS values is noise: full steps.
        factor = 1.0
        while True:
            new = theta + factor * lin.step  # eq 1.7 with a step factor
            inside = np.all((new >= lo) & (new <= hi))
            if inside and (offset <= OFFSET_TOL or problem.rss(new) <= lin.rss):
                break
            factor /= 2
            if factor < _MIN_STEP_FACTOR:
                return _Polish(
                    theta,
                    steps,
                    start_offset,
                    offset,
                    f"no decrease of the residual sum of squares along the Gauss-Newton step "
                    f"(step factor below 1/{round(1 / _MIN_STEP_FACTOR)}) after {steps} steps",
                )
        theta = new
    if best is not None:
        waived = (
            f"stopping rule (1.8) waived: at round-off its steps still reached {worst_ratio:.3g} "
            f"times the thresholds while the relative offset stayed <= {OFFSET_TOL:g}"
        )
        return _Polish(best[1], max_steps, start_offset, best[2], None, waived)
    return _Polish(
        theta,
        max_steps,
        start_offset,
        offset,
        f"(1.8) and the offset tolerance not both met in {max_steps} steps (relative offset "
        f"{offset:.3g})",
    )


def _degenerate(failure: str, reason: str) -> str:
    """The reason given for a solution whose linearisation is singular."""
    return (
        f"degenerate solution ({failure}): a local minimum on a flat direction or "
        f"unidentifiable parameters; {reason}"
    )


def _verify(
    problem: _Problem,
    theta: np.ndarray,
    eps: np.ndarray | None,
    eps_se: float,
    bounds: tuple[np.ndarray, np.ndarray],
    max_steps: int,
    solver: str,
) -> tuple[np.ndarray, bool, str]:
    """Polish the trust-region point and accept it only as a verified stationary point (within
    the bounds' active constraints): the point, converged, and the reason."""
    lin = _linearise(problem, theta)
    if isinstance(lin, str):
        return theta, False, _degenerate(lin, solver)
    lo, hi = bounds
    held_at = _held_at(problem, theta, lin, eps, eps_se, bounds)
    free = np.isnan(held_at)
    theta = np.where(free, theta, held_at)
    held = [n for n, f in zip(problem.names, free, strict=True) if not f]
    at_bounds = f"; {', '.join(held)} held at the bounds" if held else ""
    if not free.any():
        return theta, True, f"{solver}{at_bounds}"
    polish = _polish(
        problem.restricted(free, theta),
        theta[free],
        None if eps is None else eps[free],
        eps_se,
        (lo[free], hi[free]),
        max_steps,
    )
    theta[free] = polish.theta
    if polish.failure is not None:
        return (
            theta,
            False,
            f"not a verified stationary point: {solver}, but the relative offset there is "
            f"{polish.start_offset:.3g} (stationary: <= {OFFSET_TOL:g}) and the Gauss-Newton "
            f"polish from there failed: {polish.failure}{at_bounds}",
        )
    if held:  # the held set must still satisfy KKT at the polished point
        final = _linearise(problem, theta)
        if isinstance(final, str):
            return theta, False, _degenerate(final, solver)
        if not np.array_equal(held_at, _held_at(problem, theta, final, eps, eps_se, bounds), True):
            return theta, False, f"not verified: the active bounds changed in the polish; {solver}"
    rule = polish.roundoff or "stopping rule (1.8) met"
    return (
        theta,
        True,
        f"{solver}; verified stationary: relative offset {polish.offset:.2g} <= "
        f"{OFFSET_TOL:g} and {rule} after {polish.steps} Gauss-Newton polish steps{at_bounds}",
    )


def _vector(
    values: Mapping[str, float] | None, names: tuple[str, ...], what: str
) -> np.ndarray | None:
    """A per-parameter mapping as a vector in parameter order; every name must be given."""
    if values is None:
        return None
    if set(values) != set(names):
        raise AnalysisError(
            f"{what} must name exactly the parameters {names}, got {sorted(values)}"
        )
    vector = np.array([float(values[n]) for n in names])
    if not np.all(np.isfinite(vector) & (vector > 0)):
        raise AnalysisError(f"{what} values must be positive and finite, got {dict(values)}")
    return vector


def fit_nonlinear(
    model: Model,
    x: Any,
    y: Any,
    theta0: Mapping[str, float],
    *,
    jacobian: Callable[..., np.ndarray] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    x_scale: Mapping[str, float] | None = None,
    eps: Mapping[str, float] | None = None,
    eps_se: float = 1e-8,
    max_iter: int = 100,
    robust: bool = True,
) -> FitResult:
    """Fit ``model`` to ``y`` by Gauss-Newton (eqs 1.3-1.8), falling back to a bounded trust
    region when it fails; see the module docstring for every argument."""
    names = tuple(theta0)
    start = np.array([float(theta0[n]) for n in names])
    y = np.asarray(y, dtype=float).reshape(-1)
    if not np.all(np.isfinite(y)):
        raise NonFiniteError(f"observation y[{np.flatnonzero(~np.isfinite(y))[0]}] is not finite")
    if not np.all(np.isfinite(start)):
        bad = names[int(np.flatnonzero(~np.isfinite(start))[0])]
        raise NonFiniteError(f"start value of parameter {bad} is not finite")
    if y.size <= len(names):
        raise TooFewTrialsError(
            f"{y.size} observations for {len(names)} parameters: need at least {len(names) + 1}"
        )
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    for i, name in enumerate(names):
        if bounds and name in bounds:
            lo[i], hi[i] = bounds[name]
    eps_vec = _vector(eps, names, "eps")
    scale_vec = _vector(x_scale, names, "x_scale")
    problem = _Problem(model, x, y, names, jacobian)

    theta, log, failure = _gauss_newton(problem, start, eps_vec, eps_se, (lo, hi), max_iter)
    path, fallback, iterations, converged = "gauss-newton", None, len(log), failure is None
    reason = "stopping rule (1.8) met" if failure is None else failure
    if failure is not None and robust:
        path, fallback = "trust-region", failure
        theta, iterations, solver = _trust_region(
            problem, start, (lo, hi), "jac" if scale_vec is None else scale_vec
        )
        theta, converged, reason = _verify(
            problem, theta, eps_vec, eps_se, (lo, hi), max_iter, solver
        )
    return _result(problem, theta, log, iterations, converged, reason, path, fallback)


def _result(
    problem: _Problem,
    theta: np.ndarray,
    log: list[IterationRecord],
    iterations: int,
    converged: bool,
    reason: str,
    path: str,
    fallback: str | None,
) -> FitResult:
    """Statistics at the solution (1.9-1.10), flagging a degenerate (rank-deficient) one."""
    m = len(problem.names)
    dof = problem.dof
    lin = _linearise(problem, theta)
    if isinstance(lin, str):
        values = problem.values(theta)
        with np.errstate(all="ignore"):
            residuals = problem.y - values
            rss = float(residuals @ residuals)
        nan = np.full((m, m), np.nan)
        if converged:
            reason = _degenerate(lin, reason)
        return FitResult(
            names=problem.names,
            estimates=problem.kwargs(theta),
            std_errors=dict.fromkeys(problem.names, float("nan")),
            covariance=nan,
            correlation=nan,
            xtx_inv=nan,
            jacobian=problem.jacobian(theta),
            fitted=values,
            residuals=residuals,
            rss=rss,
            s2=rss / dof,
            n=problem.y.size,
            dof=dof,
            iterations=iterations,
            converged=False,
            reason=reason,
            path=path,
            fallback_reason=fallback,
            condition_number=float("inf"),
            log=tuple(log),
        )
    s2 = lin.rss / dof  # eq 1.9
    covariance = lin.xtx_inv * s2  # eq 1.10
    se = np.sqrt(np.diag(covariance))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = covariance / np.outer(se, se)
    return FitResult(
        names=problem.names,
        estimates=problem.kwargs(theta),
        std_errors=problem.kwargs(se),
        covariance=covariance,
        correlation=correlation,
        xtx_inv=lin.xtx_inv,
        jacobian=lin.jac,
        fitted=lin.values,
        residuals=lin.residuals,
        rss=lin.rss,
        s2=s2,
        n=problem.y.size,
        dof=dof,
        iterations=iterations,
        converged=converged,
        reason=reason,
        path=path,
        fallback_reason=fallback,
        condition_number=lin.cond,
        log=tuple(log),
    )
