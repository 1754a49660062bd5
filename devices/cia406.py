"""The heading source "cia406": a CiA 406 absolute encoder (CANopen encoder profile) reading the
compass card or a repeater, listened to, never configured (the encoder: `stand.encoder`).

Its position value (0x6004) in its TPDO becomes the heading (`Encoder.heading_deg`), timed by
reception on the campaign clock (`devices.clock`). The PDO carries no sequence number (a gap
shows from time only). EMCY (0x80 + node id), heartbeat (0x700 + node id) state changes and a
heartbeat missing for HEARTBEAT_MISSES producer periods are events; short frames, a position
beyond the total measuring range 0x6002 and positions before the campaign clock is known are
invalid with their reason. Frames of other nodes are not the source's.
"""

from __future__ import annotations

import math

import numpy as np
from canopen.emcy import EmcyError
from canopen.nmt import NMT_STATES

from gyrostand.devices.clock import NO_CLOCK, TIME_BASE, VIRTUAL_TIME_BASE
from gyrostand.devices.source import UNNUMBERED, CampaignClock, SourceInfo, SourceOutput
from gyrostand.frames.batch import DeviceEvent, Headings, RawFrames
from gyrostand.stand.encoder import HEARTBEAT_MISSES, OPERATIONAL, Encoder
from gyrostand.stand.protocol import InvalidFrame


def encoder_info(encoder: Encoder, virtual: bool = False) -> SourceInfo:
    """What the analysis and the campaign record state about the encoder as heading source
    (`virtual`: simulated in virtual time, `devices.decoder.source_info`)."""
    trigger = "on SYNC" if encoder.on_sync else "on its event timer"
    clock = VIRTUAL_TIME_BASE if virtual else TIME_BASE
    base = f"{clock}; CiA 406 TPDO 0x{encoder.tpdo_id:03X} sent {trigger}"
    return SourceInfo("cia406", encoder.resolution_deg, base, UNNUMBERED)


