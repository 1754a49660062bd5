"""Decode many CAN payloads of one DBC message at once with numpy.

cantools decodes one frame per Python call (tens of microseconds); acquisition and replay see
10^5-10^7 frames, so each signal's `SignalLayout` (the protocol's reading of the DBC: start bit,
length, byte order, sign, scale, offset, range) is applied here to whole arrays of payloads. A
property test checks that the result equals `cantools` bit for bit on every signal.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from cantools.database.can import Message

from gyrostand.stand.protocol import SignalLayout


class VectorDecoder:
    """Decodes arrays of payloads of one (non-multiplexed, <= 8 byte) DBC message."""

    def __init__(self, message: Message, signals: Sequence[str] | None = None) -> None:
        if message.length > 8 or message.is_multiplexed():
            raise ValueError(f"{message.name}: only plain messages of <= 8 bytes are vectorised")
        names = [s.name for s in message.signals] if signals is None else list(signals)
        self.message = message
        self.layouts = tuple(SignalLayout.of(message.get_signal_by_name(n)) for n in names)

    @property
    def length(self) -> int:
        return self.message.length

    @staticmethod
    def words(payloads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The (n, 8) uint8 payloads as little- and big-endian uint64 words."""
        data = np.ascontiguousarray(payloads, dtype=np.uint8)
        if data.shape[1] < 8:
            data = np.pad(data, ((0, 0), (0, 8 - data.shape[1])))
        little = data.view("<u8")[:, 0]
        big = data.view(">u8")[:, 0].astype(np.uint64)
        return little, big

    def raw(self, payloads: np.ndarray) -> dict[str, np.ndarray]:
        little, big = self.words(payloads)
        return {layout.name: layout.raw(little, big) for layout in self.layouts}

    def decode(self, payloads: np.ndarray) -> dict[str, np.ndarray]:
        """Physical values of every signal, one array entry per payload."""
        little, big = self.words(payloads)
        return {layout.name: layout.scaled(layout.raw(little, big)) for layout in self.layouts}

    def out_of_range(self, values: dict[str, np.ndarray]) -> np.ndarray:
        """Rows where a signal is outside its DBC range (`signal_bounds`, as the codec)."""
        n = len(next(iter(values.values()))) if values else 0
        bad = np.zeros(n, dtype=bool)
        for layout in self.layouts:
            v = values[layout.name]
            bad |= (v < layout.low) | (v > layout.high)
        return bad
