"""The simulated stand: commands and refusals, every fault knob, determinism, batch encoding."""

import math
from dataclasses import fields

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gyrostand.frames.batch import RawFrames
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.packing import BatchEncoder
from gyrostand.stand.protocol import HEADING_KEYS, STATUS_KEYS, AckFrame, Reason
from gyrostand.stand.simconfig import CompassParams, InclinometerParams, SimConfig
from tests.stand.frames import CODEC, command, config, decoded_headings, headings, invalid, statuses

N = 20_000  # heading samples in the fault tests (2000 s at 10 Hz)


def binomial_ok(count: int, n: int, p: float) -> bool:
    """count is within 5 standard deviations of n * p."""
    return abs(count - n * p) <= 5 * math.sqrt(n * p * (1 - p))


def run(seconds: float = N / 10 - 0.1, **groups) -> list:
    return StandEngine(config(**groups)).advance_to(seconds)


# ---------------------------------------------------------------------------------- commands
def test_command_cycle_and_status() -> None:
    engine = StandEngine(SimConfig())
    engine.advance_to(10.0)
    assert command(engine, "set", 31, 23.5, 6.2) == [AckFrame("set", True, "", 0, 10_000)]
    assert command(engine, "start")[0].accepted and engine.rocking
    frames = engine.advance_to(20.0)
    status = statuses(frames)[-1]
    assert (status.stand_time_ms, status.rocking) == (20_000, True)
    assert (status.direction_deg, status.amplitude_cm, status.period_s) == (31.0, 23.5, 6.2)
    assert status.cycle == 1 and status.phase_deg == pytest.approx(10 / 6.2 % 1 * 360, abs=0.01)
    assert command(engine, "stop")[0].accepted and not engine.rocking
    last = statuses(engine.advance_to(21.0))[-1]
    assert (last.rocking, last.amplitude_cm, last.period_s) == (False, 0.0, 0.0)


@pytest.mark.parametrize(
    ("commands", "reason"),
    [
        ([("set", 31, 50.01, 6)], Reason.AMPLITUDE),
        ([("set", 31, 0.0, 6)], Reason.AMPLITUDE),
        ([("set", 31, 20, 1.99)], Reason.PERIOD),
        ([("set", 31, 20, 20.01)], Reason.PERIOD),
        ([("start",)], Reason.NOT_CONFIGURED),
        ([("set", 31, 20, 6), ("start",), ("set", 40, 20, 6)], Reason.BUSY),
    ],
)
def test_refusals(commands: list, reason: Reason) -> None:
    engine = StandEngine(SimConfig())
    acks = [command(engine, *c)[0] for c in commands]
    assert acks[-1].accepted is False and acks[-1].reason == reason
    assert all(a.accepted for a in acks[:-1])


def test_repeated_start_and_stop_change_nothing() -> None:
    engine = StandEngine(SimConfig())
    command(engine, "set", 31, 20, 6)
    command(engine, "start")
    engine.advance_to(50.0)
    assert command(engine, "start")[0].accepted
    assert statuses(engine.advance_to(56.0))[-1].cycle == 9  # still counting from t = 0
    assert command(engine, "stop")[0].accepted and command(engine, "stop")[0].accepted


# ---------------------------------------------------------------------------------- faults
def test_dropped_frames_leave_counter_gaps() -> None:
    frames = run(faults={"drop_rate": 0.2})
    t, _, counter = headings(frames)
    assert binomial_ok(N - len(t), N, 0.2)
    missing = np.round(np.diff(t) * 10).astype(int) - 1  # samples lost between frames
    assert np.array_equal((np.diff(counter) - 1) % 16, missing % 16)
    assert missing.sum() == N - len(t) - round(t[0] * 10)


def test_counter_jumps_without_lost_frames() -> None:
    t, _, counter = headings(run(faults={"counter_jump_rate": 0.05}))
    assert len(t) == N and np.allclose(np.diff(t), 0.1)
    jumps = int(np.count_nonzero(np.diff(counter) % 16 != 1))
    assert binomial_ok(jumps, N - 1, 0.05)


def test_invalid_flag() -> None:
    frames = decoded_headings(run(faults={"invalid_rate": 0.1}))
    assert len(frames) == N
    assert binomial_ok(sum(not f.valid for f in frames), N, 0.1)


def test_stuck_sensor_repeats_its_last_reading() -> None:
    t, reading, _ = headings(run(faults={"stuck_at_s": 500.0, "stuck_for_s": 300.0}))
    stuck = (t >= 500.0) & (t < 800.0)
    assert np.all(reading[stuck] == reading[np.argmax(stuck) - 1])
    assert np.std(reading[(t >= 200.0) & (t < 500.0)]) > 0.005  # noise goes on outside it
    assert all(f.valid for f in decoded_headings(run(faults={"stuck_at_s": 5, "stuck_for_s": 9})))


