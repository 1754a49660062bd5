"""Protocol: round trips over the full signal ranges, range refusals, invalid frames, signal map."""

import math
from pathlib import Path

import can
import cantools
import pytest
from cantools.database.can import Message, Signal
from cantools.database.conversion import BaseConversion
from crccheck.crc import Crc8SaeJ1850
from hypothesis import given
from hypothesis import strategies as st

from gyrostand.stand.protocol import (
    COMMANDS,
    DBC_PATH,
    AckFrame,
    Codec,
    CommandFrame,
    CompassStatusFrame,
    HeadingFrame,
    InvalidFrame,
    ProtocolError,
    Reason,
    SignalMap,
    SignalRef,
    StandStatusFrame,
    crc8_sae_j1850,
    signal_bounds,
)

CODEC = Codec()
U32 = st.integers(0, 2**32 - 1)


def scaled(high_raw: int, scale: float, low_raw: int = 0) -> st.SearchStrategy[float]:
    """Values exactly on the signal's resolution grid, over the whole DBC range."""
    return st.integers(low_raw, high_raw).map(lambda raw: raw * scale)


@given(U32, scaled(359_999, 0.001), st.booleans(), st.integers(0, 15))
def test_heading_round_trip(time_ms: int, heading: float, valid: bool, counter: int) -> None:
    msg = CODEC.encode_heading(time_ms, heading, valid, counter)
    frame = CODEC.decode(msg)
    assert isinstance(frame, HeadingFrame)
    assert (frame.stand_time_ms, frame.valid, frame.counter) == (time_ms, valid, counter)
    assert frame.heading_deg == pytest.approx(heading, abs=1e-9)
    # cantools with the DBC alone reads the same frame
    plain = cantools.database.load_file(DBC_PATH).decode_message(msg.arbitration_id, msg.data)
    assert plain["STAND_TIME"] == time_ms and plain["HEADING"] == pytest.approx(heading)


@given(st.floats(0, 359.999))
def test_heading_off_grid_rounds_to_resolution(heading: float) -> None:
    frame = CODEC.decode(CODEC.encode_heading(0, heading, True, 0))
    assert isinstance(frame, HeadingFrame)
    assert abs(frame.heading_deg - heading) <= 0.0005 + 1e-12


@given(
    U32,
    st.booleans(),
    scaled(35_999, 0.01),
    scaled(65_535, 0.01),
    scaled(65_535, 0.001),
    st.integers(0, 32767),
    scaled(35_999, 0.01),
)
def test_status_round_trip(
    time_ms: int,
    rocking: bool,
    direction: float,
    amplitude: float,
    period: float,
    cycle: int,
    phase: float,
) -> None:
    codec = Codec()
    msgs = codec.encode_status(time_ms, rocking, direction, amplitude, period, cycle, phase)
    frames = [codec.decode(m) for m in msgs]
    assert frames[:-1] == [None] * (len(msgs) - 1)  # the motion part waits for the status part
    expected = StandStatusFrame(time_ms, rocking, direction, amplitude, period, cycle, phase)
    got = frames[-1]
    assert isinstance(got, StandStatusFrame)
    assert (got.stand_time_ms, got.rocking, got.cycle) == (time_ms, rocking, cycle)
    for name in ("direction_deg", "amplitude_cm", "period_s", "phase_deg"):
        assert getattr(got, name) == pytest.approx(getattr(expected, name), abs=1e-9), name


def test_status_part_alone_is_not_a_status() -> None:
    status, motion = (
        m
        for m in sorted(CODEC.encode_status(5, True, 1, 2, 3, 4, 5), key=lambda m: m.arbitration_id)
    )
    assert Codec().decode(status) is None  # no motion seen yet: incomplete, not invented


@given(scaled(35_999, 0.01), scaled(65_535, 0.01), scaled(65_535, 0.001), st.integers(0, 15))
def test_command_round_trip(direction: float, amplitude: float, period: float, seq: int) -> None:
    got = CODEC.decode(CODEC.encode_command_set(direction, amplitude, period, seq=seq))
    assert isinstance(got, CommandFrame)
    assert (got.command, got.seq) == ("set", seq)
    assert got.direction_deg == pytest.approx(direction, abs=1e-9)
    assert got.amplitude_cm == pytest.approx(amplitude, abs=1e-9)
    assert got.period_s == pytest.approx(period, abs=1e-9)
    assert CODEC.decode(CODEC.encode_command_start(seq=seq)).command == "start"
    assert CODEC.decode(CODEC.encode_command_stop(seq=seq)).command == "stop"


