"""Liveness and frame accounting of the campaign engine, on the lockstep simulated stand (virtual
time, deterministic for the seed): a trial whose heading frames are all unusable fails after the
plan's bus-silence timeout of stand time with the real cause; gaps are found from the stand time
as well as from the 4-bit counter (16 or 32 missing frames are not silent); a received corrupt
frame is not also a lost one; counter jumps without a time gap are counted as such, not as lost
frames; a run of identical readings inside a window is flagged; a command that never shows up in
the stream times out."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import can
import numpy as np
import pytest

from gyrostand.acquisition.bus import Recorder as FrameQueue
from gyrostand.acquisition.engine import Command, Engine, Phase
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.plan.model import parse_plan
from gyrostand.stand.protocol import Codec

from .harness import NoCommands, Recorder, plan_text, quick_config, small_plan

HEADING_ID = Codec().heading_arbitration_id
CRC_BYTE = 7  # GYRO_HEADING.CRC : 56|8 in stand/gyrostand.dbc
# trial 1, series 1, observation 1 of the clean run (seed 1): stand time 60.1 s to 90.1 s
WINDOW_1 = (60_100, 90_100)

Tamper = Callable[[list[can.Message]], list[can.Message]]


class Tampered(Lockstep):
    """The lockstep stand with every step's frames passed through `tamper` (commands and acks,
    which reach the stream between steps, are left alone)."""

    def __init__(self, tamper: Tamper | None = None, **faults: object) -> None:
        super().__init__(quick_config(**faults))
        if tamper is not None:
            advance = self.stand.advance_to
            self.stand.advance_to = lambda t: tamper(advance(t))  # type: ignore[method-assign]


def run(
    tamper: Tamper | None = None, max_stand_s: float = 1_000.0, **faults: object
) -> tuple[Recorder, Tampered, Engine]:
    sink, sim = Recorder(), Tampered(tamper, **faults)
    engine = Engine(small_plan(), sink, sim)
    sim.run(engine, max_stand_s)
    return sink, sim, engine


def failures(sink: Recorder) -> list[tuple]:
    return [(a[0], a[1], a[2]) for a in sink.of("trial_failed")]


def events(sink: Recorder, kind: str) -> list[tuple]:
    """(severity, message, trial, j, stand time ms) of the events of one kind."""
    return [tuple(a[1:]) for a in sink.of("event") if a[0] == kind]


def heading_rows(frames: list[can.Message], keep: Callable[[int], bool]) -> list[can.Message]:
    """The frames without the heading frames whose stand time (ms) `keep` refuses."""
    return [m for m in frames if m.arbitration_id != HEADING_ID or keep(round(m.timestamp * 1000))]


def bad_crc(times_ms: set[int] | None = None) -> Tamper:
    """Flip the CRC byte of the heading frames at the given stand times (all when None)."""

    def tamper(frames: list[can.Message]) -> list[can.Message]:
        for m in frames:
            if m.arbitration_id == HEADING_ID and (
                times_ms is None or round(m.timestamp * 1000) in times_ms
            ):
                data = bytearray(m.data)
                data[CRC_BYTE] ^= 0xFF
                m.data = data
        return frames

    return tamper


# ------------------------------------------------------------------ no valid heading frame
def quiet(trial: int, j: int | None, seconds: float, frames: int, cause: str) -> tuple:
    """A trial failed for want of a valid heading frame."""
    return (
        trial,
        j,
        f"no valid heading frame for {seconds:g} s of stand time "
        f"({frames} of {frames} frames invalid: {cause})",
    )


# The stand's first frames are stamped 0 ms; its statuses come every 500 ms, its heading frames
# every 100 ms (a heading frame before the status of the same instant). bus_silence_s = 5 s.


def test_every_heading_out_of_range_fails_each_trial_at_the_timeout() -> None:
    """Before: the campaign stayed "running" in settling for ever (no heading frame was ever
    decoded, so no settle block closed and max_wait_s was never checked)."""
    sink, _, engine = run(out_of_range_rate=1.0)
    cause = "GYRO_HEADING.HEADING outside its range"
    # trial 1: counted from the first stand time (0 ms); the first status past 5 s is at 5.5 s,
    # after the heading frames of 0..5.5 s (56); trial 2 counts from there: 5.6..11 s (55)
    assert failures(sink) == [quiet(1, 1, 5.5, 56, cause), quiet(2, 1, 5.5, 55, cause)]
    assert [(e[0], e[2], e[4]) for e in events(sink, "no valid heading")] == [
        ("error", 1, 5_500),
        ("error", 2, 11_000),
    ]
    assert engine.outcome == "completed" and engine.now_ms == 11_000
    assert not sink.observations


def test_every_heading_with_a_bad_crc_fails_with_the_crc_reason() -> None:
    sink, _, engine = run(bad_crc())
    cause = "CRC mismatch"
    assert failures(sink) == [quiet(1, 1, 5.5, 56, cause), quiet(2, 1, 5.5, 55, cause)]
    assert [e[4] for e in events(sink, "no valid heading")] == [5_500, 11_000]
    assert engine.outcome == "completed"


def test_every_heading_flagged_invalid_fails_with_that_reason_not_as_unsettled() -> None:
    """Before: the trial failed after max_wait_s (3600 s) as "not settled within 3600 s"."""
    sink, _, engine = run(invalid_rate=1.0, max_stand_s=5_000.0)
    # decoded heading frames carry their stand time: the first one past 5 s is at 5.1 s (52
    # frames since 0 ms); trial 2 (still confirming the stand is still: j is None) at 10.2 s
    cause = "VALID flag cleared"
    assert failures(sink) == [quiet(1, 1, 5.1, 52, cause), quiet(2, None, 5.1, 51, cause)]
    assert [e[4] for e in events(sink, "no valid heading")] == [5_100, 10_200]
    assert engine.outcome == "completed"


# -------------------------------------------------------------------------- gaps and counter
@pytest.mark.parametrize("missing", [15, 16, 17, 32])
def test_a_gap_is_counted_from_stand_time_and_the_counter(missing: int) -> None:
    """Before: 16 and 32 missing frames (whole turns of the 4-bit counter) counted 0 and raised
    nothing; 17 counted 1."""
    start = 70_000  # inside observation 1 of trial 1 (60.1 s to 90.1 s)
    gap = range(start, start + missing * 100, 100)
    sink, _, engine = run(lambda frames: heading_rows(frames, lambda t: t not in gap))
    assert engine.outcome == "completed" and not failures(sink)
    first, *rest = sink.observations
    assert (first.window_start_ms, first.window_end_ms) == WINDOW_1
    assert (first.frames_used, first.frames_lost, first.flags) == (
        300 - missing,
        missing,
        f"lost={missing}",
    )
    assert all(o.frames_lost == 0 and o.flags == "" for o in rest)
    assert events(sink, "frame anomalies")[0] == (
        "warning",
        f"observation 1: lost={missing}",
        1,
        1,
        90_100,
    )
    after = start + missing * 100
    hidden = [
        (
            "warning",
            f"{missing} heading frames missing before stand time {after / 1000:g} s "
            f"({(after - start + 100) / 1000:g} s after the previous one, expected every 100 ms; "
            f"the 4-bit counter shows {missing % 16})",
            1,
            1,
            after,
        )
    ]
    assert events(sink, "frame gap") == ([] if missing < 16 else hidden)


def test_a_corrupt_frame_is_not_also_a_lost_one() -> None:
    """Before: a heading frame received with a bad CRC left a counter gap, counted as lost too."""
    sink, _, _ = run(bad_crc({70_000, 75_000, 80_000}))
    first = sink.observations[0]
    assert (first.frames_used, first.frames_lost, first.flags) == (297, 0, "corrupt=3")
    assert not events(sink, "frame gap")


def test_counter_jumps_without_a_time_gap_are_not_lost_frames() -> None:
    """Before: every jump of the counter (2..15 values skipped, no frame missing in stand time)
    was counted as lost frames."""
    sink, sim, engine = run(counter_jump_rate=0.02)
    assert engine.outcome == "completed"
    obs = sink.observations
    assert all(o.frames_lost == 0 for o in obs)
    assert all(o.frames_used == (o.window_end_ms - o.window_start_ms) // 100 for o in obs)
    # independently: the heading frames of each window whose counter did not step by 1
    h = BatchDecoder(Codec()).decode(RawFrames.from_messages(0, sim.stream)).headings
    jumped = h.t_ms[1:][np.diff(h.counter) % 16 != 1]
    expected = [
        int(((jumped >= o.window_start_ms) & (jumped < o.window_end_ms)).sum()) for o in obs
    ]
    assert [o.flags for o in obs] == [f"counter_jump={n}" if n else "" for n in expected]
    assert expected[:3] == [5, 7, 7] and sum(expected) == 63
    messages = [e[1] for e in events(sink, "frame anomalies")]
    assert messages[0] == "observation 1: counter_jump=5"
    assert not events(sink, "frame gap")


# ----------------------------------------------------------------------------- stuck sensor
def test_a_stuck_run_inside_a_window_is_flagged() -> None:
    """A sensor stuck for 9.3 s inside a 30 s window: 94 identical readings in a row (the last
    good one and the 93 stuck ones), 31 % of the window's 300 frames. Before: no flag."""
    sink, _, engine = run(stuck_at_s=70.0, stuck_for_s=9.3)
    assert engine.outcome == "completed" and not failures(sink)
    first, *rest = sink.observations
    assert (first.frames_used, first.frames_lost, first.flags) == (300, 0, "stuck=94")
    assert all("stuck" not in o.flags for o in rest)
    assert events(sink, "stuck sensor") == [
        (
            "warning",
            "observation 1: 94 identical heading readings in a row (31% of its 300 frames; "
            "flagged above 30)",
            1,
            1,
            90_100,
        )
    ]


