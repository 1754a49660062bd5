"""Synthetic stand readings from model 1.1 with known C, T and Gaussian reading noise, for tests,
the Monte-Carlo validation and the benchmark.

Each trial's series j=1 (before rocking) reads a standing error b_i plus noise; series j=2 (under
rocking) reads b_i + alpha_i (eq 1.1) plus noise; every reading has standard deviation
``sigma_deg``. Then <delta_i> ~ N(alpha_i, sigma^2 (1/N1 + 1/N2)).
"""

from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.gyro_model import Conditions, KnownConstants, RollingErrorModel
from gyrostand.analysis.trials import TrialInput


@dataclass(frozen=True)
class Design:
    """Rocking conditions of k trials (arrays of shape (k,))."""

    direction_deg: np.ndarray
    amplitude_cm: np.ndarray
    period_s: np.ndarray

    @property
    def conditions(self) -> Conditions:
        return Conditions(self.direction_deg, self.amplitude_cm, self.period_s)


def synthetic_readings(
    constants: KnownConstants,
    design: Design,
    *,
    C_gcm2s2: float,
    T_s: float,
    sigma_deg: float,
    n_obs: tuple[int, int],
    rng: np.random.Generator,
    bias_sd_deg: float = 0.5,
    rho: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Readings before and under rocking, arrays (k, N1) and (k, N2), in degrees; ``rho``: the
    correlation of successive readings of a series (AR(1), rho^k at lag k)."""
    alpha = RollingErrorModel(constants)(design.conditions, C_gcm2s2, T_s)
    bias = rng.normal(0.0, bias_sd_deg, alpha.shape)[:, None]
    if rho == 0.0:
        before = bias + rng.normal(0.0, sigma_deg, (alpha.size, n_obs[0]))
        under = bias + alpha[:, None] + rng.normal(0.0, sigma_deg, (alpha.size, n_obs[1]))
        return before, under
    before = bias + sigma_deg * ar1(rho, (alpha.size, n_obs[0]), rng)
    return before, bias + alpha[:, None] + sigma_deg * ar1(rho, (alpha.size, n_obs[1]), rng)


def ar1(rho: float, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """Stationary AR(1) series of unit variance along the last axis: correlation rho^k."""
    x = np.empty(shape)
    x[..., 0] = rng.standard_normal(shape[:-1])
    for k in range(1, shape[-1]):
        x[..., k] = rho * x[..., k - 1] + np.sqrt(1 - rho**2) * rng.standard_normal(shape[:-1])
    return x


def synthetic_trials(
    constants: KnownConstants,
    design: Design,
    roles: list[str],
    *,
    C_gcm2s2: float,
    T_s: float,
    sigma_deg: float,
    n_obs: int,
    rng: np.random.Generator,
    rho: float = 0.0,
) -> list[TrialInput]:
    """Trials with raw readings (N per series, successive ones correlated by ``rho``), numbered
    from 1."""
    before, under = synthetic_readings(
        constants,
        design,
        C_gcm2s2=C_gcm2s2,
        T_s=T_s,
        sigma_deg=sigma_deg,
        n_obs=(n_obs, n_obs),
        rng=rng,
        rho=rho,
    )
    return [
        TrialInput(
            index=i + 1,
            role=role,
            direction_deg=float(design.direction_deg[i]),
            amplitude_cm=float(design.amplitude_cm[i]),
            period_s=float(design.period_s[i]),
            before_deg=tuple(before[i]),
            under_deg=tuple(under[i]),
        )
        for i, role in enumerate(roles)
    ]
