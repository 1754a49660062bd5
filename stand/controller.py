"""Client for the roll stand: command rocking, wait for acknowledgements, track the status.

The controller is a `can.Listener`: register it on the caller's `can.Notifier`; it never reads
the bus itself. Commands block the calling thread until the stand's ack (or a typed error)."""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass

import can

from gyrostand.analysis.angles import wrap180
from gyrostand.stand.protocol import AckFrame, Codec, StandStatusFrame


class StandError(Exception):
    """The stand could not be commanded."""


class StandTimeout(StandError):
    """The stand did not acknowledge a command in time."""


class StandRefused(StandError):
    """The stand refused a command."""

    def __init__(self, command: str, reason: str) -> None:
        super().__init__(f"stand refused {command!r}: {reason}")
        self.command = command
        self.reason = reason


@dataclass(frozen=True)
class TrackingError:
    """How far the stand's measured motion is from the command."""

    direction_error_deg: float  # measured - commanded, wrapped to [-180, 180)
    amplitude_rel_error: float  # (measured - commanded) / commanded
    period_rel_error: float
    stand_time_ms: int  # of the status it was computed from

    def within(self, relative: float, direction_deg: float) -> bool:
        return (
            abs(self.amplitude_rel_error) <= relative
            and abs(self.period_rel_error) <= relative
            and abs(self.direction_error_deg) <= direction_deg
        )


class StandController(can.Listener):
    def __init__(self, bus: can.BusABC, codec: Codec, ack_timeout_s: float = 2.0) -> None:
        self._bus = bus
        self._codec = codec
        self.ack_timeout_s = ack_timeout_s  # wall seconds
        self._cond = threading.Condition()
        self._acks: list[AckFrame] = []
        self._last_status: StandStatusFrame | None = None
        self._seq = 0
        self._command_lock = threading.Lock()  # one command in flight at a time
        # decode only what the controller needs: it sees every frame (heading at 10 kHz at 1000x)
        self._wanted = codec.status_arbitration_ids | {codec.ack_arbitration_id}

    # ------------------------------------------------------------------------------ listener
    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id not in self._wanted or msg.is_error_frame:
            return
        frame = self._codec.decode(msg)
        if isinstance(frame, StandStatusFrame):
            self._last_status = frame
        elif isinstance(frame, AckFrame):
            with self._cond:
                self._acks.append(frame)
                self._cond.notify_all()

    def on_error(self, exc: Exception) -> None:
        """The notifier's bus failed: wake any waiting command so it times out promptly."""
        with self._cond:
            self._cond.notify_all()

    # ------------------------------------------------------------------------------ commands
    def set_rocking(self, direction_deg: float, amplitude_cm: float, period_s: float) -> None:
        """Configure K (deg), A (cm) and tau (s); raises StandTimeout / StandRefused."""
        self._command("set", direction_deg, amplitude_cm, period_s)

    def start(self) -> None:
        """Start rocking with the configured motion."""
        self._command("start")

    def stop(self) -> None:
        """Stop rocking (accepted when already still).

        python-can's `Notifier.stop()` also calls `Listener.stop()` (its flush hook) after its
        receive thread has ended, when no ack could arrive any more: that call is ignored."""
        if sys._getframe(1).f_code is can.Notifier.stop.__code__:
            return
        self._command("stop")

    def post(self, name: str, *motion: float) -> int:
        """Send one command ("set" with motion K deg, A cm, tau s; "start"; "stop") without
        waiting for the ack (the caller reads acks from the stream); its sequence number."""
        with self._command_lock:
            return self._send(name, *motion)

    def _send(
        self,
        name: str,
        direction_deg: float = 0.0,
        amplitude_cm: float = 0.0,
        period_s: float = 0.0,
    ) -> int:
        self._seq = (self._seq + 1) % 16
        seq = self._seq
        # ProtocolError (a ValueError) for out-of-range values
        msg = self._codec.encode_command(name, direction_deg, amplitude_cm, period_s, seq=seq)
        with self._cond:
            self._acks.clear()
        try:
            self._bus.send(msg)
        except can.CanError as exc:
            raise StandError(f"could not send {name!r} to the stand: {exc}") from exc
        return seq

    def _command(self, name: str, *motion: float) -> AckFrame:
        """Send like `post` (motion: K, A, tau for "set"), then wait for the ack."""
        with self._command_lock:
            seq = self._send(name, *motion)
            ack = self._wait_ack(name, seq)
            if not ack.accepted:
                raise StandRefused(name, ack.reason)
            return ack

    def _wait_ack(self, name: str, seq: int) -> AckFrame:
        deadline = time.monotonic() + self.ack_timeout_s
        with self._cond:
            while True:
                for ack in self._acks:
                    if ack.command == name and (ack.seq == seq or not self._codec.has_sequence):
                        return ack
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise StandTimeout(
                        f"stand did not acknowledge {name!r} within {self.ack_timeout_s:g} s"
                    )
                self._cond.wait(remaining)

    # ------------------------------------------------------------------------------ status
    @property
    def last_status(self) -> StandStatusFrame | None:
        return self._last_status

    def tracking_error(
        self, direction_deg: float, amplitude_cm: float, period_s: float
    ) -> TrackingError:
        """Measured motion (last status) against the command; StandError without a rocking
        status."""
        status = self._last_status
        if status is None or not status.rocking:
            raise StandError("no status of a rocking stand received yet")
        return TrackingError(
            direction_error_deg=wrap180(status.direction_deg - direction_deg),
            amplitude_rel_error=(status.amplitude_cm - amplitude_cm) / amplitude_cm,
            period_rel_error=(status.period_s - period_s) / period_s,
            stand_time_ms=status.stand_time_ms,
        )