def test_a_clean_run_has_no_stuck_flag() -> None:
    sink, _, _ = run()
    assert all(o.flags == "" for o in sink.observations)
    assert len(sink.observations) == 12


def settled_at(sink: Recorder) -> dict[tuple[int, int], int]:
    """(trial, j) -> stand time (ms) each series settled."""
    return {(a[0], a[1]): a[2] for a in sink.of("series_settled")}


def test_a_stuck_run_inside_a_settle_hold_is_flagged_and_not_settled_on() -> None:
    """The sensor stuck from 30 s to 55 s, inside the hold (two 30 s blocks) that settles
    series 1 of trial 1 at 60.1 s in the clean run: the block 30.1-60.1 s is flagged and the
    series settles on the next two blocks instead, at 120.1 s. Before: settled at 60.1 s on
    the stuck readings, without a word."""
    clean, _, _ = run()
    assert settled_at(clean)[1, 1] == 60_100
    sink, _, engine = run(stuck_at_s=30.0, stuck_for_s=25.0)
    assert engine.outcome == "completed" and not failures(sink)
    assert settled_at(sink)[1, 1] == 60_100 + 60_000
    run_length = round((55.0 - 30.1) / 0.1)  # heading frames 30.1 .. 54.9 s of that block
    assert events(sink, "stuck sensor") == [
        (
            "warning",
            f"settle block 30.1-60.1 s: {run_length} identical heading readings in a row "
            f"({run_length / 300:.0%} of its 300 frames; flagged above 30); the series does not "
            "settle on it",
            1,
            1,
            60_100,
        )
    ]
    assert all(o.flags == "" for o in sink.observations)


