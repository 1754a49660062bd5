"""The roll a CiA 402 stand is commanded to make, and the stand's kinematics.

theta(t) = theta_A * e(t) * sin(2 pi t / tau): a sinusoid under an envelope e that rises from 0
to 1 over the start ramp and falls back to 0 over the stop ramp, each by the quintic
"smootherstep" S(s) = 6 s^5 - 15 s^4 + 10 s^3, whose first and second derivatives vanish at both
ends: position, velocity and acceleration are continuous, and the axis starts and ends at rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Kinematics:
    """How the plan's amplitude A (cm, the paper's) becomes drive counts."""

    counts_per_degree: float  # the drive's position units per degree of roll
    arm_length_cm: float  # the arm at which A is measured

    def amplitude_deg(self, amplitude_cm: float) -> float:
        """The roll angle whose arc at the arm is A: theta_A = A / l (rad)."""
        return math.degrees(amplitude_cm / self.arm_length_cm)

    def amplitude_cm(self, amplitude_deg: float) -> float:
        return math.radians(amplitude_deg) * self.arm_length_cm


def _smootherstep(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """S(s) and dS/ds, s clipped to [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2), 30.0 * s**2 * (1.0 - s) ** 2


@dataclass(frozen=True)
class RollTrajectory:
    amplitude_deg: float
    period_s: float
    ramp_s: float  # each of the start and stop ramps
    stop_at_s: float = math.inf  # the stop ramp begins here

    def stopped_at(self, t_s: float) -> RollTrajectory:
        """The same roll with its stop ramp beginning at `t_s` (or earlier, if already)."""
        return RollTrajectory(
            self.amplitude_deg, self.period_s, self.ramp_s, min(self.stop_at_s, t_s)
        )

    @property
    def end_s(self) -> float:
        """When the axis is at rest again (inf while no stop is set)."""
        return self.stop_at_s + self.ramp_s

    def envelope(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """e(t) and de/dt."""
        t = np.asarray(t_s, dtype=float)
        rise, drise = _smootherstep(t / self.ramp_s)
        if math.isinf(self.stop_at_s):
            return rise, drise / self.ramp_s
        fall, dfall = _smootherstep((t - self.stop_at_s) / self.ramp_s)
        return rise * (1.0 - fall), (drise * (1.0 - fall) - rise * dfall) / self.ramp_s

    def position_deg(self, t_s: np.ndarray) -> np.ndarray:
        e, _ = self.envelope(t_s)
        return self.amplitude_deg * e * np.sin(2.0 * math.pi * np.asarray(t_s) / self.period_s)

    def velocity_deg_s(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        e, de = self.envelope(t)
        w = 2.0 * math.pi / self.period_s
        return self.amplitude_deg * (de * np.sin(w * t) + e * w * np.cos(w * t))
