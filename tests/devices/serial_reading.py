"""Reading a live serial compass in a test: its first headings off a port, decoded as a campaign
would (timed by reception), with a guard against a port that never speaks."""

import time
from dataclasses import dataclass

import numpy as np

from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.serial_port import SerialReader

HANG_GUARD_S = 120.0


@dataclass(frozen=True)
class ReceptionClock:
    """Campaign time = reception time (ms) after `epoch_ms`; the sentences carry no time."""

    epoch_ms: int = 0

    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64) - self.epoch_ms


def read_headings(path: str, baud: int, count: int) -> tuple[list[float], Iec61162Source]:
    """At least `count` headings off the port (fewer only if it stays silent for the guard),
    asserting that no sentence was invalid; the source keeps its sentence counts."""
    source = Iec61162Source(baud, path)
    headings: list[float] = []
    deadline = time.monotonic() + HANG_GUARD_S
    with SerialReader(path, baud) as reader:
        while len(headings) < count and time.monotonic() < deadline:
            out = source.decode(reader.take(wait_s=1.0), ReceptionClock())
            headings += out.headings.heading_deg.tolist()
            assert out.invalid == ()
    return headings, source