def test_a_sensor_stuck_through_the_settle_times_it_out_with_the_reason() -> None:
    """Before: the series settled on the stuck readings and the trial failed in its first
    observation window ("stuck sensor: 300 identical readings in observation window 1")."""
    text = plan_text().replace("max_wait_s = 3600.0", "max_wait_s = 300.0")
    sink, sim = Recorder(), Tampered(stuck_at_s=30.0, stuck_for_s=2_000.0)
    engine = Engine(parse_plan(text), sink, sim)
    sim.run(engine, 1_000.0)
    reason = "not settled within 300 s (stuck sensor in the last 2 settle blocks)"
    assert failures(sink)[0] == (1, 1, reason)
    assert not [o for o in sink.observations if o.trial == 1]


def test_a_still_compass_on_a_coarse_sensor_is_not_flagged() -> None:
    """An angle sensor in 0.05 deg steps, coarser than the compass's noise: a still compass
    repeats its reading for whole windows. Told once that runs are not judged; nothing flagged,
    nothing failed. Before: trial 2 failed "stuck sensor: 300 identical readings in
    observation window 2"."""
    sink, sim = Recorder(), Tampered()
    noise = dataclasses.replace(sim.stand.config.noise, quantum_deg=0.05)
    sim.stand = type(sim.stand)(dataclasses.replace(sim.stand.config, noise=noise), Codec())
    engine = Engine(small_plan(), sink, sim)
    sim.run(engine, 3_000.0)
    assert engine.outcome == "completed" and not failures(sink)
    assert len(sink.observations) == 12 and all(o.flags == "" for o in sink.observations)
    (told,) = events(sink, "stuck sensor")
    assert told[0] == "info" and told[1].startswith("runs of identical heading readings are not")


