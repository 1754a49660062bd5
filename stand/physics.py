"""The simulated compass's physics: the settled rolling error, the transient to a new equilibrium,
and the sensor's correlated noise. Pure functions/classes on numbers; no bus, no clock."""

from __future__ import annotations

import math

import numpy as np


def rolling_error_rad(
    direction_deg: float,
    amplitude_cm: float,
    period_s: float,
    *,
    C_gcm2s2: float,
    T_s: float,
    lP_gcm2s2: float,
    H1_gcm2s: float,
    U_rad_s: float,
    g_cm_s2: float,
    latitude_deg: float,
) -> float:
    """Settled intercardinal error on a rocking base, in radians (seed 000 eq 1.1):
    alpha = (lP)^2 / (4 g^2 H1 U cos(phi)) * A^2 p^4 sin(2K) / (C (1 + p^2 T^2)), p = 2 pi / tau.
    """
    p = 2.0 * math.pi / period_s
    known = lP_gcm2s2**2 / (
        4.0 * g_cm_s2**2 * H1_gcm2s * U_rad_s * math.cos(math.radians(latitude_deg))
    )
    return (
        known
        * amplitude_cm**2
        * p**4
        * math.sin(2.0 * math.radians(direction_deg))
        / (C_gcm2s2 * (1.0 + p**2 * T_s**2))
    )


class DampedPrecession:
    """Deviation x (rad) of the sensitive element from its equilibrium, advanced in fixed steps.

    seed 003 eq 1: x'' + 2 xi x' + w0^2 sin x = 0 (the seed prints "w0 sin"; w0^2 is the
    dimensionally consistent form whose small-angle solution is the seed's eq 2,
    x = A e^(-xi t) sin(w t + phi), w = sqrt(w0^2 - xi^2)). Fixed-step RK4: with the step equal to
    the heading interval (0.1 s) against an 84-minute period its error is ~1e-15 of the amplitude.
    """

    def __init__(self, w0_rad_s: float, xi_per_s: float, step_s: float, *, nonlinear: bool):
        self.w0_sq = w0_rad_s**2
        self.xi = xi_per_s
        self.step_s = step_s
        self.nonlinear = nonlinear
        self.x_rad = 0.0
        self.v_rad_s = 0.0

    def step(self) -> float:
        """Advance one step; return the new deviation (rad)."""
        self.run(1)
        return self.x_rad

    def run(self, n: int) -> np.ndarray:
        """The deviation (rad) at each of the next n steps, before the step; advances n steps.

        One RK4 step per sample in a loop of local floats (the simulator's inner loop: ~12x
        faster than a method call per stage)."""
        out = np.empty(n)
        h, half, sixth = self.step_s, 0.5 * self.step_s, self.step_s / 6.0
        c, k = 2.0 * self.xi, self.w0_sq
        f = math.sin if self.nonlinear else float
        x, v = self.x_rad, self.v_rad_s
        for i in range(n):
            out[i] = x
            a1 = -c * v - k * f(x)
            x2, v2 = x + half * v, v + half * a1
            a2 = -c * v2 - k * f(x2)
            x3, v3 = x + half * v2, v + half * a2
            a3 = -c * v3 - k * f(x3)
            x4, v4 = x + h * v3, v + h * a3
            a4 = -c * v4 - k * f(x4)
            x, v = (
                x + sixth * (v + 2.0 * v2 + 2.0 * v3 + v4),
                v + sixth * (a1 + 2.0 * a2 + 2.0 * a3 + a4),
            )
        self.x_rad, self.v_rad_s = x, v
        return out

    def shift_equilibrium(self, delta_rad: float) -> None:
        """The equilibrium moved by delta: the element has not moved yet, so x jumps by -delta."""
        self.x_rad -= delta_rad


class CorrelatedNoise:
    """Stationary Gaussian noise with correlation function sigma^2 e^(-mu |tau|)
    (seed 004 §8.3, the Markov case below eq 8.79), sampled every `step_s`.

    Exact discretisation (an AR(1) recursion with carried state):
    x[k] = r x[k-1] + sigma sqrt(1 - r^2) w[k], r = e^(-mu step), w ~ N(0, 1); x[0] ~ N(0, sigma^2).
    Chunked calls give the same sequence as one long call.

    The recursion is a loop of floats rather than scipy's `lfilter([1], [1, -r])`: the same
    numbers to the bit (tests), ~0.1 us a sample, where importing scipy.signal for it cost the
    simulated stand ~1 s of CPU per run (and `gyrostand simulate` a pause at start)."""

    def __init__(self, sigma: float, mu_per_s: float, step_s: float, rng: np.random.Generator):
        self.sigma = sigma
        self.r = math.exp(-mu_per_s * step_s)
        self.rng = rng
        self._last: float | None = None  # the previous sample (None: none yet)

    def sample(self, n: int) -> np.ndarray:
        w = self.rng.standard_normal(n)
        if n == 0 or self.sigma == 0.0:
            return np.zeros(n)
        drive = self.sigma * math.sqrt(1.0 - self.r**2) * w
        if self._last is None:  # start in the stationary distribution
            drive[0] = self.sigma * w[0]
            self._last = 0.0
        r, x = self.r, self._last
        out = []
        for d in drive.tolist():
            x = x * r + d  # seed 004 eq 8.79's Markov case, discretised (the docstring)
            out.append(x)
        self._last = x
        return np.array(out)
