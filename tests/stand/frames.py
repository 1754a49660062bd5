"""Helpers for the stand tests: run the engine and decode what it sends."""

from dataclasses import replace

import can
import numpy as np

from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec, HeadingFrame, InvalidFrame, StandStatusFrame
from gyrostand.stand.simconfig import CompassParams, FaultParams, NoiseParams, SimConfig

CODEC = Codec()
QUIET = NoiseParams(corr_sigma_deg=0.0, white_sigma_deg=0.0, quantum_deg=0.0)


def config(**groups: dict) -> SimConfig:
    """SimConfig with fields of its parts replaced: config(noise={...}, compass={...}, seed=1)."""
    parts = {"compass": CompassParams(), "noise": NoiseParams(), "faults": FaultParams()}
    top = {}
    for name, value in groups.items():
        if name in parts:
            parts[name] = replace(parts[name], **value)
        else:
            top[name] = value
    return SimConfig(**parts, **top)


def headings(frames: list[can.Message]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stand times (s), readings (deg) and counters of the heading frames, read with numpy
    straight from the layout documented in docs/protocol.md (independent of cantools and of
    stand.packing): STAND_TIME bits 0-31 (ms), HEADING 32-50 (0.001 deg), COUNTER 52-55."""
    payload = b"".join(bytes(m.data) for m in frames if m.arbitration_id == 0x100)
    word = np.frombuffer(payload, dtype="<u8")
    t_s = (word & 0xFFFFFFFF).astype(np.float64) / 1000.0
    heading = ((word >> np.uint64(32)) & 0x7FFFF).astype(np.float64) * 0.001
    counter = ((word >> np.uint64(52)) & 0xF).astype(np.int64)
    return t_s, heading, counter


def decoded_headings(frames: list[can.Message]) -> list[HeadingFrame]:
    """The heading frames the Codec accepts."""
    return [f for f in map(CODEC.decode, frames) if isinstance(f, HeadingFrame)]


def invalid(frames: list[can.Message]) -> list[InvalidFrame]:
    return [f for f in map(CODEC.decode, frames) if isinstance(f, InvalidFrame)]


def statuses(frames: list[can.Message]) -> list[StandStatusFrame]:
    codec = Codec()  # its own: a status spans two messages
    return [f for f in map(codec.decode, frames) if isinstance(f, StandStatusFrame)]


def command(engine: StandEngine, name: str, *args: float) -> list:
    """Send one command to the engine; the decoded acks."""
    encode = {
        "set": CODEC.encode_command_set,
        "start": CODEC.encode_command_start,
        "stop": CODEC.encode_command_stop,
    }[name]
    return [CODEC.decode(m) for m in engine.receive(encode(*args))]
