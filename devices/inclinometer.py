"""The plan's [inclinometer] heard on the stand's bus, listen-only: its slope samples as
`RollSample`s on the campaign clock (timed by reception, `devices.clock`), its faults as events.

"cia410" (CiA 410): TPDO1 (0x180 + node id) with the slopes in the CiA 410 default mapping,
slope long16 0x6010 (x) then slope lateral16 0x6020 (y), INTEGER16 in the plan's `scale` (deg
per count: the resolution 0x6000 the lab set); EMCY (0x80 + node id) an error event (code 0:
error reset, an info event); its boot-up (0x700 + node id, state 0) an info event.
"j1939" (SAE J1939-71): Slope Sensor Information 2, PGN 61481, from the source address: pitch
(x) in bytes 1-3, roll (y) in bytes 4-6 (SPNs 5253, 5254: 24 bits, 1/32768 deg per bit, offset
-250 deg); a value in the error/not-available range (above 0xFAFFFF) is no sample, told once as
a warning.

A silence longer than SILENCE_INTERVALS sample intervals (the shortest one seen) between two
samples is a warning event; a silence that lasts to the end of a series is the engine's to tell
(no sample measured it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrostand.devices.clock import NO_CLOCK, ReceptionClock
from gyrostand.devices.nmea2000 import split_id
from gyrostand.frames.batch import DeviceEvent, RawFrames, RollSample
from gyrostand.stand.inclinometer import EMCY, TPDO1

SOURCE = "inclinometer"  # its name in the measured-motion table
SSI2 = 61481  # J1939 Slope Sensor Information 2
J1939_STEP_DEG = 1.0 / 32768.0
J1939_OFFSET_DEG = -250.0
J1939_VALID_MAX = 0xFAFFFF  # above: error / not available (J1939-71, 3-byte parameters)
HEARTBEAT = 0x700
SILENCE_INTERVALS = 5
MIN_SILENCE_MS = 500


@dataclass(frozen=True)
class Mount:
    """The plan's [inclinometer] (`Plan.inclinometer_mount`): protocol, node id (cia410) or
    source address (j1939), axis, scale."""

    protocol: str
    address: int
    axis: str
    scale: float


class InclinometerDecoder:
    """One inclinometer's frames -> (stream position, RollSample | DeviceEvent)."""

    def __init__(self, mount: Mount) -> None:
        self.plan = mount
        self._last_ms: int | None = None
        self._interval_ms: int | None = None  # the shortest spacing of samples seen
        self._told_unavailable = False
        if mount.protocol == "cia410":
            self.label = f"inclinometer (CiA 410 node {mount.address})"
        else:
            self.label = f"inclinometer (J1939 source address {mount.address})"

    def claims(self, raw: RawFrames) -> np.ndarray:
        """Rows that are the inclinometer's (its slopes, EMCY, heartbeat)."""
        ok = ~(raw.is_error | raw.is_remote)
        ids = raw.arbitration_id.astype(np.int64)
        if self.plan.protocol == "cia410":
            node = self.plan.address
            own = np.isin(ids, (TPDO1 + node, EMCY + node, HEARTBEAT + node))
            return ok & ~raw.is_extended & own
        pgn, source = split_id(raw.arbitration_id)
        return ok & raw.is_extended & (pgn == SSI2) & (source == self.plan.address)

    def decode(
        self, raw: RawFrames, clock: ReceptionClock
    ) -> list[tuple[int, RollSample | DeviceEvent]]:
        rows = np.flatnonzero(self.claims(raw))
        if not len(rows):
            return []
        t_ms = clock.to_campaign_ms(rows + raw.start, raw.timestamp[rows])
        out: list[tuple[int, RollSample | DeviceEvent]] = []
        for row, t in zip(rows.tolist(), t_ms.tolist(), strict=True):
            pos = raw.start + row
            if t == NO_CLOCK:
                continue  # before the stand's first status: no campaign time, nothing measured
            found = self._frame(int(raw.arbitration_id[row]), raw.data[row], int(raw.dlc[row]))
            if isinstance(found, float):
                silence = self._silence(t)
                if silence is not None:
                    out.append((pos, silence))
                out.append((pos, RollSample(SOURCE, t, found)))
            elif found is not None:
                out.append((pos, found))
        return out

    def _frame(self, can_id: int, data: np.ndarray, dlc: int) -> float | DeviceEvent | None:
        """The slope (deg) of a sample frame, an event, or None."""
        plan = self.plan
        if plan.protocol == "j1939":
            at = 0 if plan.axis == "x" else 3
            value = int(data[at]) | int(data[at + 1]) << 8 | int(data[at + 2]) << 16
            if dlc < 8 or value > J1939_VALID_MAX:
                if self._told_unavailable:
                    return None
                self._told_unavailable = True
                why = f"{dlc} bytes" if dlc < 8 else f"slope 0x{value:06X} (error/not available)"
                return DeviceEvent("inclinometer", "warning", f"{self.label}: SSI2 with {why}")
            return plan.scale * (value * J1939_STEP_DEG + J1939_OFFSET_DEG)
        base = can_id - plan.address
        if base == TPDO1:
            at = 0 if plan.axis == "x" else 2
            if dlc < at + 2:
                return DeviceEvent(
                    "inclinometer", "warning", f"{self.label}: TPDO1 of {dlc} bytes, no slope"
                )
            count = int(np.frombuffer(data[at : at + 2].tobytes(), "<i2")[0])
            return plan.scale * count
        if base == EMCY:
            code = int(data[0]) | int(data[1]) << 8
            if code == 0:
                return DeviceEvent("inclinometer", "info", f"{self.label}: EMCY error reset")
            message = f"{self.label}: EMCY 0x{code:04X}, error register 0x{int(data[2]):02X}"
            return DeviceEvent("inclinometer EMCY", "error", message)
        if dlc >= 1 and int(data[0]) == 0:
            return DeviceEvent("inclinometer", "info", f"{self.label}: boot-up")
        return None  # its heartbeat

    def _silence(self, t_ms: int) -> DeviceEvent | None:
        last, self._last_ms = self._last_ms, t_ms
        if last is None:
            return None
        gap = t_ms - last
        interval = self._interval_ms
        if gap > 0 and (interval is None or gap < interval):
            self._interval_ms = gap
        if interval is None or gap <= max(SILENCE_INTERVALS * interval, MIN_SILENCE_MS):
            return None
        message = (
            f"{self.label}: silent for {gap / 1000:g} s (no slope from stand time "
            f"{last / 1000:g} s to {t_ms / 1000:g} s)"
        )
        return DeviceEvent("inclinometer silence", "warning", message)
