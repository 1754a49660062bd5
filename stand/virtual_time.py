"""Virtual time: the simulated stand runs on the controller's progress, not on a wall clock.

The coupling is two messages of the shipped DBC (docs/protocol.md, "Virtual time"):

- SIM_SYNC (controller -> stand): "I have processed every frame up to PROCESSED_TIME". The
  stand may then simulate up to PROCESSED_TIME + LEAD, and a STAND_COMMAND that follows this
  SIM_SYNC takes effect at exactly that stand time (the stand has not simulated past it). So
  every command takes effect at a stand time fixed by the stream alone.
- SIM_CLOCK (simulation -> controller): the simulation's clock at every whole stand second, sent
  also while the simulated stand is silent (a fault knob), so that silence and missing
  acknowledgements are timed in stand time.

In virtual time the simulated stand also repeats each command on the bus at the stand time it
takes effect, just before its acknowledgement: the controller's stream (and raw log) then holds
the command at a position fixed by the stand time, wherever the host's scheduling put the
original.

The messages are gyrostand's own simulation control, so they always come from the shipped DBC
(a lab's DBC for its own angle sensor need not define them).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import can
import cantools
import numpy as np
from cantools.database.can import Message as DbcMessage

from gyrostand.stand.packing import BatchEncoder, EncodedFrames
from gyrostand.stand.protocol import ProtocolError, load_dbc

CLOCK_INTERVAL_MS = 1000  # SIM_CLOCK period in stand time
DEFAULT_LEAD_MS = 60_000  # how far the stand may run ahead of the controller (= command latency)


@dataclass(frozen=True)
class SyncFrame:
    processed_ms: int
    lead_ms: int

    @property
    def horizon_ms(self) -> int:
        """The stand may simulate up to here; a following command takes effect here."""
        return self.processed_ms + self.lead_ms


@cache
def _messages() -> tuple[DbcMessage, DbcMessage]:
    db = load_dbc()
    return db.get_message_by_name("SIM_SYNC"), db.get_message_by_name("SIM_CLOCK")


def sync_message() -> DbcMessage:
    return _messages()[0]


def clock_message() -> DbcMessage:
    return _messages()[1]


def check_free(database: cantools.database.can.Database) -> None:
    """ProtocolError when a (lab's) DBC uses the virtual-time identifiers for other messages."""
    for message in _messages():
        try:
            other = database.get_message_by_frame_id(message.frame_id)
        except KeyError:
            continue
        if other.name != message.name:
            raise ProtocolError(
                f"the DBC's {other.name} uses ID 0x{message.frame_id:X}, which virtual time "
                f"needs for {message.name}"
            )


def encode_sync(processed_ms: int, lead_ms: int) -> can.Message:
    message = sync_message()
    return can.Message(
        arbitration_id=message.frame_id,
        is_extended_id=False,
        data=message.encode({"PROCESSED_TIME": processed_ms, "LEAD": lead_ms}),
    )


def decode_sync(msg: can.Message) -> SyncFrame | None:
    """The SIM_SYNC content, or None for any other frame (or a malformed one)."""
    message = sync_message()
    if msg.arbitration_id != message.frame_id or msg.is_error_frame or len(msg.data) != 8:
        return None
    values = message.decode(bytes(msg.data))
    return SyncFrame(int(values["PROCESSED_TIME"]), int(values["LEAD"]))


class ClockEncoder:
    """SIM_CLOCK frames for every whole clock interval in a stand-time span, batch-encoded."""

    def __init__(self, clock_ms: int = 0) -> None:
        """`clock_ms`: the stand clock at simulated stand time 0 (`StandEngine.clock_ms`)."""
        message = clock_message()
        self.clock_ms = clock_ms
        self._encoder = BatchEncoder(message, {"time": message.get_signal_by_name("STAND_TIME")})
        self._next = 0  # index of the next tick

    def until(self, t_s: float) -> list[can.Message]:
        """The ticks due in (last call's t, t_s], with the stand time (s) as their timestamp."""
        return self.frames_until(t_s).messages()

    def frames_until(self, t_s: float) -> EncodedFrames:
        """`until`'s ticks as arrays."""
        end = int(t_s * 1000) // CLOCK_INTERVAL_MS + 1
        ticks = np.arange(self._next, max(self._next, end))
        self._next = max(self._next, end)
        t_ms = ticks * CLOCK_INTERVAL_MS
        clock = {"time": t_ms + self.clock_ms}
        return self._encoder.frames(self._encoder.pack(clock, len(t_ms)), t_ms / 1000)

    def now(self, t_s: float) -> can.Message:
        """One SIM_CLOCK at stand time t_s (the answer to a new controller)."""
        t_ms = np.array([round(t_s * 1000)])
        clock = {"time": t_ms + self.clock_ms}
        return self._encoder.messages(self._encoder.pack(clock, 1), t_ms / 1000)[0]