# ------------------------------------------------------------------------- command not seen
class Deaf(Lockstep):
    """Commands never reach the bus (nor the raw stream): the stand keeps sending, still."""

    def issue(self, command: Command, now_ms: int = 0) -> None:
        pass


def test_a_command_never_seen_in_the_stream_times_out() -> None:
    """Before: the engine waited for its own command to show up in the stream for ever."""
    text = plan_text().replace("max_wait_s = 3600.0", "max_wait_s = 600.0")
    assert "max_wait_s = 600.0" in text
    sink, sim = Recorder(), Deaf(quick_config())
    engine = Engine(parse_plan(text), sink, sim)
    sim.run(engine, 2_000.0)
    reason = "command 'stop' not seen in the stream within 600 s of stand time"
    assert failures(sink) == [(1, None, reason), (2, None, reason)]
    assert [e[4] for e in events(sink, "command not seen")] == [600_100, 1_200_200]
    assert engine.outcome == "completed"


# ------------------------------------------------------------------ independent of batching
@pytest.mark.parametrize(
    ("tamper", "faults"),
    [
        (None, {"out_of_range_rate": 1.0}),
        (None, {"invalid_rate": 1.0}),
        (bad_crc({70_000, 75_000, 80_000}), {}),
        (lambda frames: heading_rows(frames, lambda t: not 70_000 <= t < 73_200), {}),
        (None, {"counter_jump_rate": 0.02, "drop_rate": 0.01, "corrupt_rate": 0.01}),
        (None, {"stuck_at_s": 70.0, "stuck_for_s": 9.3}),
    ],
)
def test_the_new_rules_do_not_depend_on_batching(tamper: Tamper | None, faults: dict) -> None:
    """A replay of the stream in batches of 7 and 977 frames (and of 1, for the short ones)
    makes the same calls."""
    live, sim, _ = run(tamper, **faults)
    for size in (1, 7, 977) if len(sim.stream) < 5_000 else (7, 977):
        sink = Recorder()
        engine = Engine(small_plan(), sink, NoCommands())
        decoder = BatchDecoder(Codec())
        for start in range(0, len(sim.stream), size):
            chunk = sim.stream[start : start + size]
            engine.feed(decoder.decode(RawFrames.from_messages(start, chunk)))
        assert sink.calls == live.calls, size