@given(
    st.sampled_from(COMMANDS),
    st.one_of(st.just(""), st.sampled_from(list(Reason))),
    st.integers(0, 15),
    U32,
)
def test_ack_round_trip(command: str, reason: str, seq: int, time_ms: int) -> None:
    accepted = reason == ""
    msg = CODEC.encode_ack(command, accepted, reason, seq=seq, stand_time_ms=time_ms)
    assert CODEC.decode(msg) == AckFrame(command, accepted, str(reason), seq, time_ms)


@given(st.booleans(), scaled(20_000, 0.01, low_raw=0).map(lambda v: v - 50), st.integers(0, 255))
def test_compass_status_round_trip(rotor: bool, temp: float, faults: int) -> None:
    got = CODEC.decode(CODEC.encode_compass_status(rotor, temp, faults))
    assert isinstance(got, CompassStatusFrame)
    assert (got.rotor_running, got.fault_bits) == (rotor, faults)
    assert got.fluid_temp_c == pytest.approx(temp, abs=1e-9)


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda: CODEC.encode_heading(0, 359.9996, True, 0), "GYRO_HEADING.HEADING"),
        (lambda: CODEC.encode_heading(0, -0.001, True, 0), "[0, 359.999] deg"),
        (lambda: CODEC.encode_heading(2**32, 1.0, True, 0), "GYRO_HEADING.STAND_TIME"),
        (lambda: CODEC.encode_heading(0, 1.0, True, 16), "GYRO_HEADING.COUNTER"),
        (lambda: CODEC.encode_heading(0, math.nan, True, 0), "not a finite number"),
        (lambda: CODEC.encode_command_set(360.0, 10, 5), "STAND_COMMAND.DIRECTION"),
        (lambda: CODEC.encode_command_set(10, 655.36, 5), "[0, 655.35] cm"),
        (lambda: CODEC.encode_command_set(10, 10, -1), "STAND_COMMAND.PERIOD"),
        (lambda: CODEC.encode_status(0, True, 0, 0, 0, 32768, 0), "STAND_STATUS.CYCLE"),
        (lambda: CODEC.encode_compass_status(True, 150.01, 0), "GYRO_STATUS.FLUID_TEMP"),
        (lambda: CODEC.encode_ack("set", False, "because"), "not one of the DBC values"),
        (lambda: CODEC.encode_ack("jump", True), "STAND_ACK.COMMAND"),
    ],
)
def test_encoding_refuses_out_of_range(call, named: str) -> None:
    with pytest.raises(ProtocolError, match=named.replace("[", r"\[").replace(".", r"\.")):
        call()


def test_protocol_error_is_a_value_error() -> None:
    assert issubclass(ProtocolError, ValueError)


