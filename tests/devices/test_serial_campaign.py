"""A campaign whose compass speaks IEC 61162 on a serial line, on the lockstep simulated stand
(virtual time): the same observations as with gyrostand's heading frame (the same physics; THS
has two decimals), byte-reproducible, line faults counted, a silent line failing the trial."""

from __future__ import annotations

import time

import numpy as np
import pytest

from gyrostand.acquisition.engine import Engine, ObservationResult
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.devices.framing import byte_time_s
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.serial_config import LineFaults
from gyrostand.devices.serial_decoder import SerialSourceDecoder
from gyrostand.devices.serial_port import SerialReader
from gyrostand.devices.serial_sim import (
    SerialCompass,
    SerialCompassConfig,
    VirtualLine,
)
from gyrostand.devices.source import ByteChunks
from gyrostand.stand.protocol import Codec
from tests.acquisition.harness import Recorder, quick_config, small_plan

PLAN = small_plan(n_obs=3)
BAUD = 38400
HANG_GUARD_S = 120.0  # only against a hang: each wait returns once the bytes are read


def run(compass: SerialCompass | None = None) -> tuple[Recorder, Lockstep]:
    sink = Recorder()
    if compass is None:
        stand = Lockstep(quick_config(seed=1), 5.0)
        engine = Engine(PLAN, sink, stand)
        stand.run(engine)
        return sink, stand
    codec = Codec()
    source = Iec61162Source(BAUD, "/dev/ttyS0", resolution_deg=0.01)
    byte_s = byte_time_s(BAUD)

    def take() -> ByteChunks:  # each sample read whole when its last byte is in (virtual time)
        pieces = compass.take()
        times = [t + len(d) * byte_s for t, d in pieces]
        return ByteChunks(0, tuple(d for _, d in pieces), np.array(times))

    stand = Lockstep(
        quick_config(seed=1),
        5.0,
        codec,
        (compass, lambda: SerialSourceDecoder(codec, source, take)),
    )  # type: ignore[arg-type]
    engine = Engine(PLAN, sink, stand, source=source.info)
    stand.run(engine)
    return sink, stand


def serial(**faults: object) -> SerialCompass:
    line = LineFaults(**faults)  # type: ignore[arg-type]
    return SerialCompass(SerialCompassConfig(baud=BAUD, sentences=("THS", "ROT"), faults=line))


@pytest.fixture(scope="module")
def gyrostand_run() -> list[ObservationResult]:
    return run()[0].observations


@pytest.fixture(scope="module")
def serial_run() -> Recorder:
    return run(serial())[0]


def test_observations_as_with_the_gyrostand_heading_frame(
    gyrostand_run: list[ObservationResult], serial_run: Recorder
) -> None:
    ours = serial_run.observations
    assert [(o.trial, o.j, o.k) for o in ours] == [(o.trial, o.j, o.k) for o in gyrostand_run]
    assert len(ours) == 12
    for a, b in zip(ours, gyrostand_run, strict=True):
        # a sentence arrives after the stand status sent at its sample's time (its bytes take
        # time on the wire) where the gyrostand frame comes before it: a window starts one
        # sample (100 ms) sooner; and settling judged on 0.01 deg readings (0.001 deg in the
        # frame) may be seen a hold step (5 s) sooner: the same windows, shifted
        assert 0 <= b.window_start_ms - a.window_start_ms <= 5100
        assert a.window_end_ms - a.window_start_ms == b.window_end_ms - b.window_start_ms
        assert a.frames_used == b.frames_used
        assert abs(a.value_deg - b.value_deg) < 0.005
        assert a.frames_lost == 0 and "stuck" not in a.flags


def test_byte_reproducible(serial_run: Recorder) -> None:
    assert run(serial())[0].calls == serial_run.calls


def test_line_faults_are_counted_not_lost(gyrostand_run: list[ObservationResult]) -> None:
    sink, _ = run(serial(checksum_error_rate=0.02, garbage_rate=0.02, not_valid_rate=0.02))
    ours = sink.observations
    assert len(ours) == 12
    for a, b in zip(ours, gyrostand_run, strict=True):
        assert a.frames_used < b.frames_used  # the THS sentences unusable: left out ...
        assert abs(a.value_deg - b.value_deg) < 0.02
    # ... and counted: per window, ~2% of 2 x 300 sentences with a bad checksum, 2% of the
    # samples not valid (THS and ROT), 2% of the samples after garbage: ~30 each
    counts = [
        int(args[2].split("invalid_frame=")[1])
        for name, args in sink.calls
        if name == "event" and args[0] == "frame anomalies"
    ]
    assert len(counts) == 12 and all(c > 0 for c in counts)
    assert 15 <= np.mean(counts) <= 40


def test_through_a_pseudo_terminal_pair(serial_run: Recorder) -> None:
    """The same campaign with the compass's bytes through a real pty and pyserial (the port
    path of a real compass), timed by the simulated line: the same calls, whatever the reads."""
    compass = serial()
    line = VirtualLine(BAUD)
    try:
        with SerialReader(line.path, BAUD, line_clock=line.received) as reader:

            def take() -> ByteChunks:  # every byte written so far, read back through the pty
                line.write(compass.take())
                chunks: list[ByteChunks] = []
                deadline = time.monotonic() + HANG_GUARD_S
                while reader.bytes_taken < line.written and time.monotonic() < deadline:
                    chunks.append(reader.take(wait_s=1.0))
                data = tuple(d for c in chunks for d in c.data)
                times = np.concatenate([c.t_s for c in chunks]) if chunks else np.zeros(0)
                return ByteChunks(0, data, times)

            sink = Recorder()
            codec = Codec()
            source = Iec61162Source(BAUD, line.path, resolution_deg=0.01)
            decoder = (compass, lambda: SerialSourceDecoder(codec, source, take))
            stand = Lockstep(quick_config(seed=1), 5.0, codec, decoder)  # type: ignore[arg-type]
            stand.run(Engine(PLAN, sink, stand, source=source.info))
    finally:
        line.close()
    assert reader.error is None
    assert sink.observations == serial_run.observations
    assert sink.calls == serial_run.calls


def test_a_silent_line_fails_the_trial_naming_the_port() -> None:
    """The compass stops sending (the stand goes on): the trial in progress fails, the message
    naming the serial port; the campaign goes on to the next trial."""
    sink, _ = run(serial(line_silence_at_s=300.0, line_silence_for_s=7.0))
    failures = [args for name, args in sink.calls if name == "trial_failed"]
    assert len(failures) == 1
    assert "serial port /dev/ttyS0 silent: no heading frame for 5" in str(failures[0])
    assert len(sink.observations) >= 6  # the other trials completed


def test_a_wrong_baud_rate_is_named_and_fails_the_trial() -> None:
    """The compass sends at 9600 baud to a 38400-baud port: what the UART makes of it is no
    sentence; an event names the port and the baud rate, the trial fails on no valid heading."""
    sink, _ = run(serial(sender_baud=9600))
    events = [args for name, args in sink.calls if name == "event" and args[0] == "wrong baud rate"]
    assert len(events) == 1
    assert "serial port /dev/ttyS0: no NMEA sentences at 38400 baud: wrong baud rate?" in str(
        events[0]
    )
    failures = [args[2] for name, args in sink.calls if name == "trial_failed"]
    assert failures and all("no valid heading frame" in f for f in failures)
    assert sink.observations == []
