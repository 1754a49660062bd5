"""The simulated stand's CiA 410 inclinometer on the roll platform, as frames: TPDO1 (COB-ID
0x180 + node id, the CiA 410 default mapping slope long16 0x6010 then slope lateral16 0x6020,
INTEGER16 little-endian in the resolution's steps) at its event timer's rate, and an EMCY
(0x80 + node id) on the fault knob. The slope on the mounted axis is the platform's true roll
(stand/engine.py: the amplitude the stand really makes), the sensor adds its own bias and white
noise; the frames' timestamps are their stand times (virtual time: their reception times)."""

from __future__ import annotations

import math
from collections.abc import Callable

import can
import numpy as np

from gyrostand.stand.simconfig import InclinometerParams

TPDO1 = 0x180  # + node id (CiA 301 pre-defined connection set)
EMCY = 0x080  # + node id
EMCY_HARDWARE = 0x5000  # CiA 301 error code: device hardware
_EPS = 1e-9

RollAngle = Callable[[np.ndarray], np.ndarray]
"""The platform's roll angle (rad) at stand times, from the stand's state."""


class SimInclinometerFrames:
    """TPDO1 samples of the platform's roll (`roll_deg(t)` for a batch of stand times)."""

    def __init__(self, params: InclinometerParams, rng: np.random.Generator) -> None:
        assert params.node_id is not None
        self.params = params
        self.node_id = params.node_id
        self._rng = rng
        self._next = 0  # index of the next sample (at index / rate)
        self._emcy_sent = False

    def frames(self, t_end_s: float, roll_rad: RollAngle) -> list[can.Message]:
        """Every frame due up to stand time t_end_s."""
        p = self.params
        end = math.floor(t_end_s * p.rate_hz + _EPS) + 1
        index = np.arange(self._next, max(self._next, end))
        self._next = max(self._next, end)
        t = index / p.rate_hz
        # drawn for every sample, sent or not: a silence does not shift the noise after it
        noise = p.noise_deg * self._rng.standard_normal((len(t), 2))
        slopes = noise + p.bias_deg
        slopes[:, 0 if p.axis == "x" else 1] += np.degrees(roll_rad(t))
        counts = np.clip(np.round(slopes / p.step_deg), -32768, 32767).astype("<i2")
        heard = np.ones(len(t), dtype=bool)
        if p.silence_at_s is not None:
            heard &= ~((t >= p.silence_at_s) & (t < p.silence_at_s + p.silence_for_s))
        out = [
            can.Message(
                arbitration_id=TPDO1 + self.node_id,
                is_extended_id=False,
                data=counts[i].tobytes(),
                timestamp=float(t[i]),
            )
            for i in np.flatnonzero(heard)
        ]
        if p.emcy_at_s is not None and not self._emcy_sent and p.emcy_at_s <= t_end_s:
            self._emcy_sent = True
            data = EMCY_HARDWARE.to_bytes(2, "little") + bytes([0x01, 0, 0, 0, 0, 0])
            out.append(
                can.Message(
                    arbitration_id=EMCY + self.node_id,
                    is_extended_id=False,
                    data=data,
                    timestamp=p.emcy_at_s,  # within this call's times: they only advance
                )
            )
        return out
