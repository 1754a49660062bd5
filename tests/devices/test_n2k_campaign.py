"""A campaign whose compass speaks NMEA 2000, on the lockstep simulated stand (virtual time): the
same observations as with gyrostand's heading frame (the same physics; the PGN's resolution is
1e-4 rad), byte-reproducible, an address change and not-available values losing nothing, another
heading sensor on the bus left out, an unidentified compass failing the trial with the reason."""

from __future__ import annotations

from collections.abc import Callable

import can
import numpy as np
import pytest

from gyrostand.acquisition.engine import ObservationResult
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.devices.n2k_heading import Nmea2000Heading
from gyrostand.devices.nmea2000 import (
    RESOLUTION_DEG,
    VESSEL_HEADING,
    Product,
    ReferenceEncoder,
    decode_vessel_heading,
    iso_name,
    split_id,
)
from gyrostand.devices.sim_nmea2000 import Nmea2000Compass, Nmea2000Device, Nmea2000Faults
from tests.acquisition.harness import Recorder
from tests.devices.source_campaign import (
    assert_as_gyrostand,
    assert_window_means,
    campaign,
    stream_key,
)

PRODUCT = Product("test compass", "T-1", "1.0")  # the plan's [instrument]
WANTED = ("test compass", "T-1")


def run(
    transmitter: object | None = None,
    source: Callable[[], Nmea2000Heading] | None = None,
    **faults: float,
) -> tuple[Recorder, Lockstep]:
    if transmitter is None:
        return campaign(**faults)
    make = source or (lambda: Nmea2000Heading(None, WANTED))
    return campaign(transmitter, make, Nmea2000Heading.info, **faults)


def compass(**faults: object) -> Nmea2000Compass:
    return Nmea2000Compass(Nmea2000Device(PRODUCT), Nmea2000Faults(**faults))  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def gyrostand_run() -> list[ObservationResult]:
    return run()[0].observations


@pytest.fixture(scope="module")
def n2k_run() -> tuple[Recorder, Lockstep]:
    return run(compass())


def test_observations_as_with_the_gyrostand_heading_frame(
    gyrostand_run: list[ObservationResult], n2k_run: tuple[Recorder, Lockstep]
) -> None:
    """The same samples, rounded to 1e-4 rad instead of 0.001 deg: each window mean within a
    resolution step's worth of rounding error (the mean of ~300 rounding errors is far smaller)."""
    assert_as_gyrostand(n2k_run[0].observations, gyrostand_run, RESOLUTION_DEG)


def test_window_means_are_those_of_the_frames_sent(n2k_run: tuple[Recorder, Lockstep]) -> None:
    """Independently of the engine: the PGN 127250 frames of the stream in each window."""
    sink, stand = n2k_run
    frames = [m for m in stand.stream if m.is_extended_id]
    pgn, _ = split_id(np.array([m.arbitration_id for m in frames]))
    heading = [m for m, p in zip(frames, pgn.tolist(), strict=True) if p == VESSEL_HEADING]
    t_ms = np.round(np.array([m.timestamp for m in heading]) * 1000)
    deg = np.degrees(
        decode_vessel_heading(np.array([list(m.data) for m in heading], np.uint8)).heading_rad()
    )
    assert_window_means(sink, t_ms, deg)


def test_byte_reproducible(n2k_run: tuple[Recorder, Lockstep]) -> None:
    assert stream_key(run(compass())[1]) == stream_key(n2k_run[1])


def test_an_address_change_and_not_available_values_lose_nothing(
    n2k_run: tuple[Recorder, Lockstep],
) -> None:
    sink, stand = run(compass(address_change_at_s=500.0, not_available_rate=0.02))
    plain = n2k_run[0].observations
    assert len(sink.observations) == len(plain) and sink.of("trial_failed") == []
    unavailable = 0
    for obs, ref in zip(sink.observations, plain, strict=True):
        assert obs.frames_lost == 0
        flags = dict(f.split("=") for f in obs.flags.split(",") if f)
        assert set(flags) <= {"not_available"}
        unavailable += int(flags.get("not_available", 0))
        assert obs.frames_used + int(flags.get("not_available", 0)) == ref.frames_used
    assert unavailable > 20
    claims = [a for a in sink.of("event") if a[0] == "address claim"]
    assert len(claims) == 1 and "claimed address 36 (was 35)" in claims[0][2]
    sources = {
        split_id(np.array([m.arbitration_id]))[1][0] for m in stand.stream if m.is_extended_id
    }
    assert sources == {35, 36}


class TwoSensors:
    """The compass and another heading sensor (its own NAME, address and product) on one bus."""

    def __init__(self) -> None:
        self.compass = compass()
        other = Nmea2000Device(Product("other sensor", "X-9", "3.0"), iso_name(77), address=40)
        self.other = Nmea2000Compass(other, seed=5)

    def frames(self, t_s: np.ndarray, reading: np.ndarray, index: np.ndarray) -> list[can.Message]:
        out = self.compass.frames(t_s, reading, index) + self.other.frames(
            t_s, (reading + 10.0) % 360.0, index
        )
        return sorted(out, key=lambda m: m.timestamp)

    def answers(self, msg: can.Message) -> bool:
        return self.compass.answers(msg) or self.other.answers(msg)

    def answer(self, msg: can.Message, t_s: float) -> list[can.Message]:
        return self.compass.answer(msg, t_s) + self.other.answer(msg, t_s)


