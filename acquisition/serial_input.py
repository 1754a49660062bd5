"""A campaign's serial IEC 61162 compass: its port read in a thread, its raw log next to the
CAN log, and the decoder that merges its sentences with the stand's frames (`run_live`).

A real compass: the plan's [compass] port at its baud rate (pyserial), each chunk timed when
its read returned (`devices.serial_port`). The simulated stand's compass (virtual time): the
stand's heading transmitter writes its line's bytes onto a pseudo-terminal pair as the stand
computes them (`devices.serial_sim.VirtualLine`); they come back through the same pyserial path,
timed by the simulation, so a run is byte-reproducible. Either way every piece read goes to an
IEC 61162-450 TAG-block log (`devices.tagblock`), the CAN log's name with `.nmea`."""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.serial_config import SerialCompassConfig
from gyrostand.devices.serial_decoder import SerialSourceDecoder
from gyrostand.devices.serial_port import SerialPortError, SerialReader, open_port
from gyrostand.devices.serial_replay import check_serial_logs, serial_log_path, serial_replay
from gyrostand.devices.serial_sim import SerialCompass, VirtualLine
from gyrostand.devices.source import ByteChunks
from gyrostand.devices.tagblock import TagBlockWriter
from gyrostand.frames.batch import RawFrames
from gyrostand.frames.logfile import sha256_of
from gyrostand.plan.model import Plan
from gyrostand.stand.protocol import Codec

HDT_RESOLUTION_DEG = 0.1  # a real compass: HDT's one decimal (THS's two are finer)
SIM_SENTENCES = ("THS", "ROT")  # the simulated compass: THS, IEC 61162-1 Ed. 5's heading
THS_RESOLUTION_DEG = 0.01
READ_GUARD_WALL_S = 60.0  # virtual time: the pty gives back what was written at once
SIM_PORT = "(simulated line)"  # its name in messages (the pty's path varies)


def check_serial(plan: Plan) -> None:
    """Before anything is written: a real compass's port opens (`SerialPortError` naming it);
    the simulated compass's line can carry its sentences (`SerialSimError`)."""
    if plan.compass.protocol != "iec61162":
        return
    if plan.bus.simulated:
        simulated_compass(plan).check()
        return
    assert plan.compass.port is not None  # (plan.codec.prepare)
    open_port(plan.compass.port, plan.compass.baud).close()


def serial_source(plan: Plan, raw_log: TagBlockWriter | None = None) -> Iec61162Source:
    """The plan's serial heading source (live and replay): its port's name, its resolution
    (HDT's for a real compass, THS's for the simulated one) and time base."""
    baud = plan.compass.baud
    if not plan.bus.simulated:
        return Iec61162Source(baud, plan.compass.port or "", HDT_RESOLUTION_DEG, raw_log)
    source = Iec61162Source(baud, SIM_PORT, THS_RESOLUTION_DEG, raw_log)
    source.info = replace(source.info, time_base=virtual_time_base(baud))
    return source


def simulated_compass(plan: Plan) -> SerialCompassConfig:
    """The simulated stand's serial compass: THS and ROT at the stand's heading rate."""
    from gyrostand.plan.codec import sim_config

    rate = sim_config(plan.bus).heading_rate_hz
    return SerialCompassConfig(
        rate_hz=rate, baud=plan.compass.baud, sentences=SIM_SENTENCES, seed=plan.bus.seed
    )


def virtual_time_base(baud: int) -> str:
    """The time base of the simulated serial compass's headings."""
    return (
        f"reception of each sentence's first byte ({baud} baud) on the stand clock; virtual "
        "time: the simulated compass's sentences are sent at their sample's stand time"
    )


class LineTransmitter:
    """The simulated stand's heading transmitter on a virtual serial line: each batch of
    samples written onto the pty at once, timed on the stand clock (from `clock_ms`)."""

    def __init__(self, compass: SerialCompass, line: VirtualLine, clock_ms: int) -> None:
        self.compass, self.line, self.clock_s = compass, line, clock_ms / 1000.0

    def frames(self, t_s: np.ndarray, reading_deg: np.ndarray, index: np.ndarray) -> list:
        self.compass.frames(t_s + self.clock_s, reading_deg, index)
        self.line.write(self.compass.take())
        return []