def test_out_of_range_values_are_reported_invalid() -> None:
    frames = run(faults={"out_of_range_rate": 0.05})
    bad = invalid(frames)
    assert binomial_ok(len(bad), N, 0.05)
    assert all("GYRO_HEADING.HEADING" in f.reason and "outside" in f.reason for f in bad)
    raw = [CODEC.database.decode_message(0x100, f.raw)["HEADING"] for f in bad]
    assert min(raw) > 359.999 and max(raw) <= 524.287


def test_corrupt_payloads_are_all_caught() -> None:
    frames = run(faults={"corrupt_rate": 0.05})
    bad = invalid(frames)
    assert binomial_ok(len(bad), N, 0.05)
    assert len(bad) + len(decoded_headings(frames)) == N
    assert sum("CRC mismatch" in f.reason for f in bad) > 0.8 * len(bad)


def test_error_frames() -> None:
    frames = run(faults={"error_frame_rate": 0.05})
    errors = [m for m in frames if m.is_error_frame]
    assert binomial_ok(len(errors), N, 0.05)
    assert all(f.reason == "error frame" for f in invalid(errors))
    assert len(decoded_headings(frames)) == N  # each errored frame is retransmitted
    after = [frames[frames.index(e) + 1] for e in errors[:20]]
    assert all(
        m.arbitration_id == 0x100 and m.timestamp == e.timestamp
        for m, e in zip(after, errors[:20], strict=True)
    )


def test_bus_silence_sends_nothing_and_answers_nothing() -> None:
    engine = StandEngine(config(faults={"silence_at_s": 100.0, "silence_for_s": 50.0}))
    frames = engine.advance_to(120.0)
    assert command(engine, "set", 31, 20, 6) == []
    frames += engine.advance_to(200.0)
    times = np.array([m.timestamp for m in frames])
    assert not np.any((times >= 100.0) & (times < 150.0))
    assert np.any(times == 99.9) and np.any(times == 150.0)
    assert command(engine, "set", 31, 20, 6)[0].accepted


def test_stand_not_acknowledging() -> None:
    engine = StandEngine(config(faults={"no_ack": True}))
    assert command(engine, "set", 31, 20, 6) == [] and command(engine, "start") == []
    assert not engine.rocking and not statuses(engine.advance_to(10.0))[-1].rocking


def test_wrong_amplitude_is_rocked_and_reported() -> None:
    engine = StandEngine(config(faults={"amplitude_factor": 0.8}))
    command(engine, "set", 45, 30, 5)
    command(engine, "start")
    assert statuses(engine.advance_to(5.0))[-1].amplitude_cm == pytest.approx(24.0)
    assert engine.equilibrium_deg == pytest.approx(CompassParams().settled_shift_deg(45, 24, 5))


def test_compass_fault_bits_are_reported() -> None:
    frames = StandEngine(config(faults={"compass_fault_bits": 5})).advance_to(1.0)
    reports = [f for f in map(CODEC.decode, frames) if type(f).__name__ == "CompassStatusFrame"]
    assert [f.fault_bits for f in reports] == [5, 5, 5]
    assert all(f.rotor_running and f.fluid_temp_c == 42.0 for f in reports)


def test_fault_probabilities_are_validated() -> None:
    with pytest.raises(ValueError, match="drop_rate must be a probability"):
        config(faults={"drop_rate": 1.5})
    with pytest.raises(ValueError, match="speedup must be a positive number"):
        config(speedup=0)


# ---------------------------------------------------------------------------------- determinism
FAULTY = {
    "drop_rate": 0.05,
    "counter_jump_rate": 0.02,
    "corrupt_rate": 0.02,
    "error_frame_rate": 0.02,
    "out_of_range_rate": 0.02,
    "invalid_rate": 0.02,
}


def scripted(seed: int, chunks: list[float]) -> list[tuple[float, int, bytes, bool]]:
    """Frames of one session (rocking commanded at stand time 300 s), advancing the engine
    through the given stand times."""
    engine = StandEngine(config(seed=seed, faults=FAULTY))
    frames = []
    for t_s in [t for t in chunks if t < 300.0] + [300.0]:
        frames += engine.advance_to(t_s)
    frames += engine.receive(CODEC.encode_command_set(31, 20, 6))
    frames += engine.receive(CODEC.encode_command_start())
    for t_s in [t for t in chunks if t > 300.0] + [600.0]:
        frames += engine.advance_to(t_s)
    return [(m.timestamp, m.arbitration_id, bytes(m.data), m.is_error_frame) for m in frames]


