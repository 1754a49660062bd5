"""A campaign whose compass is read by a CiA 406 absolute encoder, on the lockstep simulated stand
(virtual time): the same observations as with gyrostand's heading frame (the same physics, at the
encoder's resolution), byte-reproducible, a still compass not stuck, dropped TPDOs counted lost
from time, a silent encoder told by its missing heartbeat, an EMCY an event."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from gyrostand.acquisition.engine import ObservationResult
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.devices.cia406 import Cia406Heading, encoder_info
from gyrostand.devices.sim_cia406 import Cia406Encoder, Cia406Faults
from gyrostand.stand.encoder import Encoder
from tests.acquisition.harness import Recorder
from tests.devices.source_campaign import (
    assert_as_gyrostand,
    assert_window_means,
    campaign,
    stream_key,
)

# 14-bit single turn (0.022 deg), read counter-clockwise from a zero at 5000 counts
ENCODER = Encoder(5, 16384, zero_counts=5000, sign=-1, heartbeat_ms=1000)


def run(faults: Cia406Faults | None = None, **stand_faults: float) -> tuple[Recorder, Lockstep]:
    if faults is None:
        return campaign(**stand_faults)
    device = Cia406Encoder(ENCODER, faults)
    return campaign(device, lambda: Cia406Heading(ENCODER), encoder_info(ENCODER), **stand_faults)


@pytest.fixture(scope="module")
def gyrostand_run() -> list[ObservationResult]:
    return run()[0].observations


@pytest.fixture(scope="module")
def encoder_run() -> tuple[Recorder, Lockstep]:
    return run(Cia406Faults())


def tpdo_stream(stand: Lockstep) -> tuple[np.ndarray, np.ndarray]:
    """Stand ms and headings of the encoder's TPDOs in the stream, decoded with struct and the
    mounting (eq of stand.encoder) written out here."""
    frames = [m for m in stand.stream if m.arbitration_id == 0x185 and not m.is_extended_id]
    counts = np.array([struct.unpack("<I", bytes(m.data))[0] for m in frames])
    deg = ((5000 - counts) % 16384) * 360.0 / 16384
    return np.round(np.array([m.timestamp for m in frames]) * 1000), deg


def test_observations_as_with_the_gyrostand_heading_frame(
    gyrostand_run: list[ObservationResult], encoder_run: tuple[Recorder, Lockstep]
) -> None:
    assert_as_gyrostand(encoder_run[0].observations, gyrostand_run, ENCODER.resolution_deg)
    assert encoder_run[0].of("trial_failed") == []


def test_window_means_are_those_of_the_frames_sent(encoder_run: tuple[Recorder, Lockstep]) -> None:
    sink, stand = encoder_run
    assert_window_means(sink, *tpdo_stream(stand))


def test_byte_reproducible(encoder_run: tuple[Recorder, Lockstep]) -> None:
    assert stream_key(run(Cia406Faults())[1]) == stream_key(encoder_run[1])


def test_dropped_tpdos_are_counted_lost_from_time() -> None:
    sink, stand = run(Cia406Faults(), drop_rate=0.03)
    sent, _ = tpdo_stream(stand)
    assert sink.observations and sink.of("trial_failed") == []
    for obs in sink.observations:
        due = np.arange(obs.window_start_ms, obs.window_end_ms, 100)
        assert obs.frames_lost == len(set(due.tolist()) - set(sent.tolist()))
    assert sum(o.frames_lost for o in sink.observations) > 30


def test_a_silent_encoder_and_an_emcy_are_events() -> None:
    sink, _ = run(Cia406Faults(silence_at_s=300.0, silence_for_s=4.0, emcy_at_s=200.0))
    events = {(kind, severity): text for kind, severity, text, *_ in sink.of("event")}
    assert "no heartbeat for 3 producer periods" in events["heartbeat lost", "error"]
    assert "heartbeat back" in events["heartbeat back", "info"]
    assert "EMCY: Code 0x1000, Generic Error" in events["emcy", "error"]
    assert "booted" in events["nmt state", "info"]
