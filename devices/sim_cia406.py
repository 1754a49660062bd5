"""The simulated compass read by a CiA 406 absolute encoder: the stand simulator's heading
samples (the same physics, `stand.physics`) as the encoder's position value 0x6004 in its TPDO,
one per sample (its event timer at the heading rate; or on SYNC, after a SYNC it produces
itself), after a boot-up message, with its heartbeat (OPERATIONAL) every producer period. Frames
carry the stand time of their sample as their timestamp: in virtual time that is their reception
time, so runs are byte-reproducible.

Fault knobs (`Cia406Faults`): silence (no TPDO, no heartbeat) for a while, an EMCY at a stand
time; dropped samples come from the stand's own fault knobs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import can
import numpy as np

from gyrostand.devices.encoder_knobs import KNOBS
from gyrostand.stand.encoder import OPERATIONAL, Encoder


@dataclass(frozen=True)
class Cia406Faults:
    silence_at_s: float | None = None  # stand time from which the encoder sends nothing ...
    silence_for_s: float = 0.0  # ... for this long
    emcy_at_s: float | None = None  # stand time of an EMCY
    emcy_code: int = 0x1000  # its error code (CiA 301: generic error)


class Cia406Encoder:
    """A `stand.engine.HeadingTransmitter`: heading samples -> CiA 406 frames."""

    def __init__(
        self, encoder: Encoder, faults: Cia406Faults | None = None, sync_id: int | None = None
    ) -> None:
        """`sync_id`: the encoder's TPDO goes on SYNC, which it produces at this COB-ID (None:
        on its event timer)."""
        self.encoder = encoder
        self.faults = faults or Cia406Faults()
        self.sync_id = sync_id
        self._next_beat_s: float | None = None  # stand time of the next heartbeat
        self._emcy_sent = False

    def _message(self, t: float, cob_id: int, data: bytes) -> can.Message:
        return can.Message(timestamp=t, arbitration_id=cob_id, is_extended_id=False, data=data)

    def frames(
        self, t_s: np.ndarray, reading_deg: np.ndarray, index: np.ndarray
    ) -> list[can.Message]:
        enc, f = self.encoder, self.faults
        tpdo, emcy, heartbeat = enc.ids
        counts = (enc.counts(reading_deg) << enc.offset_bits).tolist()
        size = -(-(enc.offset_bits + enc.length_bits) // 8)
        out: list[can.Message] = []
        quiet_from = np.inf if f.silence_at_s is None else f.silence_at_s
        for t, word in zip(t_s.tolist(), counts, strict=True):
            if quiet_from <= t < quiet_from + f.silence_for_s:
                continue
            if self._next_beat_s is None:
                out.append(self._message(t, heartbeat, bytes([0])))  # boot-up
                self._next_beat_s = t
            if enc.heartbeat_ms and t >= self._next_beat_s:
                out.append(self._message(t, heartbeat, bytes([OPERATIONAL])))
                period_s = enc.heartbeat_ms / 1000.0
                self._next_beat_s += period_s * (1 + (t - self._next_beat_s) // period_s)
            if f.emcy_at_s is not None and t >= f.emcy_at_s and not self._emcy_sent:
                self._emcy_sent = True
                data = f.emcy_code.to_bytes(2, "little") + bytes([0x01, 0, 0, 0, 0, 0])
                out.append(self._message(t, emcy, data))
            if self.sync_id is not None:
                out.append(self._message(t, self.sync_id, b""))
            out.append(self._message(t, tpdo, int(word).to_bytes(8, "little")[:size]))
        return out


def simulated_encoder(knobs: Mapping[str, Any]) -> Cia406Encoder:
    """The simulated encoder from `KNOBS` (the defaults for those not given); ValueError naming
    each knob it cannot take, one line."""
    k = {name: default for name, (_, default, _) in KNOBS.items()} | dict(knobs)
    problems = [f"unknown cia406 knob {name!r}" for name in k if name not in KNOBS]
    for name, (kind, _, _) in KNOBS.items():
        number = isinstance(k[name], int | float) and kind in (float, float | None)
        if not (isinstance(k[name], kind) or number):
            problems.append(f"{name} {k[name]!r} is not {getattr(kind, '__name__', kind)}")
    if problems:
        raise ValueError("; ".join(problems))
    if not 1 <= k["node_id"] <= 127:
        problems.append(f"node_id {k['node_id']} is not a CANopen node id (1-127)")
    if k["counts_per_revolution"] < 2:
        problems.append(f"counts_per_revolution {k['counts_per_revolution']} is below 2")
    if k["direction"] not in ("clockwise", "counterclockwise"):
        problems.append(f"direction {k['direction']!r} is not clockwise or counterclockwise")
    if k["sync_id"] is not None and not 0 < k["sync_id"] < 0x800:
        problems.append(f"sync_id {k['sync_id']} is not an 11-bit COB-ID")
    if problems:
        raise ValueError("; ".join(problems))
    sign = 1 if k["direction"] == "clockwise" else -1
    encoder = Encoder(
        k["node_id"],
        k["counts_per_revolution"],
        zero_counts=k["zero_counts"],
        sign=sign,
        on_sync=k["sync_id"] is not None,
        heartbeat_ms=k["heartbeat_ms"],
    )
    faults = Cia406Faults(k["encoder_silence_at_s"], k["encoder_silence_for_s"], k["emcy_at_s"])
    return Cia406Encoder(encoder, faults, k["sync_id"])