def test_same_seed_same_frames_different_seed_different_frames() -> None:
    assert scripted(7, []) == scripted(7, [])
    assert scripted(7, []) != scripted(8, [])


@settings(max_examples=10, deadline=None)
@given(st.lists(st.floats(0.0, 600.0), max_size=30))
def test_frames_do_not_depend_on_how_time_is_chunked(cuts: list[float]) -> None:
    assert scripted(3, sorted(cuts)) == scripted(3, [])


def test_frames_as_arrays_are_the_messages_frame_for_frame() -> None:
    """`advance_parts` (the in-process stand's path into a campaign) gives `advance_to`'s frames,
    in `advance_to`'s order once sorted as `RawFrames.from_parts` sorts them: every fault knob,
    error frames, an inclinometer, rocking."""
    cfg = config(seed=5, faults=FAULTY, inclinometer=InclinometerParams(node_id=6))
    as_messages, as_arrays = StandEngine(cfg), StandEngine(cfg)
    for engine in (as_messages, as_arrays):
        engine.receive(CODEC.encode_command_set(31, 20, 6))
        engine.receive(CODEC.encode_command_start())
    for t_s in (0.0, 0.35, 120.0, 121.0, 400.0):
        expected = RawFrames.from_messages(0, as_messages.advance_to(t_s))
        got = RawFrames.from_parts(0, as_arrays.advance_parts(t_s))
        assert len(got) == len(expected) > 0 or t_s == 0.0
        for f in fields(RawFrames)[1:]:
            assert np.array_equal(getattr(got, f.name), getattr(expected, f.name)), f.name
    assert got.is_error.any() and (got.arbitration_id == 0x180 + 6).any()


def test_an_unheard_wait_leaves_the_frames_heard_after_it_unchanged() -> None:
    """`pass_to` (a procedure's wait) makes every draw `advance_to` makes: the frames heard
    after it, all of them or the compass's alone, are those of an engine heard throughout."""
    full = scripted(3, [])
    heading_id = CODEC.heading_arbitration_id
    engine = StandEngine(config(seed=3, faults=FAULTY))
    engine.pass_to(200.0)
    heard = engine.advance_to(300.0)
    heard += engine.receive(CODEC.encode_command_set(31, 20, 6))
    heard += engine.receive(CODEC.encode_command_start())
    engine.pass_to(450.0)
    compass = engine.advance_to(600.0, compass_only=True)
    rows = [(m.timestamp, m.arbitration_id, bytes(m.data), m.is_error_frame) for m in heard]
    assert rows == [f for f in full if 200.0 < f[0] <= 300.0]
    rows = [(m.timestamp, m.arbitration_id, bytes(m.data), m.is_error_frame) for m in compass]
    assert rows == [f for f in full if f[0] > 450.0 and (f[1] == heading_id or f[3])]
    assert len(rows) > 250  # 150 s at 10 Hz, less the dropped


# ---------------------------------------------------------------------------------- encoding
@given(
    st.lists(
        st.tuples(
            st.integers(0, 2**32 - 1),
            st.integers(0, 524_287).map(lambda raw: raw / 1000),
            st.booleans(),
            st.integers(0, 15),
        ),
        min_size=1,
        max_size=20,
    )
)
def test_batch_heading_encoding_equals_cantools(rows: list) -> None:
    ((message, signals),) = CODEC.layout(HEADING_KEYS)
    encoder = BatchEncoder(message, signals, "heading_crc")
    columns = [np.array(c) for c in zip(*rows, strict=True)]
    keys = ["heading_time", "heading", "heading_valid", "heading_counter"]
    data = encoder.pack(dict(zip(keys, columns, strict=True)), len(rows))
    for row, (time_ms, heading, valid, counter) in zip(data, rows, strict=True):
        expected = CODEC.encode_heading(time_ms, heading, valid, counter, strict=False)
        assert row.tobytes() == bytes(expected.data)


@given(
    st.tuples(
        st.integers(0, 2**32 - 1),
        st.booleans(),
        st.integers(0, 35_999).map(lambda r: r / 100),
        st.integers(0, 65_535).map(lambda r: r / 100),
        st.integers(0, 65_535).map(lambda r: r / 1000),
        st.integers(0, 32767),
        st.integers(0, 35_999).map(lambda r: r / 100),
    )
)
def test_batch_status_encoding_equals_cantools(values: tuple) -> None:
    columns = {key: np.array([value]) for key, value in zip(STATUS_KEYS, values, strict=True)}
    packed = [BatchEncoder(m, s).pack(columns, 1)[0] for m, s in CODEC.layout(STATUS_KEYS)]
    assert [p.tobytes() for p in packed] == [bytes(m.data) for m in CODEC.encode_status(*values)]
