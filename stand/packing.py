"""Encode many frames of one DBC message at once with numpy.

cantools encodes one frame per Python call (~15 us); the simulator sends 16 000 frames a second
of wall time at 1000x, so the layout cantools parses from the DBC (start bit, length, byte order,
scale, offset) is applied here to whole arrays. Tests check the bytes equal the `Codec`'s
(cantools) frame for frame."""

from __future__ import annotations

from dataclasses import dataclass

import can
import numpy as np
from cantools.database.can import Message as DbcMessage
from cantools.database.can import Signal

from gyrostand.stand.protocol import CRC8_J1850_TABLE, ProtocolError

_CRC_TABLE = np.array(CRC8_J1850_TABLE, dtype=np.uint8)


@dataclass(frozen=True)
class _Placement:
    """Where a signal's raw value sits in the payload read as a 64-bit integer."""

    shift: int  # bit position of its least significant bit
    length: int
    big_endian: bool
    scale: float
    offset: float

    @classmethod
    def of(cls, signal: Signal) -> _Placement:
        if signal.is_float:
            raise ProtocolError(f"{signal.name}: float signals cannot be batch-encoded")
        big = signal.byte_order == "big_endian"
        # DBC Motorola numbering: start is the MSB; bit b of byte k is bit (7 - k) * 8 + b of the
        # big-endian 64-bit word. Intel: start is the LSB of the little-endian word.
        shift = (
            (7 - signal.start // 8) * 8 + signal.start % 8 - signal.length + 1
            if big
            else (signal.start)
        )
        return cls(shift, signal.length, big, signal.scale, signal.offset)

    def place(self, values: np.ndarray) -> np.ndarray:
        """Raw values (rounded as cantools rounds, two's complement) at their bit position."""
        raw = np.round((np.asarray(values, dtype=np.float64) - self.offset) / self.scale)
        bits = raw.astype(np.int64).view(np.uint64) & np.uint64((1 << self.length) - 1)
        return bits << np.uint64(self.shift)


class BatchEncoder:
    """Payloads (n, message length) as uint8 of many frames of one DBC message, given arrays of
    physical values by signal-map key; the CRC (when `crc_key` is mapped) is computed last.

    Like `Codec.encode_*(..., strict=False)`: no range check, so the simulator can put
    out-of-range values on the wire deliberately. Unset signals are raw 0."""

    def __init__(
        self, message: DbcMessage, signals: dict[str, Signal], crc_key: str | None = None
    ) -> None:
        if message.length > 8:
            raise ProtocolError(f"{message.name}: batch encoding handles frames of <= 8 bytes")
        self.arbitration_id = message.frame_id
        self.is_extended_id = message.is_extended_frame
        self.length = message.length
        self._fields = {key: _Placement.of(signal) for key, signal in signals.items()}
        self._crc_key = crc_key if crc_key in self._fields else None

    def pack(self, values: dict[str, np.ndarray], n: int) -> np.ndarray:
        data = self._bytes(values, n)
        if self._crc_key is not None:  # CRC-8/SAE-J1850 over the payload, CRC bits still zero
            crc = np.full(n, 0xFF, dtype=np.uint8)
            for column in data.T:
                crc = _CRC_TABLE[crc ^ column]
            data |= self._bytes({self._crc_key: crc ^ np.uint8(0xFF)}, n)
        return data

    def _bytes(self, values: dict[str, np.ndarray], n: int) -> np.ndarray:
        words = {False: np.zeros(n, np.uint64), True: np.zeros(n, np.uint64)}
        for key, value in values.items():
            placement = self._fields.get(key)
            if placement is not None:
                words[placement.big_endian] |= placement.place(value)
        little = words[False].astype("<u8").view(np.uint8).reshape(n, 8)
        big = words[True].astype(">u8").view(np.uint8).reshape(n, 8)
        return (little | big)[:, : self.length].copy()

    def messages(self, data: np.ndarray, timestamps: np.ndarray) -> list[can.Message]:
        return [
            can.Message(
                arbitration_id=self.arbitration_id,
                is_extended_id=self.is_extended_id,
                data=row.tobytes(),
                timestamp=float(t),
            )
            for row, t in zip(data, timestamps, strict=True)
        ]