class SerialInput:
    """The compass's port (or the simulated one's pty), its reader, its raw log and the
    merged-stream decoder (`decoder`). `skip`: pieces already in earlier segments' logs (a
    resumed simulation re-run from its start logs only the pieces after them)."""

    def __init__(
        self, plan: Plan, codec: Codec, can_log: Path, clock_ms: int = 0, skip: int = 0
    ) -> None:
        compass = plan.compass
        self.line: VirtualLine | None = None
        self.transmitter: LineTransmitter | None = None
        if plan.bus.simulated:
            config = simulated_compass(plan)
            self.line = VirtualLine(config.baud)
            self.transmitter = LineTransmitter(SerialCompass(config), self.line, clock_ms)
            port, line_clock = self.line.path, self.line.received
        else:
            assert compass.port is not None
            port, line_clock = compass.port, None
        self.path = serial_log_path(can_log)
        try:
            self.reader = SerialReader(port, compass.baud, line_clock=line_clock).start()
        except SerialPortError:
            self._close_line()
            raise
        self.log = TagBlockWriter(self.path, skip=skip)
        self._virtual = plan.bus.timing == "virtual"
        self.source = serial_source(plan)
        self.decoder = SerialSourceDecoder(codec, self.source, self.take, stand_time=self._virtual)
        self.info = self.source.info

    def stream_pos(self, frame: int) -> int:
        """The stream position of the last batch's frame `frame` (its end: after the last)."""
        pos = self.decoder.frame_pos
        return int(pos[frame]) if frame < len(pos) else self.decoder.end

    def take(self) -> ByteChunks:
        """What the port has read; in virtual time everything written onto the line so far
        (the stand wrote a sample's bytes before it sent the frames of that time)."""
        if self.line is None:
            return self.reader.take()
        written = self.line.written
        chunks = [self.reader.take()]
        deadline = time.monotonic() + READ_GUARD_WALL_S
        while self.reader.bytes_taken < written and self.reader.alive:
            if time.monotonic() > deadline:
                self.reader.error = f"serial port {self.line.path}: the written bytes never came"
                break
            chunks.append(self.reader.take(wait_s=0.5))
        data = tuple(d for c in chunks for d in c.data)
        return ByteChunks(0, data, np.concatenate([c.t_s for c in chunks]))

    def log_batch(self, consumed: int) -> None:
        """Log the last batch's pieces; in virtual time those before stream position
        `consumed` only (the log ends where the campaign did, as the CAN log does)."""
        d = self.decoder
        keep = int(np.searchsorted(d.piece_pos, consumed)) if self._virtual else len(d.pieces)
        self.log.write(d.pieces[:keep])

    @property
    def error(self) -> str | None:
        """The one line naming the port once reading it failed (unplugged?)."""
        return self.reader.error

    def close(self) -> tuple[int, str | None]:
        """Stop reading, close the log: the pieces it holds (this run's) and its sha256."""
        try:
            self.reader.stop()
            if not self._virtual:  # what came after the last frame: still the line's
                self.log.write(self.decoder.held + self.source.close_pieces())
        finally:
            self._close_line()
            self.log.close()
        return self.log.lines, sha256_of(self.path) if self.path.is_file() else None

    def _close_line(self) -> None:
        if self.line is not None:
            self.line.close()


def replay_stream(
    plan: Plan, codec: Codec, can_logs: Sequence[Path]
) -> tuple[SerialSourceDecoder, Iterator[RawFrames]]:
    """A replay's decoder and its CAN frames (`devices.serial_replay`), the logs checked
    first (`LogFileError`)."""
    virtual = plan.bus.timing == "virtual"
    check_serial_logs(can_logs, virtual)
    return serial_replay(codec, serial_source(plan), can_logs, virtual)