class Cia406Heading:
    """The TPDO position of one encoder -> `Headings` on the campaign clock."""

    def __init__(self, encoder: Encoder, bus: int | None = None) -> None:
        """`bus`: the `RawFrames.channel` the encoder is on (None: any, a one-bus stream)."""
        self.encoder = encoder
        self.bus = bus
        self.info = encoder_info(encoder)
        self._ids = np.array(encoder.ids, dtype=np.uint32)
        self._state: int | None = None  # the last NMT state its heartbeat gave
        self._heartbeat_s: float | None = None  # reception time of the last heartbeat
        self._missing = False  # a missing heartbeat told, not yet back
        self._need = math.ceil((encoder.offset_bits + encoder.length_bits) / 8)

    def claims(self, raw: RawFrames) -> np.ndarray:
        """Rows that are this encoder's (its TPDO, EMCY and heartbeat; 11-bit identifiers)."""
        ok = ~(raw.is_extended | raw.is_error | raw.is_remote) & raw.on_bus(self.bus)
        return ok & np.isin(raw.arbitration_id, self._ids)

    def decode(
        self, raw: RawFrames, clock: CampaignClock, claimed: np.ndarray | None = None
    ) -> SourceOutput:
        """`claimed`: `claims(raw)`, when the caller has it already."""
        claimed = self.claims(raw) if claimed is None else claimed
        tpdo, emcy, heartbeat = self.encoder.ids
        invalid: list[tuple[int, InvalidFrame]] = []
        events: list[tuple[int, DeviceEvent]] = []
        rows = np.flatnonzero(claimed & (raw.arbitration_id == tpdo))
        headings = self._headings(raw, rows, clock, invalid)
        beats = np.flatnonzero(claimed & (raw.arbitration_id == heartbeat)).tolist()
        for start, stop in zip([0, *beats], [*beats, len(raw)], strict=True):
            self._supervise(raw, start, stop, events)
            if stop < len(raw):
                self._heartbeat(raw, stop, invalid, events)
        for row in np.flatnonzero(claimed & (raw.arbitration_id == emcy)).tolist():
            self._emcy(raw, row, invalid, events)
        return SourceOutput(
            headings,
            tuple(sorted(invalid, key=lambda x: x[0])),
            tuple(sorted(events, key=lambda x: x[0])),
            claimed,
        )

    def _invalid(self, raw: RawFrames, row: int, reason: str) -> tuple[int, InvalidFrame]:
        data = raw.data[row, : raw.dlc[row]].tobytes()
        return raw.start + row, InvalidFrame(int(raw.arbitration_id[row]), reason, data)

    def _headings(
        self,
        raw: RawFrames,
        rows: np.ndarray,
        clock: CampaignClock,
        invalid: list[tuple[int, InvalidFrame]],
    ) -> Headings:
        """The TPDO frames: usable ones as headings, the rest invalid. Vectorised over the
        batch (the (n, 8) payloads as little-endian 64-bit words, shifted and masked): canopen's
        PdoMap decodes one frame per call through its object dictionary, 60x slower (5,600 vs
        360,000 TPDOs/s on this machine, loaded); tests check the two agree."""
        enc, node = self.encoder, self.encoder.node_id
        words = raw.data[rows].copy().view("<u8")[:, 0]
        counts = (words >> np.uint64(enc.offset_bits)) & np.uint64((1 << enc.length_bits) - 1)
        pos = rows + raw.start
        t_ms = clock.to_campaign_ms(pos, raw.timestamp[rows])
        short = raw.dlc[rows] < self._need
        beyond = np.zeros(len(rows), dtype=bool)
        if enc.total_range is not None:
            beyond = counts >= np.uint64(enc.total_range)
        early = t_ms == NO_CLOCK
        for i in np.flatnonzero(short | beyond | early).tolist():
            row = int(rows[i])
            if short[i]:
                why = f"{int(raw.dlc[row])} bytes, the position 0x6004 needs {self._need}"
            elif beyond[i]:
                why = f"position {int(counts[i])} beyond the total range 0x6002 ({enc.total_range})"
            else:
                why = "received before the stand's first status (no clock)"
            invalid.append(self._invalid(raw, row, f"encoder node {node} TPDO: {why}"))
        good = ~(short | beyond | early)
        return Headings(
            pos=pos[good],
            t_ms=t_ms[good],
            heading_deg=enc.heading_deg(counts[good]),
            valid=np.ones(int(good.sum()), dtype=bool),
            counter=np.full(int(good.sum()), -1, dtype=np.int64),
        )

    def _supervise(self, raw: RawFrames, start: int, stop: int, events: list) -> None:
        """A missing heartbeat: told at the first frame of the stream received more than
        HEARTBEAT_MISSES periods after the last heartbeat (rows start..stop-1: up to the next
        heartbeat or the batch's end), so replay tells it where live did."""
        period_s = self.encoder.heartbeat_ms / 1000.0
        if period_s <= 0 or self._missing or len(raw) == 0:
            return
        if self._heartbeat_s is None:
            self._heartbeat_s = float(raw.timestamp[0])  # supervised from the first frame heard
        deadline = self._heartbeat_s + HEARTBEAT_MISSES * period_s
        late = np.flatnonzero(raw.timestamp[start:stop] > deadline)
        if len(late):
            self._missing = True
            text = (
                f"encoder node {self.encoder.node_id}: no heartbeat for {HEARTBEAT_MISSES} "
                f"producer periods ({self.encoder.heartbeat_ms} ms each)"
            )
            pos = raw.start + start + int(late[0])
            events.append((pos, DeviceEvent("heartbeat lost", "error", text)))

    def _heartbeat(self, raw: RawFrames, row: int, invalid: list, events: list) -> None:
        node, state = self.encoder.node_id, int(raw.data[row, 0]) & 0x7F
        if raw.dlc[row] != 1 or int(raw.data[row, 0]) & 0x7F not in NMT_STATES:
            why = f"{int(raw.dlc[row])} bytes" if raw.dlc[row] != 1 else f"state {state}"
            invalid.append(self._invalid(raw, row, f"encoder node {node} heartbeat: {why}"))
            return
        pos = raw.start + row
        self._heartbeat_s = float(raw.timestamp[row])
        if self._missing:
            self._missing = False
            text = f"encoder node {node}: heartbeat back ({NMT_STATES[state]})"
            events.append((pos, DeviceEvent("heartbeat back", "info", text)))
        if state == self._state:
            return
        before, self._state = self._state, state
        if state == OPERATIONAL:
            if before not in (None, 0):  # (a boot-up is followed by the state it starts in)
                text = f"encoder node {node} is OPERATIONAL again (was {NMT_STATES[before]})"
                events.append((pos, DeviceEvent("nmt state", "info", text)))
        elif state == 0:
            text = f"encoder node {node} booted (boot-up message)"
            events.append((pos, DeviceEvent("nmt state", "info", text)))
        else:
            text = f"encoder node {node} is {NMT_STATES[state]}: no position until OPERATIONAL"
            events.append((pos, DeviceEvent("nmt state", "warning", text)))

    def _emcy(self, raw: RawFrames, row: int, invalid: list, events: list) -> None:
        node, data = self.encoder.node_id, raw.data[row].tobytes()
        if raw.dlc[row] != 8:
            why = f"encoder node {node} EMCY: {int(raw.dlc[row])} bytes, not 8"
            invalid.append(self._invalid(raw, row, why))
            return
        error = EmcyError(int.from_bytes(data[:2], "little"), data[2], data[3:], 0.0)
        if error.code & 0xFF00 == 0:
            severity, text = "info", f"encoder node {node} EMCY: error reset"
        else:
            severity = "error"
            text = f"encoder node {node} EMCY: {error}, error register 0x{error.register:02X}"
            text += f", manufacturer data {error.data.hex()}"
        events.append((raw.start + row, DeviceEvent("emcy", severity, text)))