# ---------------------------------------------------------------------------- queue overflow
class Congested(Lockstep):
    """The lockstep stand's frames pass through the acquisition's bounded queue
    (`acquisition.bus.Recorder`), which the campaign does not drain during the steps that end
    in `stalls` (stand time s, as a campaign thread held up would not): the queue fills and
    drops what comes, as live. `sent`: frames the stand put in the queue, per step end, and
    `stream` all of them."""

    def __init__(self, maxsize: int, stalls: set[float], **faults: object) -> None:
        super().__init__(quick_config(**faults))
        self.queue, self.stalls = FrameQueue(maxsize, None), stalls
        self.sent: dict[float, int] = {}

    def run(self, engine: Engine, max_stand_s: float = 1_000.0) -> None:
        decoder = BatchDecoder(Codec())
        position, t = 0, 0.0
        while engine.phase is not Phase.DONE and t < max_stand_s:
            t += self.step_s
            frames, self._pending = self._pending + self.stand.advance_to(t), []
            self.sent[t] = len(frames)
            self.stream += frames
            for msg in frames:
                self.queue.on_message_received(msg)
            if t in self.stalls:
                continue
            msgs = self.queue.drain(1_000_000, 0.0)
            for before, overflow in self.queue.overflows:
                engine.frames_dropped(position + before, overflow)
            engine.feed(decoder.decode(RawFrames.from_messages(position, msgs)))
            position += len(msgs)


def congested(maxsize: int, stalls: set[float], **faults: object) -> tuple[Recorder, Congested]:
    sink, sim = Recorder(), Congested(maxsize, stalls, **faults)
    engine = Engine(small_plan(), sink, sim)
    sim.run(engine)
    assert engine.outcome == "completed"
    return sink, sim


def test_a_queue_overflow_fails_the_trial_as_an_overflow_not_as_bus_silence() -> None:
    """The campaign held up from 100 s to 130 s of stand time (inside trial 1's second still
    window): the queue of 200 frames fills and every later frame is dropped until it is
    drained. Before: "bus silence: no heading frame for 25.6 s of stand time"."""
    stalls = {100.0, 105.0, 110.0, 115.0, 120.0, 125.0}
    sink, sim = congested(200, stalls)
    dropped = sum(sim.sent[t] for t in (*stalls, 130.0)) - 200  # the last step's too
    assert dropped > 300 and sim.queue.dropped == dropped
    (trial, j, reason), *_ = failures(sink)
    assert (trial, j) == (1, 1)
    assert reason.startswith(
        f"the acquisition's queue overflowed: {dropped} frames dropped (no valid heading frame for "
    )
    assert [(e[0], e[1]) for e in events(sink, "queue overflow")] == [("error", reason)]
    assert not events(sink, "bus silence")


def test_an_overflow_shorter_than_the_timeout_is_lost_frames_and_no_later_silence_s_cause() -> None:
    """Frames dropped for a few seconds are lost frames of the window they fall in; the stand's
    silence of 30 s later on is still told as bus silence."""
    sink, sim = congested(120, {65.0}, silence_at_s=150.0, silence_for_s=30.0)
    # the queue, empty after the step ending at 60 s, keeps the first 120 frames of the next two
    before = sum(n for t, n in sim.sent.items() if t <= 60.0)
    lost = sim.stream[before + 120 : before + sim.sent[65.0] + sim.sent[70.0]]
    assert sim.queue.dropped == len(lost) == 40  # 2.5 s, less than the 5 s timeout
    first = sink.observations[0]
    assert (first.trial, first.j, first.k) == (1, 1, 1)
    assert first.flags == f"lost={sum(m.arbitration_id == HEADING_ID for m in lost)}"
    (trial, _, reason), *_ = failures(sink)
    assert trial == 1 and reason.startswith("bus silence: no heading frame for ")
    assert not events(sink, "queue overflow")
