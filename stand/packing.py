"""Encode many frames of one DBC message at once with numpy.

cantools encodes one frame per Python call (~15 us); the simulator sends 16 000 frames a second
of wall time at 1000x, so each signal's `SignalLayout` (the protocol's reading of the DBC) is
applied here to whole arrays. Tests check the bytes equal the `Codec`'s (cantools) frame for
frame."""

from __future__ import annotations

from dataclasses import dataclass

import can
import numpy as np
from cantools.database.can import Message as DbcMessage
from cantools.database.can import Signal

from gyrostand.stand.protocol import ProtocolError, SignalLayout, crc8_sae_j1850_rows


@dataclass(frozen=True)
class EncodedFrames:
    """Frames of one message as arrays: payloads (n, length) uint8 and their timestamps. The
    in-process simulated stand hands them on as they are (`StandEngine.advance_parts`); a bus
    takes them as messages (`messages`)."""

    arbitration_id: int
    is_extended_id: bool
    data: np.ndarray
    timestamp: np.ndarray

    def __len__(self) -> int:
        return len(self.timestamp)

    def messages(self) -> list[can.Message]:
        return [
            can.Message(
                arbitration_id=self.arbitration_id,
                is_extended_id=self.is_extended_id,
                data=row.tobytes(),
                timestamp=float(t),
            )
            for row, t in zip(self.data, self.timestamp, strict=True)
        ]


# frames as the simulated stand builds them: one message's frames as arrays, or messages one by
# one (error frames, another protocol's); a list of parts is in stand-time order once sorted
# stably by timestamp (`frames.batch.RawFrames.from_parts`)
Part = EncodedFrames | list[can.Message]


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
        self._fields = {key: SignalLayout.of(signal) for key, signal in signals.items()}
        for layout in self._fields.values():
            if layout.is_float:
                raise ProtocolError(f"{layout.name}: float signals cannot be batch-encoded")
        self._crc_key = crc_key if crc_key in self._fields else None

    def pack(self, values: dict[str, np.ndarray], n: int) -> np.ndarray:
        data = self._bytes(values, n)
        if self._crc_key is not None:  # CRC-8/SAE-J1850 over the payload, CRC bits still zero
            data |= self._bytes({self._crc_key: crc8_sae_j1850_rows(data)}, n)
        return data

    def _bytes(self, values: dict[str, np.ndarray], n: int) -> np.ndarray:
        words = {False: np.zeros(n, np.uint64), True: np.zeros(n, np.uint64)}
        for key, value in values.items():
            layout = self._fields.get(key)
            if layout is not None:
                words[layout.big_endian] |= layout.place(value)
        little = words[False].astype("<u8").view(np.uint8).reshape(n, 8)
        big = words[True].astype(">u8").view(np.uint8).reshape(n, 8)
        return (little | big)[:, : self.length].copy()

    def frames(self, data: np.ndarray, timestamps: np.ndarray) -> EncodedFrames:
        """Payloads from `pack` with their timestamps, as this message's frames."""
        return EncodedFrames(self.arbitration_id, self.is_extended_id, data, timestamps)

    def messages(self, data: np.ndarray, timestamps: np.ndarray) -> list[can.Message]:
        return self.frames(data, timestamps).messages()
