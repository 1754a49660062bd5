"""The gyrocompass rolling (intercardinal) error model, seed 000 eq 1.1, in the paper's CGS units.

    alpha = (lP)^2 / (4 g^2 H1 U cos(phi)) * A^2 p^4 sin(2K) / (C (1 + p^2 T^2)),  p = 2 pi / tau

alpha comes out in radians and is reported in degrees. Units: lP in g cm^2 s^-2, H1 in
g cm^2 s^-1, U in rad/s, g in cm/s^2, A in cm, tau and T in s, C in g cm^2 s^-2, K and phi in
degrees (K: direction of the horizontal acceleration of the base from the meridian).
"""

from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.errors import AnalysisError, NonFiniteError

PARAMETERS = ("C_gcm2s2", "T_s")
"""Names of the two estimated parameters: the reduced elastic compliance coefficient C and the
time constant T of the gyrosphere's centre-of-mass displacement."""


@dataclass(frozen=True)
class KnownConstants:
    """The known parameters B of model 1.1 (CGS), from the instrument and the test site."""

    lP_gcm2s2: float
    H1_gcm2s: float
    earth_rate_rad_s: float
    gravity_cm_s2: float
    latitude_deg: float

    def __post_init__(self) -> None:
        for name in ("lP_gcm2s2", "H1_gcm2s", "earth_rate_rad_s", "gravity_cm_s2"):
            value = getattr(self, name)
            if not np.isfinite(value):
                raise NonFiniteError(f"constant {name} = {value} is not finite")
            if value <= 0:
                raise AnalysisError(f"constant {name} = {value} must be positive")
        if not abs(self.latitude_deg) < 90:
            raise AnalysisError(f"latitude {self.latitude_deg} deg must lie in (-90, 90)")

    def gain(self, latitude_deg: np.ndarray | float | None = None) -> np.ndarray:
        """The factor (lP)^2 / (4 g^2 H1 U cos phi) of eq 1.1, at the site or a given latitude."""
        phi = np.radians(self.latitude_deg if latitude_deg is None else latitude_deg)
        denominator = 4 * self.gravity_cm_s2**2 * self.H1_gcm2s * self.earth_rate_rad_s
        return self.lP_gcm2s2**2 / (denominator * np.cos(phi))


@dataclass(frozen=True)
class Conditions:
    """Rocking conditions at which the model is evaluated (arrays broadcast together)."""

    direction_deg: np.ndarray
    amplitude_cm: np.ndarray
    period_s: np.ndarray
    latitude_deg: np.ndarray | float | None = None  # None: the constants' latitude


@dataclass(frozen=True)
class RollingErrorModel:
    """Model 1.1 for `fit_nonlinear`: ``model(x, C_gcm2s2=..., T_s=...)`` with x a `Conditions`,
    and its analytic Jacobian (the paper's x1, x2 of eq 1.4)."""

    constants: KnownConstants

    def __call__(self, x: Conditions, C_gcm2s2: float, T_s: float) -> np.ndarray:
        """Rolling error alpha in degrees (seed 000 eq 1.1)."""
        p = 2 * np.pi / np.asarray(x.period_s, dtype=float)
        amplitude = np.asarray(x.amplitude_cm, dtype=float)
        sin2k = np.sin(2 * np.radians(x.direction_deg))
        alpha_rad = (
            self.constants.gain(x.latitude_deg)
            * amplitude**2
            * p**4
            * sin2k
            / (C_gcm2s2 * (1 + p**2 * T_s**2))
        )
        return np.degrees(alpha_rad)

    def jacobian(self, x: Conditions, C_gcm2s2: float, T_s: float) -> np.ndarray:
        """Partials (..., 2): x1 = -alpha/C, x2 = -alpha 2p^2 T/(1 + p^2 T^2) (seed 000 eq 1.4)."""
        alpha = self(x, C_gcm2s2, T_s)
        p2 = (2 * np.pi / np.asarray(x.period_s, dtype=float)) ** 2
        return np.stack([-alpha / C_gcm2s2, -alpha * 2 * p2 * T_s / (1 + p2 * T_s**2)], axis=-1)
