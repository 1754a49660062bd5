"""A serial port read in a thread: byte chunks with their read times, for the serial source.

pyserial does the port. Each read asks for what has arrived (at least one byte, waiting at most
`POLL_S`), and takes the clock when the read returns: the chunk's last byte has just arrived,
which is what `framing` needs to time each sentence. A port that cannot be opened, or that fails
while read (a USB adapter pulled out), is one line naming the port; a silent port is just no
chunks (the engine judges the silence from time)."""

from __future__ import annotations

import errno
import os
import queue
import threading
import time
from collections.abc import Callable
from typing import Generic, Self, TypeVar

import numpy as np
import serial

from gyrostand.devices.source import ByteChunks

POLL_S = 0.1  # longest wait of one read: how soon `stop` is seen on a silent port


T = TypeVar("T")


class ReaderThread(Generic[T]):
    """A reader of a device in a daemon thread: `_run` puts what it reads in `_queue` until
    `_stop` is set; `_drain` takes it out; `_close` closes the device after the thread ended."""

    def __init__(self, name: str) -> None:
        self._queue: queue.Queue[T] = queue.Queue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def _run(self) -> None:
        raise NotImplementedError

    def _unblock(self) -> None:
        """Make a read waiting for data return (a stop is then seen at once)."""

    def _close(self) -> None:
        raise NotImplementedError

    def start(self) -> Self:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._unblock()
        if self._thread.is_alive():
            self._thread.join()
        self._close()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def alive(self) -> bool:
        """Still reading (not stopped, no error)."""
        return self._thread.is_alive()

    def _drain(self, wait_s: float) -> list[T]:
        """Everything read so far; waits up to `wait_s` for the first item."""
        got: list[T] = []
        try:
            got.append(self._queue.get(timeout=wait_s) if wait_s > 0 else self._queue.get_nowait())
            while True:
                got.append(self._queue.get_nowait())
        except queue.Empty:
            pass
        return got


class SerialPortError(RuntimeError):
    """A port that cannot be opened or read; the message names it."""


def open_port(port: str, baud: int) -> serial.Serial:
    """The port at `baud`, 8N1, or a `SerialPortError` naming it."""
    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=POLL_S)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise SerialPortError(f"serial port {port}: cannot open it ({_why(exc)})") from exc


def _why(exc: BaseException) -> str:
    """The operating system's words for a failed open (pyserial wraps them in its own)."""
    cause: BaseException | None = exc
    while cause is not None:  # the OSError or termios.error under pyserial's exception
        code = getattr(cause, "errno", None)
        if not isinstance(code, int) and cause.args and isinstance(cause.args[0], int):
            code = cause.args[0]
        if code == errno.ENOTTY:
            return "not a serial port"
        if isinstance(code, int):
            return os.strerror(code)
        cause = cause.__cause__ or cause.__context__
    return str(exc)


class SerialReader(ReaderThread[tuple[float, bytes]]):
    """Reads `port` in a background thread; `take()` gives what has arrived as `ByteChunks`.
    `error` is the one line naming the port once reading has failed."""

    def __init__(
        self,
        port: str,
        baud: int,
        *,
        clock: Callable[[], float] = time.time,
        line_clock: Callable[[int, bytes], list[tuple[float, bytes]]] | None = None,
    ) -> None:
        """`line_clock`: in virtual time, the bytes read at a stream offset as timed chunks (the
        simulated line's times, not the host's clock: `devices.serial_sim.VirtualLine`)."""
        self.port = port
        self._line_clock = line_clock
        self.baud = baud
        self._serial = open_port(port, baud)
        self._clock = clock
        self._next = 0  # stream position of the next chunk taken
        self.error: str | None = None
        self.bytes_read = 0
        self.bytes_taken = 0  # in the chunks `take` gave
        super().__init__(f"serial {port}")

    def _unblock(self) -> None:
        self._serial.cancel_read()

    def _close(self) -> None:
        self._serial.close()

    def take(self, wait_s: float = 0.0) -> ByteChunks:
        """Every chunk read since the last call; waits up to `wait_s` for the first one."""
        got = self._drain(wait_s)
        start, self._next = self._next, self._next + len(got)
        self.bytes_taken += sum(len(d) for _, d in got)
        return ByteChunks(start, tuple(d for _, d in got), np.array([t for t, _ in got]))

    def _run(self) -> None:
        ser = self._serial
        try:
            while not self._stop.is_set():
                data = ser.read(ser.in_waiting or 1)
                read_time = self._clock()
                if not data:
                    continue
                if self._line_clock is None:
                    self._queue.put((read_time, data))
                else:
                    for chunk in self._line_clock(self.bytes_read, data):
                        self._queue.put(chunk)
                self.bytes_read += len(data)
        except (serial.SerialException, OSError) as exc:
            if not self._stop.is_set():
                self.error = f"serial port {self.port}: read failed ({_why(exc)}): unplugged?"