def test_another_heading_sensor_is_told_and_left_out(n2k_run: tuple[Recorder, Lockstep]) -> None:
    sink, _ = run(TwoSensors())
    ours = [(o.value_deg, o.frames_used, o.flags) for o in sink.observations]
    assert ours == [(o.value_deg, o.frames_used, o.flags) for o in n2k_run[0].observations]
    told = [a for a in sink.of("event") if a[0] == "other device"]
    assert len(told) == 1 and "from address 40 (NAME 0x" in told[0][2]


class LateFrames:
    """The compass with every 7th sample received 70 ms (0.7 of the 10 Hz interval) late, as a
    loaded host or gateway delays frames: their SID runs on."""

    def __init__(self) -> None:
        self.compass = compass()

    def frames(self, t_s: np.ndarray, reading: np.ndarray, index: np.ndarray) -> list[can.Message]:
        out = self.compass.frames(t_s, reading, index)
        late = {float(t) for t, i in zip(t_s, index, strict=True) if i % 7 == 3}
        for m in out:
            if m.timestamp in late:
                m.timestamp += 0.07
        return sorted(out, key=lambda m: m.timestamp)

    def answers(self, msg: can.Message) -> bool:
        return self.compass.answers(msg)

    def answer(self, msg: can.Message, t_s: float) -> list[can.Message]:
        return self.compass.answer(msg, t_s)


def test_a_late_frame_whose_sid_runs_on_is_not_lost() -> None:
    """Before: each late frame, 1.7 intervals after the previous one, counted one frame lost
    (from time) although the SID showed none."""
    sink, _ = run(LateFrames())
    assert sink.observations and sink.of("trial_failed") == []
    assert all(o.frames_lost == 0 and o.flags == "" for o in sink.observations)
    assert [a for a in sink.of("event") if a[0] == "frame gap"] == []


class Intruder:
    """The compass, and at stand time 500 s a device joining the bus that claims its address
    with a lower NAME: the compass answers as ISO 11783-5 has it, by claiming another one."""

    def __init__(self) -> None:
        self.compass = compass()
        self.joined = False

    def frames(self, t_s: np.ndarray, reading: np.ndarray, index: np.ndarray) -> list[can.Message]:
        cut = int(np.searchsorted(t_s, 500.0))
        if self.joined or cut == len(t_s):
            return self.compass.frames(t_s, reading, index)
        self.joined = True
        out = self.compass.frames(t_s[:cut], reading[:cut], index[:cut])
        (claim,) = ReferenceEncoder().address_claim(iso_name(1), 35, float(t_s[cut]))
        out += [claim, *self.compass.answer(claim, float(t_s[cut]))]
        return out + self.compass.frames(t_s[cut:], reading[cut:], index[cut:])

    def answers(self, msg: can.Message) -> bool:
        return self.compass.answers(msg)

    def answer(self, msg: can.Message, t_s: float) -> list[can.Message]:
        return self.compass.answer(msg, t_s)


def test_a_device_taking_the_compass_address_loses_nothing(
    n2k_run: tuple[Recorder, Lockstep],
) -> None:
    sink, _ = run(Intruder())
    assert [o.frames_lost for o in sink.observations] == [0] * len(n2k_run[0].observations)
    claims = [a[2] for a in sink.of("event") if a[0] == "address claim"]
    assert claims == [
        f"compass NAME 0x{iso_name(4242):016X} claimed address 36 (was 35); its headings follow it"
    ]


def test_a_compass_never_identified_fails_the_trial_with_the_reason() -> None:
    """The plan names a NAME no device claims: every heading is invalid, with why."""
    sink, _ = run(compass(), lambda: Nmea2000Heading(name=0x1234, product=None))
    assert sink.observations == []
    failed = sink.of("trial_failed")
    assert failed and all("before the compass is identified" in f[2] for f in failed)


def test_a_product_other_than_the_plans_instrument_is_an_error_event() -> None:
    name = Nmea2000Device(PRODUCT).name
    sink, _ = run(compass(), lambda: Nmea2000Heading(name=name, product=("GX-2", "S-7")))
    (event,) = [a for a in sink.of("event") if a[0] == "product information"]
    assert event[1] == "error" and "the plan's instrument is 'GX-2', serial 'S-7'" in event[2]


def heading_times(stand: Lockstep) -> np.ndarray:
    """Stand ms of the PGN 127250 frames in the stream."""
    frames = [m for m in stand.stream if m.is_extended_id]
    pgn, _ = split_id(np.array([m.arbitration_id for m in frames]))
    return np.round(
        np.array([m.timestamp for m, p in zip(frames, pgn, strict=True) if p == 127250]) * 1000
    )


@pytest.mark.parametrize("no_sid", [False, True], ids=["SID", "SID 255: time only"])
def test_dropped_frames_are_counted_lost(no_sid: bool) -> None:
    """Frames the compass did not send (the stand's drop_rate knob), counted from the SID or,
    without one, from the reception times: per window, the samples due (every 100 ms) that are
    not in the stream."""
    sink, stand = run(compass(no_sid=no_sid), drop_rate=0.03)
    sent = heading_times(stand)
    assert sink.observations and sink.of("trial_failed") == []
    for obs in sink.observations:
        due = np.arange(obs.window_start_ms, obs.window_end_ms, 100)
        missing = len(set(due.tolist()) - set(sent.tolist()))
        assert obs.frames_lost == missing
    assert sum(o.frames_lost for o in sink.observations) > 30
    gaps = [a for a in sink.of("event") if a[0] == "frame gap"]
    assert bool(gaps) == no_sid and all("no sequence number" in g[2] for g in gaps)