@given(st.integers(0, 63))
def test_any_single_bit_flip_in_a_heading_frame_is_reported(bit: int) -> None:
    msg = CODEC.encode_heading(123_456, 201.5, True, 9)
    msg.data[bit // 8] ^= 1 << (bit % 8)
    frame = CODEC.decode(msg)
    assert isinstance(frame, InvalidFrame)
    assert frame.arbitration_id == 0x100 and frame.raw == bytes(msg.data)


@given(st.binary(min_size=0, max_size=64))
def test_crc_matches_the_reference_implementation(data: bytes) -> None:
    assert crc8_sae_j1850(data) == Crc8SaeJ1850.calc(data)


def test_crc_check_value() -> None:
    assert crc8_sae_j1850(b"123456789") == 0x4B  # catalogue check value of CRC-8/SAE-J1850


@given(
    st.sampled_from([1, 0.1, 0.001, 2.5, -0.5]),
    st.sampled_from([(0, 359.9), (-50, 150), (0.25, 0.75)]),
    st.floats(-3, 3),
)
def test_range_rule_is_cantools(scale: float, limits: tuple[float, float], k: float) -> None:
    """A value k rounding tolerances past either limit is in `signal_bounds` exactly when
    cantools' strict encoding accepts it."""
    minimum, maximum = limits
    conversion = BaseConversion.factory(scale=scale)
    signal = Signal(
        "x", 0, 32, is_signed=True, minimum=minimum, maximum=maximum, conversion=conversion
    )
    message = Message(0x10, "m", 8, [signal])
    low, high = signal_bounds(signal)
    for value in (minimum - k * abs(scale) * 1e-6, maximum + k * abs(scale) * 1e-6):
        try:
            message.encode({"x": value}, strict=True)
            accepted = True
        except cantools.database.EncodeError:
            accepted = False
        assert (low <= value <= high) == accepted, value


@pytest.mark.parametrize(
    ("msg", "reason"),
    [
        (can.Message(arbitration_id=0x100, data=b"\x00" * 5), "wrong length: 5 bytes"),
        (can.Message(is_error_frame=True), "error frame"),
        (can.Message(arbitration_id=0x100, is_remote_frame=True, dlc=8), "remote frame"),
        (CODEC.encode_heading(1, 419.0, True, 1, strict=False), "outside [0, 359.999]"),
        (
            can.Message(arbitration_id=0x80, data=bytes([0x0F, 0, 0, 0, 0, 0, 0, 0])),
            "unknown command code 15",
        ),
        (
            can.Message(arbitration_id=0x201, data=bytes([0xFF, 0xFF, 0, 0, 0, 0, 0, 0])),
            "STAND_MOTION.DIRECTION = 655.35 outside",
        ),
    ],
)
def test_invalid_frames_are_reported(msg: can.Message, reason: str) -> None:
    frame = CODEC.decode(msg)
    assert isinstance(frame, InvalidFrame)
    assert reason in frame.reason


def test_unknown_ids_are_ignored() -> None:
    assert CODEC.decode(can.Message(arbitration_id=0x7FF, data=b"\x01")) is None
    assert CODEC.heading_arbitration_id == 0x100


@given(st.sampled_from([0x80, 0x81, 0x100, 0x200, 0x201, 0x300]), st.binary(max_size=8))
def test_decode_never_raises(arbitration_id: int, data: bytes) -> None:
    frame = CODEC.decode(can.Message(arbitration_id=arbitration_id, data=data))
    if len(data) != 8:
        assert isinstance(frame, InvalidFrame)


# ------------------------------------------------------------------------------------ signal map
def test_default_signal_map_matches_the_shipped_dbc() -> None:
    assert SignalMap.from_mapping({}) == SignalMap.default()
    assert SignalMap.default().heading == SignalRef("GYRO_HEADING", "HEADING")
    assert DBC_PATH.name == "gyrostand.dbc" and DBC_PATH.is_file()


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ({"hedaing": "A.B"}, "unknown key 'hedaing'"),
        ({"heading": "HEADING"}, "signals.heading: expected MESSAGE.SIGNAL"),
        ({"heading": 3}, "signals.heading: expected"),
        ({"heading": ""}, "signals.heading: expected MESSAGE.SIGNAL"),
    ],
)
def test_signal_map_rejects_bad_entries(mapping: dict, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        SignalMap.from_mapping(mapping)


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ({"heading": "NOPE.HEADING"}, "signals.heading: no message 'NOPE'"),
        ({"heading_time": "GYRO_HEADING.TIME"}, "GYRO_HEADING has no signal 'TIME'"),
        ({"heading_counter": "STAND_STATUS.CYCLE"}, "heading entries must share one message"),
    ],
)
def test_codec_rejects_a_map_that_does_not_fit_the_dbc(mapping: dict, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        Codec(signal_map=SignalMap.from_mapping(mapping))


LAB_SENSOR = """
BO_ 801 LAB_ANGLE_SENSOR: 8 SENSOR
 SG_ T_MS : 0|32@1+ (1,0) [0|4294967295] "ms" PC
 SG_ ANGLE : 32|24@1+ (0.0001,0) [0|359.9999] "deg" PC
 SG_ CNT : 56|4@1+ (1,0) [0|15] "" PC
"""


def test_a_lab_dbc_works_through_its_signal_map(tmp_path: Path) -> None:
    text = DBC_PATH.read_text()
    dbc = tmp_path / "lab.dbc"
    dbc.write_text(text.replace("\nCM_ BU_", LAB_SENSOR + "\nCM_ BU_", 1))
    signal_map = SignalMap.from_mapping(
        {
            "heading": "LAB_ANGLE_SENSOR.ANGLE",
            "heading_time": "LAB_ANGLE_SENSOR.T_MS",
            "heading_counter": "LAB_ANGLE_SENSOR.CNT",
            "heading_valid": "",
            "heading_crc": "",
        }
    )
    codec = Codec(dbc, signal_map)
    assert codec.heading_arbitration_id == 801
    msg = codec.encode_heading(77, 12.3456, True, 4)
    assert codec.decode(msg) == HeadingFrame(77, pytest.approx(12.3456, abs=1e-9), True, 4)
    # the shipped heading frame is no longer the heading for this lab
    assert not isinstance(codec.decode(CODEC.encode_heading(1, 2.0, True, 3)), HeadingFrame)


def test_missing_dbc_is_a_protocol_error(tmp_path: Path) -> None:
    with pytest.raises(ProtocolError, match="cannot load DBC"):
        Codec(tmp_path / "absent.dbc")
