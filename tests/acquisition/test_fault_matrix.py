"""Every fault knob of the simulated stand (`FaultParams`) and every limit of its roll stand
(`StandParams`), one row each, on the lockstep harness (virtual time, seed 1, the small plan: two
trials, N = 3): the status of each trial, the failure reason, the kind and severity of the events
recorded, and the frame accounting of every observation.

The expected counts come from the frames the stand actually sent (`Lockstep.stream`), decoded
here bit by bit from the DBC layout with an independent CRC (crccheck), not from the engine or
the codec under test."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Any

import can
import pytest
from crccheck.crc import Crc8SaeJ1850

from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.plan.model import Plan
from gyrostand.stand.simconfig import FaultParams, StandParams

from .harness import Recorder, quick_config, small_plan

# GYRO_HEADING in stand/gyrostand.dbc (Intel byte order): STAND_TIME 0|32 ms, HEADING 32|19
# x 0.001 deg [0|359.999], VALID 51|1, COUNTER 52|4, CRC 56|8 (CRC-8/SAE-J1850 over the 8 bytes
# with the CRC byte zeroed)
HEADING_ID = 0x100
HEADING_MAX_RAW = 359_999
INTERVAL_MS = 100  # quick_config: heading frames at 10 Hz
TRIALS = ((45.0, 24.0, 6.0), (315.0, 20.0, 5.0))  # K deg, A cm, tau s of the small plan


@dataclass(frozen=True)
class Sent:
    """One heading frame as the stand put it on the bus."""

    t_ms: int
    heading_raw: int
    counter: int
    valid: bool
    in_range: bool
    crc_ok: bool

    @property
    def usable(self) -> bool:
        return self.crc_ok and self.in_range and self.valid


def sent(msg: can.Message) -> Sent:
    data = bytes(msg.data)
    word = int.from_bytes(data, "little")
    return Sent(
        t_ms=round(msg.timestamp * 1000),
        heading_raw=word >> 32 & 0x7FFFF,
        counter=word >> 52 & 0xF,
        valid=bool(word >> 51 & 1),
        in_range=(word >> 32 & 0x7FFFF) <= HEADING_MAX_RAW,
        crc_ok=Crc8SaeJ1850.calc(data[:7] + b"\x00") == data[7],
    )


@dataclass(frozen=True)
class Run:
    plan: Plan
    sink: Recorder
    sim: Lockstep
    engine: Engine

    @cached_property
    def headings(self) -> list[Sent]:
        return [
            sent(m)
            for m in self.sim.stream
            if m.arbitration_id == HEADING_ID and not m.is_error_frame
        ]

    def statuses(self) -> tuple[str, ...]:
        done = {a[0] for a in self.sink.of("trial_completed")}
        failed = {a[0] for a in self.sink.of("trial_failed")}
        assert not done & failed
        return tuple(
            "completed" if i in done else "failed" if i in failed else "never ended"
            for i in range(1, len(TRIALS) + 1)
        )

    def reasons(self) -> dict[int, str]:
        return {a[0]: a[2] for a in self.sink.of("trial_failed")}

    def noteworthy(self) -> set[tuple[str, str]]:
        """(kind, severity) of every event but the commands sent."""
        return {(a[0], a[1]) for a in self.sink.of("event") if a[0] != "command"}

    def settled_ms(self, trial: int, j: int) -> int:
        """Stand time at which series j of a trial settled: its first window starts there."""
        (t_ms,) = [a[2] for a in self.sink.of("series_settled") if a[:2] == (trial, j)]
        return t_ms


def run(faults: dict[str, Any], stand: dict[str, float]) -> Run:
    plan = small_plan()
    config = quick_config(**faults)
    config = replace(config, stand=StandParams(**stand))
    sink, sim = Recorder(), Lockstep(config)
    engine = Engine(plan, sink, sim)
    sim.run(engine)
    return Run(plan, sink, sim, engine)


def accounting(r: Run, start_ms: int, end_ms: int) -> tuple[int, int, str]:
    """(frames used, frames lost, flags) of the window [start, end) from the frames sent.
    Received frames are corrupt (CRC), out of range, or VALID cleared, in that order. Between two
    decodable frames (CRC and range good) the 10 Hz slots that stayed empty are lost frames, and
    a counter that does not step by one per frame sent, with no slot empty, is a jump; both are
    told at the later frame, in its window. Error frames are counted where they were sent."""
    counts = {"corrupt": 0, "out_of_range": 0, "invalid": 0, "counter_jump": 0, "lost": 0}
    used = 0
    previous: Sent | None = None
    unusable = 0  # frames sent since the previous decodable one that cannot be decoded
    for now in r.headings:
        inside = start_ms <= now.t_ms < end_ms
        if not now.crc_ok or not now.in_range:
            unusable += 1
            if inside:
                counts["corrupt" if not now.crc_ok else "out_of_range"] += 1
            continue
        if inside and previous is not None:
            missing = (now.t_ms - previous.t_ms) // INTERVAL_MS - 1 - unusable
            step = (now.counter - previous.counter - 1 - unusable) % 16
            counts["lost"] += missing
            counts["counter_jump"] += int(missing == 0 and step != 0)
        if inside:
            if now.valid:
                used += 1
            else:
                counts["invalid"] += 1
        previous, unusable = now, 0
    counts["error_frame"] = sum(
        1
        for m in r.sim.stream
        if m.is_error_frame and start_ms <= round(m.timestamp * 1000) < end_ms
    )
    flags = ",".join(f"{k}={v}" for k, v in sorted(counts.items()) if v)
    return used, counts["lost"], flags


def last_status(trial: int, factor: float) -> str:
    """How the stand reports rocking trial `trial` at `factor` x its amplitude."""
    k, a, tau = TRIALS[trial - 1]
    return f"rocking, K={k:g} deg, A={a * factor:g} cm, tau={tau:g} s"


def longest_silence_s(r: Run) -> float:
    times = [h.t_ms for h in r.headings]
    return max(b - a for a, b in zip(times, times[1:], strict=False)) / 1000


def stuck_readings(r: Run) -> int:
    """Heading frames in the first still window of trial 1 (all stuck in that row)."""
    start = r.settled_ms(1, 1)
    end = start + round(r.plan.observation.still_window_s * 1000)
    inside = [h for h in r.headings if start <= h.t_ms < end]
    assert len({h.heading_raw for h in inside}) == 1
    return len(inside)


Reason = Callable[[Run, int], str]  # the failure reason of trial i


@dataclass(frozen=True)
class Row:
    """One knob (or knob pair) set; what each trial ends as, the failure reason of the failed
    ones (from the run's plan and stream), the events other than commands, whether the knob
    shows in the observations' flags (every observation's accounting is checked against the
    frames sent either way), and the series that got observations."""

    id: str
    faults: dict[str, Any] = field(default_factory=dict)
    stand: dict[str, float] = field(default_factory=dict)
    statuses: tuple[str, str] = ("completed", "completed")
    reason: Reason | None = None
    events: frozenset[tuple[str, str]] = frozenset()
    accounted: bool = False
    series: frozenset[tuple[int, int]] = frozenset((i, j) for i in (1, 2) for j in (1, 2))


ANOMALIES = frozenset({("frame anomalies", "warning")})
FAILED_1 = ("failed", "completed")
FAILED_2 = ("completed", "failed")
BOTH_FAILED = ("failed", "failed")
ROWS = [
    Row("drop_rate", {"drop_rate": 0.05}, events=ANOMALIES, accounted=True),
    Row("counter_jump_rate", {"counter_jump_rate": 0.02}, events=ANOMALIES, accounted=True),
    Row("invalid_rate", {"invalid_rate": 0.05}, events=ANOMALIES, accounted=True),
    Row("out_of_range_rate", {"out_of_range_rate": 0.02}, events=ANOMALIES, accounted=True),
    Row("corrupt_rate", {"corrupt_rate": 0.03}, events=ANOMALIES, accounted=True),
    Row("error_frame_rate", {"error_frame_rate": 0.001}, events=ANOMALIES, accounted=True),
    Row(
        "error_frame_rate over the series limit",
        {"error_frame_rate": 0.05},
        statuses=BOTH_FAILED,
        reason=lambda r, _: (
            f"more than {r.plan.checks.max_error_frames} error frames in one series"
        ),
        events=frozenset({("error frames", "error")}),
        series=frozenset(),
    ),
    Row(
        "stuck_at_s, stuck_for_s",
        {"stuck_at_s": 60.0, "stuck_for_s": 40.0},  # over trial 1's first window (60.1-90.1 s)
        statuses=FAILED_1,
        reason=lambda r, _: (
            f"stuck sensor: {stuck_readings(r)} identical readings in observation window 1"
        ),
        # the readings still stuck after trial 1 failed open trial 2's first settle block:
        # flagged there too, and not settled on
        events=frozenset({("stuck sensor", "error"), ("stuck sensor", "warning")}),
        series=frozenset({(2, 1), (2, 2)}),
    ),
    Row(
        "silence_at_s, silence_for_s",
        {"silence_at_s": 150.0, "silence_for_s": 30.0},  # in trial 1's third still window
        statuses=FAILED_1,
        reason=lambda r, _: (
            f"bus silence: no heading frame for {longest_silence_s(r):g} s of stand time"
        ),
        events=frozenset({("bus silence", "error")}),
        series=frozenset({(1, 1), (2, 1), (2, 2)}),
    ),
    Row(
        "no_ack",
        {"no_ack": True},
        statuses=BOTH_FAILED,
        reason=lambda r, _: (
            "stand did not acknowledge 'stop' within "
            f"{r.plan.timeouts.ack_s * r.plan.bus.speedup:g} s of stand time"
        ),
        events=frozenset({("no ack", "error")}),
        series=frozenset(),
    ),
    # a stand that reports the command whatever it rocks at goes unnoticed without an
    # inclinometer (tests/acquisition/test_measured_motion.py: with one, it fails the trial)
    Row("amplitude_unreported", {"amplitude_unreported": True, "amplitude_factor": 0.8}),
    Row(
        "amplitude_factor",
        {"amplitude_factor": 0.8},
        statuses=BOTH_FAILED,
        reason=lambda r, i: (
            f"stand not rocking as commanded within {r.plan.tracking.confirm_s:g} s "
            f"(last status: {last_status(i, 0.8)})"
        ),
        events=frozenset({("mis-tracking", "error")}),
        series=frozenset({(1, 1), (2, 1)}),  # still series acquired before the stand rocked
    ),
    Row(
        "compass_fault_bits",
        {"compass_fault_bits": 0b0100},  # bit 2: angle sensor (DBC comment of FAULT_BITS)
        statuses=BOTH_FAILED,
        reason=lambda *_: "compass reports fault bits 0x04 (angle sensor)",
        events=frozenset({("compass fault", "error")}),
        series=frozenset(),
    ),
    Row(
        "max_amplitude_cm",
        stand={"max_amplitude_cm": 22.0},  # trial 1 asks 24 cm, trial 2 20 cm
        statuses=FAILED_1,
        reason=lambda *_: "stand refused 'set': amplitude out of stand limits",
        events=frozenset({("stand refusal", "error")}),
        series=frozenset({(1, 1), (2, 1), (2, 2)}),
    ),
    Row(
        "min_period_s",
        stand={"min_period_s": 5.5},  # trial 1 asks 6 s, trial 2 5 s
        statuses=FAILED_2,
        reason=lambda *_: "stand refused 'set': period out of stand limits",
        events=frozenset({("stand refusal", "error")}),
        series=frozenset({(1, 1), (1, 2), (2, 1)}),
    ),
    Row(
        "max_period_s",
        stand={"max_period_s": 5.5},
        statuses=FAILED_1,
        reason=lambda *_: "stand refused 'set': period out of stand limits",
        events=frozenset({("stand refusal", "error")}),
        series=frozenset({(1, 1), (2, 1), (2, 2)}),
    ),
]


@pytest.mark.parametrize("row", ROWS, ids=[r.id for r in ROWS])
def test_fault_matrix(row: Row) -> None:
    r = run(row.faults, row.stand)
    assert r.engine.outcome == "completed"  # on_trial_failure = "continue"
    assert r.statuses() == row.statuses
    failed = [i for i, status in enumerate(row.statuses, start=1) if status == "failed"]
    assert row.reason is not None or not failed
    expected = {i: row.reason(r, i) for i in failed} if row.reason is not None else {}
    assert r.reasons() == expected
    assert r.noteworthy() == row.events
    errors = [a for a in r.sink.of("event") if a[1] == "error"]
    assert [a[3] for a in errors] == failed  # one error event per failed trial, its own
    n = r.plan.n_obs
    acquired = {(o.trial, o.j) for o in r.sink.observations}
    assert acquired == row.series
    for trial, j in row.series:
        if trial not in failed:
            ks = [o.k for o in r.sink.observations if (o.trial, o.j) == (trial, j)]
            assert ks == list(range(1, n + 1))
    for o in r.sink.observations:  # every window: as the frames sent say
        expected_frames = accounting(r, o.window_start_ms, o.window_end_ms)
        assert (o.frames_used, o.frames_lost, o.flags) == expected_frames, o
        # every 10 Hz slot of the window is a frame used, lost, or received unusable
        counts = dict(f.split("=") for f in o.flags.split(",") if f)
        unusable = sum(int(counts.get(k, 0)) for k in ("invalid", "corrupt", "out_of_range"))
        slots = (o.window_end_ms - o.window_start_ms) // INTERVAL_MS
        assert o.frames_used + o.frames_lost + unusable == slots, o
    assert any(o.flags for o in r.sink.observations) == row.accounted
    warnings = [a for a in r.sink.of("event") if a[0] == "frame anomalies"]
    assert [a[2] for a in warnings] == [
        f"observation {o.k}: {o.flags.replace(',', ', ')}" for o in r.sink.observations if o.flags
    ]


def test_every_knob_has_a_row() -> None:
    """A new fault knob or stand limit cannot go untested: each field of FaultParams and
    StandParams is set (away from its default) by some row."""
    set_by_rows = {
        (cls, name)
        for row in ROWS
        for cls, knobs in (
            (FaultParams, row.faults),
            (StandParams, row.stand),
        )
        for name in knobs
    }
    for cls in (FaultParams, StandParams):
        for f in fields(cls):
            assert (cls, f.name) in set_by_rows, f"{cls.__name__}.{f.name} has no row"
    for row in ROWS:
        for cls, knobs in ((FaultParams, row.faults), (StandParams, row.stand)):
            defaults = cls()
            assert all(getattr(defaults, k) != v for k, v in knobs.items()), row.id
