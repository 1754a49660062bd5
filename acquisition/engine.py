"""The campaign state machine: frames in stream order -> observations, events, commands.

One implementation for live acquisition and offline replay. It sees only decoded frames
(`FrameBatch`) and times everything by the STAND time they carry, so the result does not depend on
how the stream is cut into batches nor on how fast it arrives. Per trial i (seed 000 §2):

    stand still -> settle -> N observations, series j = 1 -> set K, A, tau + start -> confirm the
    stand tracks it -> settle -> N observations, series j = 2 -> stop

Settled means the plan's band criterion holds over the settle blocks (window-long means), or,
with `[settle] method = "estimate"` / "compensated", the compass's transient model fitted online
(`acquisition.early_settle`, seed 003): the settle point is known and the transient left over
the observations bounded, or compensated at the end of the series.

Commands go out through a `Commander` (the live one talks to the stand; replay's does nothing):
in both cases the engine waits for the stand's acknowledgement IN THE STREAM, so a replay of the
raw log takes exactly the same decisions as the live run did. Results go to a `Sink` (the
database store).

Arithmetic is exact where order could matter: heading deviations from the trial's reference are
quantised to nano-degrees and summed as integers, so a window mean is bit-identical however the
frames were batched.

Every wait has a stand-time limit: no VALID heading frame for `timeouts.bus_silence_s` (stand time
as told by any heading frame, stand status or SIM_CLOCK tick) fails the trial with what the frames
that came had (CRC mismatch, a value outside its range, VALID cleared; bus silence when none came);
acks, the stand's confirmation, settling and a command's own echo in the stream have theirs. Gaps
between heading frames are judged from the stand time (against the expected interval learnt from
the stream) as well as from the source's sequence numbers (gyrostand's 4-bit counter, NMEA 2000's
SID modulo 253; none for serial sentences): 16 or 32 missing frames are counted and told, a
counter jump with no time gap is a "counter_jump", and a frame received unusable is not lost. A
heading without a sequence number (`devices.source.NO_SEQUENCE`) is judged by time alone.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Literal, Protocol

import numpy as np

from gyrostand.acquisition.early_settle import (
    EarlySettle,
    Identified,
    TransientRecord,
    band_settled,
    describe,
    hold_blocks,
    identify,
)
from gyrostand.acquisition.motion import MotionRecorder
from gyrostand.analysis.angles import wrap180
from gyrostand.analysis.gls import SharedError
from gyrostand.analysis.measured_motion import STAND_REPORT, MeasuredMotion, preferred
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.analysis.transient import PLAN_CONTRADICTED
from gyrostand.devices.source import SourceInfo
from gyrostand.devices.stand_frames import GYROSTAND
from gyrostand.frames.batch import DeviceEvent, FrameBatch, Headings, RollSample, Statuses
from gyrostand.plan.model import EstimatePlan, Plan, TrialPlan
from gyrostand.stand.protocol import (
    AckFrame,
    ClockFrame,
    CommandFrame,
    CompassStatusFrame,
    Frame,
    InvalidFrame,
)

NANO = 1_000_000_000  # deviations are summed as integer nano-degrees
INTERVAL_SAMPLE = 20  # heading-frame spacings whose median is the expected frame interval
# Stuck: a run of identical consecutive readings, in an observation window or a settle block,
# longer than STUCK_MIN_RUN frames (per STUCK_RESOLUTION_DEG of the source's resolution: a
# coarser heading stays longer on one value), than STUCK_FRACTION of its valid frames (a real
# heading at 0.001 deg under noise changes within ~13 frames: longest run in 800 000 still
# frames of the simulated 16-bit sensor) and than the sensor's resolution makes likely:
# readings that repeat at the rate p seen so far (still and rocking apart) give a run of L
# among n frames about n p^(L-1) times (geometric run lengths); a run whose expected count is
# below STUCK_CHANCE is stuck. A sensor coarser than the compass's noise repeats most readings
# (p > STUCK_RESOLVED) and its runs are far longer than geometric (the noise is correlated:
# runs of 500 frames at p = 0.84 on the simulated compass, 0.03 deg steps): a run is then no
# sign, and none is judged (told once). Nor before STUCK_LEARN pairs of readings have been seen.
STUCK_MIN_RUN = 20
STUCK_RESOLUTION_DEG = 0.001
STUCK_FRACTION = 0.1
STUCK_CHANCE = 1e-4
STUCK_RESOLVED = 0.5
STUCK_LEARN = 200
CAN_ERR_BUSOFF = 0x40  # SocketCAN error class bit in the error frame's identifier
COMPASS_FAULTS = ("rotor", "fluid temperature", "angle sensor", "follow-up")  # DBC FAULT_BITS


@dataclass(frozen=True)
class Command:
    kind: Literal["stop", "set", "start"]
    direction_deg: float = 0.0
    amplitude_cm: float = 0.0
    period_s: float = 0.0

    def describe(self) -> str:
        if self.kind != "set":
            return self.kind
        return (
            f"set K={self.direction_deg:g} deg, A={self.amplitude_cm:g} cm, tau={self.period_s:g} s"
        )


class CommandNotSent(Exception):
    """The commander could not put the command on the bus at all."""


@dataclass(frozen=True)
class ObservationResult:
    """delta_jik of seed 000 eq 2.1: the mean heading over one stand-time window."""

    trial: int
    j: int
    k: int
    value_deg: float
    window_start_ms: int
    window_end_ms: int
    frames_used: int
    frames_lost: int
    flags: str


@dataclass(frozen=True)
class SeriesCompensation:
    """The transient subtracted from observations ``first_k``, ``first_k + 1``, ... of a
    compensated series (deg each, the fitted transient over the observation's window) and the
    standard error of the series' compensated mean (`analysis.transient.compensated_mean_se`:
    its settle point's, with the observations' residual scatter about the fit)."""

    first_k: int
    transient_deg: tuple[float, ...]
    standard_error_deg: float
    shared: SharedError | None = None  # its share in the period and damping error (issue 34)


@dataclass(frozen=True)
class Measured:
    """The motion trial i applies: A and tau of its preferred measuring source
    (`analysis.measured_motion.PREFERENCE`, named in `source`), K of the stand's reports (None:
    not reported)."""

    direction_deg: float | None
    amplitude_cm: float
    period_s: float
    source: str = STAND_REPORT


class Commander(Protocol):
    def issue(self, command: Command, now_ms: int) -> None: ...


class DroppedFrames(Protocol):
    """Frames the acquisition dropped in a row, its queue full (counted until it takes frames
    again)."""

    frames: int


class Operator(Protocol):
    def before_trial(self, trial: int) -> str | None:
        """Block until the operator has answered the plan's prompts before `trial`: None, or
        why the campaign stops instead."""
        ...


class Sink(Protocol):
    def trial_started(self, trial: int) -> None: ...
    def series_settling(self, trial: int, j: int, t_ms: int) -> None: ...
    def series_settled(self, trial: int, j: int, t_ms: int, outcome: SettleOutcome) -> None: ...
    def observation(self, obs: ObservationResult) -> None: ...
    def series_completed(
        self,
        trial: int,
        j: int,
        compensation: SeriesCompensation | None = None,
        motion: tuple[MeasuredMotion, ...] = (),
    ) -> None: ...
    def series_compensated(self, trial: int, j: int, compensation: SeriesCompensation) -> None:
        """A completed series of the trial's current attempt compensated later (replaces)."""
        ...

    def trial_completed(self, trial: int, measured: Measured | None) -> None: ...
    def trial_failed(self, trial: int, j: int | None, reason: str) -> None: ...
    def event(
        self,
        kind: str,
        severity: str,
        message: str,
        trial: int | None = None,
        j: int | None = None,
        t_ms: int | None = None,
    ) -> None: ...
    def flush(self) -> None:
        """Make the writes so far durable (an observation is at once): the engine calls it at
        the end of each of its calls, before a command goes out and before it waits for the
        operator."""
        ...


@dataclass(frozen=True)
class TrialState:
    """What the database already holds for a trial (for resume)."""

    completed: bool = False
    series_done: frozenset[int] = frozenset()
    committed: dict[int, int] = field(default_factory=dict)  # j -> observations committed
    reference_deg: float | None = None


class Phase(Enum):
    COMMANDS = "waiting for the stand's acknowledgement"
    STILL = "confirming the stand is still"
    TRACKING = "confirming the stand rocks as commanded"
    SETTLE = "settling"
    PROMPT = "waiting for the operator"
    OBSERVE = "observing"
    DONE = "done"


@dataclass
class _Window:
    """Accumulators for one settle block or observation window."""

    start_ms: int
    end_ms: int
    total_ndeg: int = 0
    used: int = 0
    lost: int = 0
    low: int | None = None
    high: int | None = None
    anomalies: Counter[str] = field(default_factory=Counter)
    run_value: int | None = None  # the last reading (ndeg) and how many times in a row
    run_length: int = 0
    longest_run: int = 0
    repeats: int = 0  # consecutive readings equal to the one before

    def add(self, dev: np.ndarray, lost: int, invalid: int, jumps: int = 0) -> None:
        self.lost += lost
        if invalid:
            self.anomalies["invalid"] += invalid
        if jumps:
            self.anomalies["counter_jump"] += jumps
        if len(dev):
            self.total_ndeg += int(dev.sum())
            self.used += len(dev)
            lo, hi = int(dev.min()), int(dev.max())
            self.low = lo if self.low is None else min(self.low, lo)
            self.high = hi if self.high is None else max(self.high, hi)
            self._add_runs(dev)

    def _add_runs(self, dev: np.ndarray) -> None:
        """Longest run of identical consecutive readings, carried over the batches."""
        change = np.flatnonzero(dev[1:] != dev[:-1])  # run i ends at change[i]
        first = int(change[0]) + 1 if len(change) else len(dev)
        self.repeats += len(dev) - 1 - len(change)
        if int(dev[0]) == self.run_value:
            first += self.run_length
            self.repeats += 1
        longest = max(self.longest_run, first)
        if len(change):
            ends = np.append(change, len(dev) - 1)
            lengths = np.diff(ends)  # the runs after the first one
            longest = max(longest, int(lengths.max()))
            self.run_length = int(lengths[-1])
        else:
            self.run_length = first
        self.longest_run = longest
        self.run_value = int(dev[-1])

    def mean_ndeg(self) -> float:
        return self.total_ndeg / self.used if self.used else math.nan

    def flags(self) -> str:
        counts = dict(self.anomalies)
        if self.lost:
            counts["lost"] = self.lost
        return ",".join(f"{k}={v}" for k, v in sorted(counts.items()))


@dataclass(frozen=True)
class Snapshot:
    """Where the engine is, for the progress display."""

    trial: int
    n_trials: int
    j: int
    k: int
    n_obs: int
    phase: Phase
    now_ms: int
    values_deg: tuple[float, ...]
    settle_spread_deg: float | None
    remaining_ms: int


def _compass_fault(frame: CompassStatusFrame) -> str:
    """Why the compass's own status makes its readings unusable ("" when it does not)."""
    if not frame.rotor_running:
        return "compass reports its rotor stopped"
    if frame.fault_bits:
        names = [n for bit, n in enumerate(COMPASS_FAULTS) if frame.fault_bits >> bit & 1]
        return f"compass reports fault bits 0x{frame.fault_bits:02X} ({', '.join(names) or '?'})"
    return ""


def _is_bus_off(frame: InvalidFrame) -> bool:
    return frame.reason == "error frame" and bool(frame.arbitration_id & CAN_ERR_BUSOFF)


def _invalid_cause(reason: str) -> str:
    """Why a received frame was unusable, for the no-valid-heading message (the codec's reasons:
    "CRC mismatch: ...", "MESSAGE.SIGNAL = value outside [low, high]", others as they are)."""
    if "CRC" in reason:
        return "CRC mismatch"
    if " outside " in reason:
        return f"{reason.split(' = ')[0]} outside its range"
    return reason


QUIET = "no valid heading"  # event kind: no valid heading frame for the silence timeout


class Engine:
    """Drives one campaign plan through the trials still to do, from a stream of frame batches."""

    def __init__(
        self,
        plan: Plan,
        sink: Sink,
        commander: Commander,
        progress: dict[int, TrialState] | None = None,
        operator: Operator | None = None,
        source: SourceInfo = GYROSTAND,
        start_ms: int = 0,
    ) -> None:
        """`start_ms`: the stand clock where this run starts (a resumed campaign's stand clock
        goes on from its last stored time), until the stream says otherwise."""
        self.plan = plan
        self.source = source  # the heading source: its sequence rule and resolution
        self._modulo = source.sequence.modulo
        self._min_run = max(
            STUCK_MIN_RUN, math.ceil(STUCK_MIN_RUN * source.resolution_deg / STUCK_RESOLUTION_DEG)
        )
        # a window of identical readings fails the trial from 3 frames at the finest resolution;
        # a coarser one may hold still longer: from more than the longest run allowed
        self._min_identical = 3 if self._min_run == STUCK_MIN_RUN else self._min_run + 1
        self.operator = operator  # live runs: prompts before a trial (replay: none)
        self.sink = sink
        self.commander = commander
        # what the stand statuses' motion is measured by (a commander may say: `cia402_sim`)
        self.motion_source: str = getattr(commander, "motion_source", STAND_REPORT)
        self.progress = progress or {}
        self.todo = [t for t in plan.trials if not self.progress.get(t.index, _NONE).completed]
        self.outcome: Literal["running", "completed", "paused", "stopped"] = "running"
        self.phase = Phase.DONE
        self.now_ms = start_ms
        self._last_t: int | None = None  # stand time of the last heading frame
        self._last_counter: int | None = None
        self._last_pos: int | None = None  # its stream position
        # No valid heading frame for bus_silence_s of stand time fails the trial. Stand time is
        # known at every heading frame (valid or not), stand status and SIM_CLOCK tick; the
        # batch's valid heading frames are indexed once (`_quiet_index`).
        self._valid_ms: int | None = None  # last valid heading (or trial start) before the batch
        self._quiet_from = 0  # stream position from which unusable frames are counted
        self._quiet_carry: Counter[str] = Counter()  # ... those counted in earlier batches
        self._quiet_key: tuple[int, int] | None = None
        self._watch_key: tuple[int, int] | None = None  # `_watched`, for this batch and trial
        self._watch = np.zeros(0, dtype=np.int64)
        self._resets = 0
        self._batch_no = 0
        # gaps: the expected frame interval and the received-but-unusable frames in a gap
        self._spacings: list[float] = []
        self._interval: float | None = None
        self._late_ms = math.inf  # spacing over 1.5 intervals: a frame was due in between
        self._inv_pos = np.zeros(0, dtype=np.int64)  # this batch's unusable frames (positions)
        self._inv_cause: list[str] = []
        self._inv_carry = 0  # unusable frames after the last heading frame, earlier batches
        self._carry_from: int | None = None  # the last heading frame before this batch
        self._gap_events: list[tuple[int, str, int]] = []  # (position, message, stand ms)
        self._drops: list[tuple[int, DroppedFrames]] = []  # since the last valid heading frame
        self._stopped = False  # the stand acknowledged a stop since the last start
        self._trial: TrialPlan | None = None
        self._ref: float | None = None
        self._j = 1
        self._k = 1
        self._values: list[float] = []
        self._pending: list[Command] = []
        self._sent = False  # the pending command has been seen in the stream
        self._bad_key: tuple[object, ...] | None = None
        self._bad = np.zeros(0, dtype=np.int64)
        self._then = Phase.DONE
        self._phase_start_ms = 0
        self._window: _Window | None = None
        self._blocks: list[tuple[int, int, float]] = []  # (start ms, end ms, mean dev ndeg)
        self._stuck_blocks: set[int] = set()  # start ms of the series' stuck settle blocks
        self._repeat_rate = {1: [0, 0], 2: [0, 0]}  # per j: [readings repeated, pairs seen]
        self._coarse_told = False
        self._settle_start: int | None = None
        self._early: EarlySettle | None = None  # settle.method = "estimate" / "compensated"
        self._late_compensations: list[tuple[tuple[int, int], SeriesCompensation]] = []
        self._record = TransientRecord()  # window means and equilibrium steps of this run
        self._identified: Identified | None = None  # the record's period, damping (`identify`)
        self._contradiction_told = False
        self._step_ms: int | None = None  # the last start/stop that took effect (this run)
        self._windows: list[tuple[int, int]] = []  # the series' observation windows (ms)
        self._series_errors = 0
        self._motion = MotionRecorder(plan, self.motion_source)  # the rocking series' motion
        self._measured: Measured | None = None
        self._last_status_text = ""
        self._settle_durations: list[int] = []
        self._next_trial()
        self.sink.flush()

    # --------------------------------------------------------------------------- trial sequence
    def _next_trial(self) -> None:
        if not self.todo:
            self.phase = Phase.DONE
            if self.outcome == "running":
                self.outcome = "completed"
            return
        self._trial = self.todo.pop(0)
        if self.operator is not None and self.plan.prompts_before(self._trial.index):
            self.phase = Phase.PROMPT  # asked by `feed`, at this point of the stream
            return
        self._start_trial()

    def _ask(self) -> None:
        """The prompts before the next trial: the engine (and, in virtual time, the stand clock:
        nothing is granted meanwhile) waits for the answers at this point of the stream."""
        assert self.operator is not None and self._trial is not None
        self.sink.flush()
        stopped = self.operator.before_trial(self._trial.index)
        if stopped is None:
            self._start_trial()
        else:
            self.interrupt(stopped)

    def _start_trial(self) -> None:
        assert self._trial is not None
        self._quiet_reset()
        done = self.progress.get(self._trial.index, _NONE)
        self._ref = done.reference_deg
        self._motion.reset()
        self._measured = None
        self.sink.trial_started(self._trial.index)
        self._j = 2 if 1 in done.series_done else 1
        self._k = done.committed.get(self._j, 0) + 1
        self._values = []
        self._windows = []
        commands: list[Command] = [] if self._stopped else [Command("stop")]
        if self._j == 1:
            self._send(commands, Phase.STILL)
        else:
            self._send(commands + self._rocking_commands(), Phase.TRACKING)

    def _rocking_commands(self) -> list[Command]:
        t = self._trial
        assert t is not None
        return [Command("set", t.direction_deg, t.amplitude_cm, t.period_s), Command("start")]

    def _send(self, commands: list[Command], then: Phase) -> None:
        self._pending = list(commands)
        self._then = then
        self._enter(Phase.COMMANDS if commands else then)
        if commands:
            self._issue_next()

    def _issue_next(self) -> None:
        """Send the next pending command. Its ack is awaited only after the command itself shows
        up in the stream (the frames before it were on their way before it was sent), and the
        ack timeout runs in stand time from there."""
        command = self._pending[0]
        if command.kind != "stop":
            self._stopped = False
        self._sent = False
        self._phase_start_ms = self.now_ms  # (until it shows up in the stream)
        self.sink.event("command", "info", command.describe(), self._tidx, None, self.now_ms)
        self.sink.flush()  # write-ahead: a command's event is stored before the stand gets it
        try:
            self.commander.issue(command, self.now_ms)
        except CommandNotSent as exc:
            self.fail(f"could not send '{command.kind}': {exc}", kind="bus error")

    def _enter(self, phase: Phase) -> None:
        self.phase = phase
        self._phase_start_ms = self.now_ms
        if phase is Phase.SETTLE:
            self._settle_start = None
            self._blocks = []
            self._stuck_blocks = set()
            self._window = None
            self._series_errors = 0
            self._early = None

    @property
    def _tidx(self) -> int | None:
        return None if self._trial is None else self._trial.index

    def _window_ms(self) -> int:
        assert self._trial is not None
        period = self._trial.period_s if self._j == 2 else None
        return self.plan.observation.window_ms(period)

    # ----------------------------------------------------------------------------------- input
    def feed(self, batch: FrameBatch) -> None:
        """Consume one batch of frames in stream order."""
        self._h, self._s, self._o = batch.headings, batch.statuses, batch.others
        self._hi = self._si = self._oi = 0
        self._end = batch.end
        if self.phase is Phase.DONE:
            return
        self._batch_no += 1
        self._batch_started()
        try:
            while self.phase is not Phase.DONE:
                if self.phase is Phase.PROMPT:
                    self._ask()
                elif not self._left():
                    break
                elif self.phase in (Phase.SETTLE, Phase.OBSERVE):
                    self._bulk()
                else:
                    self._step()
        finally:
            self.sink.flush()
        self._batch_ended()

    def _left(self) -> bool:
        """Frames of the batch not taken in yet."""
        return self._hi < len(self._h) or self._si < len(self._s) or self._oi < len(self._o)

    def _batch_started(self) -> None:
        """Index the batch's unusable frames; start the stand-time count at the first frame
        that carries a stand time when none has been seen yet."""
        inv_pos, causes = [], []
        first_clock: tuple[int, int] | None = None
        for pos, frame in self._o:
            if isinstance(frame, InvalidFrame) and frame.reason != "error frame":
                inv_pos.append(pos)
                causes.append(_invalid_cause(frame.reason))
            elif first_clock is None and isinstance(frame, ClockFrame):
                first_clock = (pos, frame.stand_time_ms)
        self._inv_pos = np.array(inv_pos, dtype=np.int64)
        self._inv_cause = causes
        self._carry_from = self._last_pos
        if self._valid_ms is None:
            timed = [first_clock] if first_clock is not None else []
            for a in (self._h, self._s):
                if len(a):
                    timed.append((int(a.pos[0]), int(a.t_ms[0])))
            if timed:  # the first stand time known: nothing waited before it
                self._valid_ms = min(timed)[1]
                self.now_ms = max(self.now_ms, self._valid_ms)
                self._phase_start_ms = max(self._phase_start_ms, self._valid_ms)

    def _batch_ended(self) -> None:
        """Carry the stand-time count and the unusable frames over to the next batch."""
        consumed = self.consumed
        if self._valid_ms is not None:
            self._valid_ms = self._valid_before(consumed)
        self._quiet_from, self._quiet_carry = self._quiet_counts(consumed)
        after = self._inv_pos[: int(np.searchsorted(self._inv_pos, consumed))]
        if self._last_pos is not None:
            after = after[after > self._last_pos]
        kept = self._inv_carry if self._last_pos == self._carry_from else 0
        self._inv_carry = kept + len(after)
        self._gap_events = []
        if self._drops:  # those before a valid heading frame made no silence
            since = self._valid_pos_before(consumed)
            self._drops = [d for d in self._drops if d[0] > since]

    def frames_dropped(self, pos: int, dropped: DroppedFrames) -> None:
        """The acquisition dropped frames, its queue full, just before stream position `pos`
        (told before the batch holding `pos` is fed): a silence they make fails the trial as
        the queue overflow it is, not as bus silence."""
        self._drops.append((pos, dropped))

    @property
    def consumed(self) -> int:
        """Stream position after the last frame the engine has taken in (where it stopped when
        it finished inside a batch)."""
        nxt = [self._end]
        if self._hi < len(self._h):
            nxt.append(int(self._h.pos[self._hi]))
        if self._si < len(self._s):
            nxt.append(int(self._s.pos[self._si]))
        if self._oi < len(self._o):
            nxt.append(self._o[self._oi][0])
        return min(nxt)

    def fail(self, reason: str, kind: str = "fault", *, last: bool = False) -> None:
        """A fatal problem for the current trial (also called by the live driver). `last`:
        nothing can go on (a stand that stopped answering): the campaign pauses, a trial under
        way or not, whatever the plan's `on_trial_failure`."""
        if self.phase is Phase.DONE:
            return
        if self._trial is None:
            if last:
                self.sink.event(kind, "error", reason, self._tidx, None, self.now_ms)
                self._pause()
        else:
            j = self._j if self.phase in (Phase.SETTLE, Phase.OBSERVE) else None
            self.sink.event(kind, "error", reason, self._tidx, j, self.now_ms)
            self.sink.trial_failed(self._trial.index, j, reason)
            self._record.forget(self._trial.index)  # a retry is another attempt, another run
            self._stopped = False
            self._trial = None
            if last or self.plan.on_trial_failure == "pause":
                self._pause()
            else:
                self._next_trial()
        self.sink.flush()

    def _pause(self) -> None:
        self.outcome = "paused"
        self.todo = []
        self._stop_stand()
        self.phase = Phase.DONE

    def _stop_stand(self) -> None:
        """Best effort on the way out: nothing waits for this ack."""
        self.sink.event("command", "info", "stop", self._tidx, None, self.now_ms)
        self.sink.flush()
        try:
            self.commander.issue(Command("stop"), self.now_ms)
        except CommandNotSent as exc:
            self.sink.event("command", "error", f"could not send 'stop': {exc}", self._tidx)

    def interrupt(self, reason: str) -> None:
        """Stop where we are (operator or signal): the stand is told to stop rocking."""
        if self.phase is not Phase.DONE:
            self.sink.event("interrupted", "warning", reason, self._tidx, None, self.now_ms)
            self._stop_stand()
            self.outcome = "stopped"
            self.phase = Phase.DONE
            self.sink.flush()

    # ------------------------------------------------------------ one frame at a time (waiting)
    def _step(self) -> None:
        """Consume the next frame in stream order while waiting for an ack or a status."""
        candidates = []
        if self._hi < len(self._h):
            candidates.append((int(self._h.pos[self._hi]), 0))
        if self._si < len(self._s):
            candidates.append((int(self._s.pos[self._si]), 1))
        if self._oi < len(self._o):
            candidates.append((self._o[self._oi][0], 2))
        _, which = min(candidates)
        if which == 0:
            i = self._hi
            self._hi += 1
            if not self._heading_clock(i):
                return
            if self._ref is None and self._h.valid[i]:
                self._ref = float(self._h.heading_deg[i])
        elif which == 1:
            i = self._si
            self._si += 1
            t = int(self._s.t_ms[i])
            self.now_ms = max(self.now_ms, t)
            if self._is_quiet(int(self._s.pos[i])):
                self._fail_quiet(int(self._s.pos[i]), t)
                return
            self._on_status(self._s, i)
        else:
            pos, frame = self._o[self._oi]
            self._oi += 1
            self._on_other(pos, frame)
        if self.phase in (Phase.COMMANDS, Phase.STILL, Phase.TRACKING):
            self._check_wait_timeout()

    def _heading_clock(self, i: int) -> bool:
        """Advance the stand clock with heading frame i (waiting phases); False when it failed
        the trial (no valid heading frame for the silence timeout)."""
        h = self._h
        pos, t, counter = int(h.pos[i]), int(h.t_ms[i]), int(h.counter[i])
        self.now_ms = max(self.now_ms, t)
        if self._is_quiet(pos):
            self._note_heading(pos, t, counter)
            self._fail_quiet(pos, t)
            return False
        if self._last_t is not None and self._last_pos is not None:
            dt, prev_c = t - self._last_t, int(self._last_counter or 0)
            timed = self._interval is not None
            step = int(self._steps(np.array([prev_c]), np.array([counter]))[0])
            if not timed:
                self._learn_interval(np.array([dt]), np.array([step]))
            if step != 1 or (timed and self._late(dt)):
                prev = (self._last_pos, self._last_t, prev_c)
                self._gap(prev, (pos, t, counter), timed)  # no window to count in: events only
                self._tell_gaps(pos + 1)
        self._note_heading(pos, t, counter)
        return True

    def _steps(self, prev: np.ndarray, now: np.ndarray) -> np.ndarray:
        """Sequence-number steps from `prev` to `now` (modulo the source's rule), 1 where either
        has no number (then only time tells a gap)."""
        if self._modulo is None:
            return np.ones(len(now), dtype=np.int64)
        step = (now - prev) % self._modulo
        return np.where((prev < 0) | (now < 0), 1, step)

    def _numbered(self, prev_c: int, c: int) -> bool:
        return self._modulo is not None and prev_c >= 0 and c >= 0

    def _note_heading(self, pos: int, t: int, counter: int) -> None:
        self._last_pos, self._last_t, self._last_counter = pos, t, counter

    @property
    def _silence_ms(self) -> int:
        return round(self.plan.timeouts.bus_silence_s * 1000)

    # ------------------------------------------------------- no valid heading frame (liveness)
    def _quiet_index(self) -> np.ndarray:
        """Stream positions of this batch's heading frames and stand statuses at which no valid
        heading frame has come for longer than the silence timeout (once per batch and trial)."""
        key = (self._batch_no, self._resets)
        if self._quiet_key == key:
            return self._quiet
        self._quiet_key = key
        h, s = self._h, self._s
        valid = h.valid
        self._vpos = h.pos[valid]
        self._vrun = np.maximum.accumulate(h.t_ms[valid]) if len(self._vpos) else self._vpos
        self._flagged = np.concatenate(([0], np.cumsum(~valid)))  # VALID cleared, running
        if self._valid_ms is None:
            self._quiet = np.zeros(0, dtype=np.int64)
            return self._quiet
        before = np.cumsum(valid) - valid  # valid heading frames before each one
        quiet = h.t_ms - self._last_valid(before) > self._silence_ms
        before_s = np.searchsorted(self._vpos, s.pos)
        quiet_s = s.t_ms - self._last_valid(before_s) > self._silence_ms
        self._quiet = np.union1d(h.pos[quiet], s.pos[quiet_s])
        return self._quiet

    def _last_valid(self, before: np.ndarray) -> np.ndarray:
        """Stand time of the last valid heading frame, given how many of the batch's come
        before."""
        assert self._valid_ms is not None
        last = np.full(len(before), self._valid_ms, dtype=np.int64)
        some = before > 0
        last[some] = np.maximum(self._valid_ms, self._vrun[before[some] - 1])
        return last

    def _valid_before(self, pos: int) -> int:
        """Stand time of the last valid heading frame before stream position `pos`."""
        self._quiet_index()
        assert self._valid_ms is not None
        k = int(np.searchsorted(self._vpos, pos))
        return max(self._valid_ms, int(self._vrun[k - 1])) if k else self._valid_ms

    def _next_quiet(self) -> int:
        """Position of the next frame revealing the timeout (the batch end when none)."""
        quiet = self._quiet_index()
        i = int(np.searchsorted(quiet, self.consumed))
        return int(quiet[i]) if i < len(quiet) else self._end

    def _valid_pos_before(self, pos: int) -> int:
        """Stream position of this batch's last valid heading frame before `pos` (-1: none)."""
        self._quiet_index()
        k = int(np.searchsorted(self._vpos, pos))
        return int(self._vpos[k - 1]) if k else -1

    def _is_quiet(self, pos: int) -> bool:
        quiet = self._quiet_index()
        i = int(np.searchsorted(quiet, pos))
        return i < len(quiet) and int(quiet[i]) == pos

    def _quiet_counts(self, stop: int) -> tuple[int, Counter[str]]:
        """Unusable frames since the last valid heading frame (or the trial start), up to stream
        position `stop`: (position counted from, count per cause)."""
        self._quiet_index()
        k = int(np.searchsorted(self._vpos, stop))
        if k and int(self._vpos[k - 1]) >= self._quiet_from:
            start, counts = int(self._vpos[k - 1]) + 1, Counter()
        else:
            start, counts = self._quiet_from, Counter(self._quiet_carry)
        h = self._h
        a, b = np.searchsorted(h.pos, (start, stop))
        if self._flagged[b] - self._flagged[a]:
            counts["VALID flag cleared"] += int(self._flagged[b] - self._flagged[a])
        a, b = np.searchsorted(self._inv_pos, (start, stop))
        counts.update(self._inv_cause[a:b])
        return start, counts

    def _quiet_reset(self) -> None:
        """A trial starts: it gets the whole timeout from now."""
        if self._valid_ms is None:
            return
        self._valid_ms = self.now_ms
        self._quiet_from, self._quiet_carry = self.consumed, Counter()
        self._resets += 1

    def _fail_quiet(self, pos: int, t_ms: int) -> None:
        """No valid heading frame for longer than the timeout, seen at the frame at `pos` (stand
        time t_ms): bus silence when nothing came at all, else what the frames that came had."""
        since = self._valid_before(pos)
        _, counts = self._quiet_counts(pos + 1)
        waited = f"{(t_ms - since) / 1000:g} s of stand time"
        after = self._valid_pos_before(pos)
        dropped = sum(d.frames for p, d in self._drops if after < p <= pos)
        if dropped:
            self.fail(
                f"the acquisition's queue overflowed: {dropped} frames dropped (no valid heading "
                f"frame for {waited})",
                kind="queue overflow",
            )
            return
        if not counts:
            silence = self.source.silence
            self.fail(f"{silence}: no heading frame for {waited}", kind="bus silence")
            return
        n = sum(counts.values())
        causes = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
        detail = causes[0][0] if len(causes) == 1 else ", ".join(f"{v} {k}" for k, v in causes)
        self.fail(
            f"no valid heading frame for {waited} ({n} of {n} frames invalid: {detail})",
            kind=QUIET,
        )

    def _on_clock(self, pos: int, t_ms: int) -> None:
        """A SIM_CLOCK tick (virtual time): the clock moves on, also while the stand is silent."""
        self.now_ms = max(self.now_ms, t_ms)
        if self._valid_ms is not None and t_ms - self._valid_before(pos) > self._silence_ms:
            self._fail_quiet(pos, t_ms)

    def _check_wait_timeout(self) -> None:
        waited_s = (self.now_ms - self._phase_start_ms) / 1000
        if self.phase is Phase.COMMANDS:
            if not self._sent:  # the frames before it were on their way: a generous limit
                limit = self.plan.settle.max_wait_s
                if waited_s > limit:
                    self.fail(
                        f"command '{self._pending[0].kind}' not seen in the stream within "
                        f"{limit:g} s of stand time",
                        kind="command not seen",
                    )
                return
            limit = self.plan.timeouts.ack_s * self.plan.bus.speedup
            if waited_s > limit:
                self.fail(
                    f"stand did not acknowledge '{self._pending[0].kind}' within "
                    f"{limit:g} s of stand time",
                    kind="no ack",
                )
        elif waited_s > self.plan.tracking.confirm_s:
            what = "still" if self.phase is Phase.STILL else "rocking as commanded"
            detail = f" (last status: {self._last_status_text})" if self._last_status_text else ""
            self.fail(
                f"stand not {what} within {self.plan.tracking.confirm_s:g} s{detail}",
                kind="mis-tracking",
            )

    def _on_other(self, pos: int, frame: Frame | DeviceEvent | RollSample) -> None:
        if isinstance(frame, RollSample):
            self._on_roll(frame)
        elif isinstance(frame, DeviceEvent):
            j = self._j if self.phase in (Phase.SETTLE, Phase.OBSERVE) else None
            self.sink.event(frame.kind, frame.severity, frame.message, self._tidx, j, self.now_ms)
        elif isinstance(frame, CommandFrame):
            if self.phase is Phase.COMMANDS and not self._sent and self._awaits(frame):
                self._sent = True
                self._phase_start_ms = self.now_ms
            else:
                self._foreign_command(frame)
        elif isinstance(frame, AckFrame):
            self._on_ack(frame)
        elif isinstance(frame, ClockFrame):
            self._on_clock(pos, frame.stand_time_ms)
        elif isinstance(frame, CompassStatusFrame) and _compass_fault(frame):
            self.fail(_compass_fault(frame), kind="compass fault")
        elif isinstance(frame, InvalidFrame) and _is_bus_off(frame):
            self.fail("bus-off reported by the CAN controller", kind="bus-off")

    def _awaits(self, frame: CommandFrame) -> bool:
        """Is this the command the engine has just sent (a set with the same K, A, tau)?"""
        command = self._pending[0]
        if frame.command != command.kind:
            return False
        if command.kind != "set":
            return True
        return (
            abs(frame.direction_deg - command.direction_deg) < 0.01
            and abs(frame.amplitude_cm - command.amplitude_cm) < 0.01
            and abs(frame.period_s - command.period_s) < 0.002
        )

    def _foreign_command(self, frame: CommandFrame) -> None:
        """A stand command this campaign did not send now: another controller on the bus, or
        (replay) a log recorded with another plan."""
        self.sink.event(
            "foreign command",
            "warning",
            f"stand command '{frame.command}' on the bus not sent by this campaign at this point"
            " (another controller, or a log recorded with another plan)",
            self._tidx,
            None,
            self.now_ms,
        )

    def _on_ack(self, ack: AckFrame) -> None:
        if self.phase is not Phase.COMMANDS or not self._sent:
            return
        if ack.command != self._pending[0].kind:
            return
        if not ack.accepted:
            self.fail(f"stand refused '{ack.command}': {ack.reason}", kind="stand refusal")
            return
        command = self._pending.pop(0)
        if command.kind == "stop":
            self._stopped = True
        if command.kind in ("start", "stop"):  # the compass's equilibrium may move now
            self._step_ms = ack.stand_time_ms
            self._record.step(ack.stand_time_ms / 1000)
        if self._pending:
            self._issue_next()
        elif self._then is Phase.DONE:
            self._trial_completed()
        else:
            self._enter(self._then)

    def _on_status(self, s: Statuses, i: int) -> None:
        frame = s.frame(i)
        self._last_status_text = (
            f"{'rocking' if frame.rocking else 'still'}, K={frame.direction_deg:g} deg, "
            f"A={frame.amplitude_cm:g} cm, tau={frame.period_s:g} s"
        )
        if self.phase in (Phase.STILL, Phase.TRACKING) and self._tracking_problem(s, i) is None:
            self._enter(Phase.SETTLE)

    def _tracking_bad(self, s: Statuses) -> np.ndarray:
        """`_tracking_problem(...) is not None` for every status at once."""
        t = self._trial
        assert t is not None
        if self._j == 1 or self.phase is Phase.STILL:
            return s.rocking.copy()
        tol = self.plan.tracking
        direction = np.abs(wrap180(s.direction_deg - t.direction_deg))
        return (
            ~s.rocking
            | (np.abs(s.amplitude_cm - t.amplitude_cm) > tol.amplitude_rel * t.amplitude_cm)
            | (np.abs(s.period_s - t.period_s) > tol.period_rel * t.period_s)
            | (direction > tol.direction_deg)
        )

    def _tracking_problem(self, s: Statuses, i: int) -> str | None:
        """Why status i does not match what the current series needs (None when it does)."""
        t = self._trial
        assert t is not None
        rocking = bool(s.rocking[i])
        if self._j == 1 or self.phase is Phase.STILL:
            return "stand rocking during a still series" if rocking else None
        if not rocking:
            return "stand stopped rocking"
        tol = self.plan.tracking
        amplitude, period = float(s.amplitude_cm[i]), float(s.period_s[i])
        direction = float(s.direction_deg[i])
        if abs(amplitude - t.amplitude_cm) > tol.amplitude_rel * t.amplitude_cm:
            return f"amplitude {amplitude:g} cm, commanded {t.amplitude_cm:g} cm"
        if abs(period - t.period_s) > tol.period_rel * t.period_s:
            return f"period {period:g} s, commanded {t.period_s:g} s"
        if abs(wrap180(direction - t.direction_deg)) > tol.direction_deg:
            return f"direction {direction:g} deg, commanded {t.direction_deg:g} deg"
        return None

    # ------------------------------------------------------------ bulk (settling and observing)
    def _bulk(self) -> None:
        fatal_pos, fatal_reason, fatal_kind = self._first_fatal()
        h = self._h
        stop = self._hi + int(np.searchsorted(h.pos[self._hi :], fatal_pos))
        seg = h.take(slice(self._hi, stop))
        consumed, transition = self._consume(seg)
        self._hi += consumed
        self._account(int(h.pos[self._hi]) if transition else fatal_pos)
        if transition:
            self._close_window()
        elif fatal_kind == QUIET:
            self._quiet_at(fatal_pos)
        elif fatal_reason is not None:
            self._skip_to(fatal_pos + 1)
            self.fail(fatal_reason, kind=fatal_kind)

    def _quiet_at(self, pos: int) -> None:
        """Take in the frame at `pos` (a heading frame, stand status or SIM_CLOCK tick that
        reveals the timeout) and fail the trial."""
        h, s = self._h, self._s
        if self._hi < len(h) and int(h.pos[self._hi]) == pos:
            i = self._hi
            t = int(h.t_ms[i])
            self._note_heading(pos, t, int(h.counter[i]))
        elif self._si < len(s) and int(s.pos[self._si]) == pos:
            t = int(s.t_ms[self._si])
        else:
            frame = self._o[self._oi][1]
            assert isinstance(frame, ClockFrame)
            t = frame.stand_time_ms
        self._skip_to(pos + 1)
        self.now_ms = max(self.now_ms, t)
        self._fail_quiet(pos, t)

    def _first_fatal(self) -> tuple[int, str | None, str]:
        """Position and reason of the first status or frame that ends this series (for a
        missing valid heading frame, kind QUIET: its reason is told by `_fail_quiet`)."""
        best: tuple[int, str | None, str] = (self._end, None, "")
        s = self._s
        key = (id(s), self._tidx, self._j, self.phase is Phase.STILL)
        if self._bad_key != key:  # once per batch and series, not per window
            self._bad_key, self._bad = key, np.flatnonzero(self._tracking_bad(s))
        bad = self._bad[np.searchsorted(self._bad, self._si) :]
        if len(bad):
            i = int(bad[0])
            best = (int(s.pos[i]), f"mis-tracking: {self._tracking_problem(s, i)}", "mis-tracking")
        quiet = self._next_quiet()
        if quiet < best[0]:
            best = (quiet, None, QUIET)
        errors = self._series_errors
        watched = self._watched()
        for k in watched[int(np.searchsorted(watched, self._oi)) :].tolist():
            pos, frame = self._o[k]
            if pos >= best[0]:
                break
            if isinstance(frame, ClockFrame):  # (only those revealing the timeout are watched)
                return pos, None, QUIET
            if isinstance(frame, CompassStatusFrame) and _compass_fault(frame):
                return pos, _compass_fault(frame), "compass fault"
            if isinstance(frame, InvalidFrame) and frame.reason == "error frame":
                if _is_bus_off(frame):
                    return pos, "bus-off reported by the CAN controller", "bus-off"
                errors += 1
                if errors > self.plan.checks.max_error_frames:
                    limit = self.plan.checks.max_error_frames
                    return pos, f"more than {limit} error frames in one series", "error frames"
        return best

    def _watched(self) -> np.ndarray:
        """Indices of the batch's other frames that may end a series (`_first_fatal`): SIM_CLOCK
        ticks revealing the silence timeout, faulty compass statuses, error frames. Once per
        batch and trial (as `_quiet_index`): `_first_fatal` runs once per window or step, and
        the batch's ticks, one per stand second, are nearly all fine."""
        key = (self._batch_no, self._resets)
        if self._watch_key == key:
            return self._watch
        self._quiet_index()
        clocks: list[tuple[int, int, int]] = []  # (index, position, stand ms)
        watched: list[int] = []
        for k, (pos, frame) in enumerate(self._o):
            if isinstance(frame, ClockFrame):
                clocks.append((k, pos, frame.stand_time_ms))
            elif (isinstance(frame, CompassStatusFrame) and _compass_fault(frame)) or (
                isinstance(frame, InvalidFrame) and frame.reason == "error frame"
            ):
                watched.append(k)
        if clocks and self._valid_ms is not None:  # as `_valid_before` at each tick
            index, pos, t_ms = np.array(clocks, dtype=np.int64).T
            since = self._last_valid(np.searchsorted(self._vpos, pos))
            watched += index[t_ms - since > self._silence_ms].tolist()
        self._watch_key, self._watch = key, np.array(sorted(watched), dtype=np.int64)
        return self._watch

    def _skip_to(self, pos: int) -> None:
        self._hi += int(np.searchsorted(self._h.pos[self._hi :], pos))
        self._si += int(np.searchsorted(self._s.pos[self._si :], pos))
        while self._oi < len(self._o) and self._o[self._oi][0] < pos:
            self._oi += 1

    def _account(self, limit: int) -> None:
        """Attribute statuses and other frames before stream position `limit` to the window;
        tell the gaps found meanwhile, in stream order."""
        s = self._s
        stop = self._si + int(np.searchsorted(s.pos[self._si :], limit))
        if self._j == 2 and self.phase is Phase.OBSERVE:
            self._motion.reports(s, self._si, stop)
        if stop > self._si:
            self.now_ms = max(self.now_ms, int(s.t_ms[stop - 1]))
        self._si = stop
        while self._oi < len(self._o) and self._o[self._oi][0] < limit:
            pos, frame = self._o[self._oi]
            self._oi += 1
            if self._gap_events:
                self._tell_gaps(pos)
            if type(frame) is ClockFrame:  # most of them (one a stand second): only the clock
                self.now_ms = max(self.now_ms, frame.stand_time_ms)
                continue
            if isinstance(frame, CommandFrame):
                self._foreign_command(frame)
            if isinstance(frame, DeviceEvent | RollSample):
                self._on_other(pos, frame)
            if isinstance(frame, InvalidFrame) and frame.reason == "error frame":
                self._series_errors += 1
            if isinstance(frame, InvalidFrame) and self._window is not None:
                if frame.reason == "error frame":
                    self._window.anomalies["error_frame"] += 1
                elif "CRC" in frame.reason:
                    self._window.anomalies["corrupt"] += 1
                elif "outside" in frame.reason:
                    self._window.anomalies["out_of_range"] += 1
                elif "not available" in frame.reason:
                    self._window.anomalies["not_available"] += 1
                else:
                    self._window.anomalies["invalid_frame"] += 1
        if self._gap_events:
            self._tell_gaps(limit)

    def _consume(self, seg: Headings) -> tuple[int, bool]:
        """Accumulate heading frames into the current block/window up to the first one that
        closes it. Returns (frames consumed, window closed). Work is bounded by the window, not
        by the rest of the batch."""
        n = len(seg)
        if n == 0:
            return 0, False
        t = seg.t_ms
        if self._window is None:
            start = int(t[0])
            if self.phase is Phase.SETTLE:
                self._settle_start = start
                assert self._trial is not None
                self.sink.series_settling(self._trial.index, self._j, start)
            self._window = _Window(start, start + self._window_ms())
        w = self._window
        guess = int(np.searchsorted(t, w.end_ms))  # exact when the stand clock only advances
        early = np.flatnonzero(t[:guess] >= w.end_ms)
        end = int(early[0]) if len(early) else guess
        if self._ref is None:
            valid_idx = np.flatnonzero(seg.valid[:end])
            if len(valid_idx):
                self._ref = float(seg.heading_deg[valid_idx[0]])
        if end:
            inside = t[:end] >= w.start_ms
            lost, jumps = self._gaps(seg, end, inside)
            valid = seg.valid[:end] & inside
            if self._ref is not None:
                dev = np.rint(wrap180(seg.heading_deg[:end][valid] - self._ref) * NANO)
                w.add(dev.astype(np.int64), lost, int((inside & ~valid).sum()), jumps)
            last = end - 1
            self._note_heading(int(seg.pos[last]), int(t[last]), int(seg.counter[last]))
            self.now_ms = max(self.now_ms, self._last_t)
        return end, end < n

    # ---------------------------------------------------------------------------------- gaps
    # A gap between two consecutive heading frames is judged from the stand time AND the 4-bit
    # counter: the counter alone cannot see 16, 32, ... missing frames, and a counter that skips
    # values while the stand time runs on has lost nothing. Frames received but unusable in
    # between (bad CRC, out of range: counted as such in the window) are not missing.

    def _learn_interval(self, dt: np.ndarray, step: np.ndarray) -> int:
        """The expected heading-frame interval, from the stream (the engine sees frames, not
        the DBC; on the shipped one GYRO_HEADING's GenMsgCycleTime is 100 ms, as the simulated
        stand sends): the median stand-time spacing per counter step of the first
        INTERVAL_SAMPLE pairs of consecutive heading frames with a positive spacing and a
        counter step of 1 to 15 (per step, so that dropped frames do not stretch it; the median,
        so that a few counter jumps do not shrink it). Takes pairs from `dt`, `step` in order
        while learning; returns how many of them come before the interval is known (those are
        judged by the counter alone)."""
        if self._interval is not None:
            return 0
        need = INTERVAL_SAMPLE - len(self._spacings)
        taken = np.flatnonzero((dt > 0) & (step > 0))[:need]
        self._spacings.extend(float(x) for x in dt[taken] / step[taken])
        if len(self._spacings) < INTERVAL_SAMPLE:
            return len(dt)
        self._interval = float(np.median(self._spacings))
        self._late_ms = 1.5 * self._interval  # a frame was due in between
        return int(taken[-1]) + 1 if len(taken) else 0

    def _late(self, dt: int) -> bool:
        return self._interval is not None and dt > self._late_ms

    def _gaps(self, seg: Headings, end: int, inside: np.ndarray) -> tuple[int, int]:
        """Missing frames and counter jumps before each of the first `end` frames of `seg`
        (those inside the window summed); gaps the counter under-reports are told as events."""
        t, counter = seg.t_ms[:end], seg.counter[:end]
        dt = t[1:] - t[:-1]  # before frame i + 1
        step = self._steps(counter[:-1], counter[1:])
        first = None if self._last_t is None else int(t[0]) - self._last_t  # before frame 0
        step0 = 0  # before frame 0
        if self._last_counter is not None and len(counter):
            step0 = int(self._steps(np.array([self._last_counter]), counter[:1])[0])
        learned = 0  # frames from here on are judged with the interval
        if self._interval is None:  # (a spacing of 0 is never taken: none before frame 0)
            learned = self._learn_interval(
                np.concatenate(([first or 0], dt)), np.concatenate(([step0], step))
            )
        odd = step != 1
        if self._interval is not None:
            late = dt > self._late_ms
            if learned > 1:
                late[: learned - 1] = False
            odd |= late
        at = (np.flatnonzero(odd) + 1).tolist()
        known = first is not None and self._last_pos is not None
        if (
            known
            and self._last_counter is not None
            and (step0 != 1 or (learned == 0 and self._late(first or 0)))
        ):
            at.insert(0, 0)
        lost = jumps = 0
        for i in at:
            if i:
                prev = (int(seg.pos[i - 1]), int(t[i - 1]), int(counter[i - 1]))
            else:
                assert self._last_pos is not None and self._last_t is not None
                prev = (self._last_pos, self._last_t, int(self._last_counter or 0))
            now = (int(seg.pos[i]), int(t[i]), int(counter[i]))
            missing, jump = self._gap(prev, now, timed=i >= learned)
            if inside[i]:
                lost += missing
                jumps += jump
        return lost, jumps

    def _gap(
        self, prev: tuple[int, int, int], now: tuple[int, int, int], timed: bool
    ) -> tuple[int, int]:
        """(frames missing, counter jumps) between two consecutive heading frames, each given
        as (stream position, stand time ms, counter). Missing = max(by the counter, by the
        stand time); a counter step with no time gap is a counter jump, nothing missing."""
        (prev_pos, prev_t, prev_c), (pos, t, c) = prev, now
        dt = t - prev_t
        if dt > self._silence_ms:  # a silence: the trial failed on it
            return 0, 0
        a, b = np.searchsorted(self._inv_pos, (prev_pos, pos))
        unusable = int(b - a) + (self._inv_carry if prev_pos == self._carry_from else 0)
        numbered = self._numbered(prev_c, c)
        modulo = self._modulo or 1
        counted = (c - prev_c - 1) % modulo if numbered else 0  # unusable frames included
        if not timed or self._interval is None:
            return counted - min(unusable, counted), 0
        slots = max(round(dt / self._interval) - 1, 0)  # frames due between the two
        unusable = min(unusable, slots)
        by_time = slots - unusable
        by_counter = (counted - unusable) % modulo if numbered else 0
        if by_time == 0:
            return 0, int(by_counter != 0)
        if numbered and by_time > by_counter and slots < modulo - 1:
            # the sequence cannot have wrapped within so few slots: it counts exactly, and the
            # frame came late (a source timed by reception: jitter), nothing is missing beyond it
            return by_counter, 0
        missing = max(by_counter, by_time)
        if by_time > by_counter:  # the counter cannot tell: never a silent gap
            sequence = self.source.sequence.description
            told = f"the {sequence} shows {by_counter}" if numbered else "no sequence number"
            self._gap_events.append(
                (
                    pos,
                    f"{missing} heading frames missing before stand time {t / 1000:g} s "
                    f"({dt / 1000:g} s after the previous one, expected every "
                    f"{self._interval:g} ms; {told})",
                    t,
                )
            )
        return missing, 0

    def _tell_gaps(self, limit: int) -> None:
        """The gap events of heading frames before stream position `limit`."""
        j = self._j if self.phase in (Phase.SETTLE, Phase.OBSERVE) else None
        while self._gap_events and self._gap_events[0][0] < limit:
            _, message, t = self._gap_events.pop(0)
            self.sink.event("frame gap", "warning", message, self._tidx, j, t)

    def _close_window(self) -> None:
        w = self._window
        assert w is not None and self._trial is not None
        if self.phase is Phase.SETTLE:
            self._close_settle_block(w)
        else:
            self._close_observation(w)

    def _close_settle_block(self, w: _Window) -> None:
        assert self._settle_start is not None and self._trial is not None
        self._blocks.append((w.start_ms, w.end_ms, w.mean_ndeg()))
        width = w.end_ms - w.start_ms
        settle = self.plan.settle
        need = hold_blocks(settle, width / 1000)
        limit = self._stuck_limit(w)
        if limit is not None:
            self._stuck_blocks.add(w.start_ms)
            where = f"settle block {w.start_ms / 1000:g}-{w.end_ms / 1000:g} s"
            self._tell_stuck(w, where, limit, "; the series does not settle on it")
        # a hold with a stuck block is no sign of settling: the series waits for one without
        stuck = self._stuck_blocks
        trusted = not stuck or not any(start in stuck for start, _, _ in self._blocks[-need:])
        estimate = self._estimate_plan()
        recent: list[float] = []
        band = False
        # the band criterion decides (method "band"), or is recorded until it first holds
        if estimate is None or self._early is None or self._early.band_s is None:
            recent = [m / NANO for _, _, m in self._blocks[-need:]]
            band = len(recent) == need and not any(math.isnan(m) for m in recent) and trusted
            band = band and band_settled(recent, settle)
        outcome: SettleOutcome | None = None
        waited_s = (w.end_ms - self._settle_start) / 1000
        if w.used and limit is None:  # (frames are used once the reference heading is known)
            assert self._ref is not None
            self._record.add(w.start_ms / 1000, w.end_ms / 1000, self._ref + w.mean_ndeg() / NANO)
        if estimate is None:
            if band:
                assert self._ref is not None
                outcome = SettleOutcome(
                    "band", waited_s, self._ref + sum(recent) / need, band_s=waited_s
                )
        elif w.used and limit is None:
            if self._early is None:
                estimate = self._identify(estimate, w.end_ms)
                spacing = round(self.plan.observation.spacing_s * 1000)
                self._early = EarlySettle(
                    estimate,
                    self._record,
                    self._settle_start,
                    width / 1000,
                    (width + spacing) / 1000,
                    self.plan.n_obs,
                )
            if self._early.check(w.end_ms, band).ready and trusted:
                outcome = self._early_settled(w)
        if outcome is not None:
            outcome = replace(outcome, step_ms=self._step_ms, blocks=self._settle_record())
            self._settle_durations.append(w.end_ms - self._settle_start)
            self.sink.series_settled(self._trial.index, self._j, w.end_ms, outcome)
            self._enter(Phase.OBSERVE)
            self._window = _Window(w.end_ms, w.end_ms + width)
            return
        if w.end_ms - self._settle_start > settle.max_wait_s * 1000:
            stuck = f" (stuck sensor in the last {need} settle blocks)" if not trusted else ""
            self.fail(
                f"not settled within {settle.max_wait_s:g} s{stuck or self._why_not()}",
                kind="settle timeout",
            )
            return
        next_start = w.end_ms
        if self._last_t is not None and self._last_t >= next_start + width:  # skip empty blocks
            next_start += (self._last_t - next_start) // width * width
        self._window = _Window(next_start, next_start + width)

    def _stuck_limit(self, w: _Window) -> int | None:
        """The run limit when window `w`'s longest run of identical readings is stuck (None:
        it is not, or cannot be told yet); the readings' repeat rate learns from `w`."""
        rate = self._repeat_rate[self._j]
        run = max(w.longest_run - 1, 0)  # its repeats, left out of the rate
        repeated, pairs = rate[0] + w.repeats - run, rate[1] + max(w.used - 1, 0) - run
        limit = None
        p = repeated / pairs if pairs >= STUCK_LEARN else None  # a reading repeats the last
        if p is not None and p <= STUCK_RESOLVED:
            limit = max(self._min_run, int(w.used * STUCK_FRACTION))
            if p > 0:  # n p^(L-1) < STUCK_CHANCE (geometric run lengths)
                limit = max(limit, 1 + math.ceil(math.log(STUCK_CHANCE / w.used) / math.log(p)))
            if w.longest_run <= limit:
                limit = None
        elif p is not None and not self._coarse_told:
            self._coarse_told = True
            self.sink.event(
                "stuck sensor",
                "info",
                f"runs of identical heading readings are not judged while {p:.0%} of the "
                "readings repeat the one before (the angle sensor's resolution is coarser than the "
                "compass's noise, so a still compass cannot be told from a stuck sensor)",
                self._tidx,
                self._j,
                w.end_ms,
            )
        rate[0], rate[1] = (repeated, pairs) if limit is not None else (repeated + run, pairs + run)
        return limit

    def _tell_stuck(self, w: _Window, where: str, limit: int, then: str = "") -> None:
        self.sink.event(
            "stuck sensor",
            "warning",
            f"{where}: {w.longest_run} identical heading readings in a row "
            f"({w.longest_run / w.used:.0%} of its {w.used} frames; flagged above {limit}){then}",
            self._tidx,
            self._j,
            w.end_ms,
        )

    def _settle_record(self) -> tuple[tuple[int, int, float], ...]:
        """The series' settle blocks as (start ms, end ms, mean heading deg), those with frames."""
        assert self._ref is not None
        return tuple(
            (start, end, self._ref + mean / NANO)
            for start, end, mean in self._blocks
            if not math.isnan(mean)
        )

    def _why_not(self) -> str:
        """What the transient-model rule last saw, for the settle timeout message."""
        check = None if self._early is None else self._early.last
        if check is None or check.settle_point_deg is None:
            return ""
        plan = check.plan
        return (
            f" (transient model: SE {check.standard_error_deg:.5f} deg, last estimates within "
            f"{check.spread_deg:.5f} deg, tolerance {plan.tolerance_deg:.5f} deg; transient "
            f"over the observations {check.transient_deg:.5f} deg, bound "
            f"{plan.transient_tolerance_deg:.5f} deg)"
        )

    def _estimate_plan(self) -> EstimatePlan | None:
        """The transient-model criterion with the period and damping in use: the record's
        once it contradicted the plan's (`identify`), else the plan's."""
        estimate = self.plan.settle.estimate
        if estimate is None or self._identified is None:
            return estimate
        return self._identified.applied(estimate)

    def _identify(self, estimate: EstimatePlan, end_ms: int) -> EstimatePlan:
        """As a series starts (and before a compensated one is compensated): the criterion
        with the record's period and damping when they contradict the plan's (told once in a
        "plan contradicted" warning event, while the campaign runs), the plan's when the record
        confirms them, and without compensation while the record cannot tell."""
        plan = self.plan.settle.estimate
        assert plan is not None
        found = identify(self._record, plan)
        if found is not None and found.contradicted and not self._contradiction_told:
            self._contradiction_told = True
            message = found.describe(plan)
            self.sink.event(PLAN_CONTRADICTED, "warning", message, self._tidx, self._j, end_ms)
        if found is not None:
            self._identified = found
        if self._identified is None:
            return replace(estimate, compensated=False)
        return self._identified.applied(plan)

    def _early_settled(self, w: _Window) -> SettleOutcome:
        """How an early-settle series settled (also told in an "early settle" event with the
        estimate and the time saved against the band criterion)."""
        assert self._early is not None and self._early.last is not None and self._ref is not None
        means = [m / NANO for _, _, m in self._blocks if not math.isnan(m)]
        outcome = self._early.outcome(self._ref, means, self.plan.settle)
        message = describe(outcome, self._early.last)
        self.sink.event("early settle", "info", message, self._tidx, self._j, w.end_ms)
        return outcome

    def _close_observation(self, w: _Window) -> None:
        trial = self._trial
        assert trial is not None and self._ref is not None
        if w.used == 0:
            self.fail(f"no valid heading frame in observation window {self._k}")
            return
        limit = self._stuck_limit(w)
        if limit is not None and w.used >= self._min_identical and w.low == w.high:
            w.anomalies["stuck"] += 1
            self.fail(
                f"stuck sensor: {w.used} identical readings in observation window {self._k}",
                kind="stuck sensor",
            )
            return
        if limit is not None:
            w.anomalies["stuck"] = w.longest_run
        value = self._ref + w.mean_ndeg() / NANO
        flags = w.flags()
        obs = ObservationResult(
            trial.index, self._j, self._k, value, w.start_ms, w.end_ms, w.used, w.lost, flags
        )
        self.sink.observation(obs)
        self._record.add(w.start_ms / 1000, w.end_ms / 1000, value)
        self._windows.append((w.start_ms, w.end_ms))
        if limit is not None:
            self._tell_stuck(w, f"observation {self._k}", limit)
        if flags:
            self.sink.event(
                "frame anomalies",
                "warning",
                f"observation {self._k}: {flags.replace(',', ', ')}",
                trial.index,
                self._j,
                w.end_ms,
            )
        self._values.append(value)
        self._k += 1
        if self._k <= self.plan.n_obs:
            start = w.end_ms + round(self.plan.observation.spacing_s * 1000)
            self._window = _Window(start, start + (w.end_ms - w.start_ms))
            return
        motion = self._series_motion(trial) if self._j == 2 else ()
        compensation = self._compensation()
        if compensation is None and self._windows:  # its mean covaries with later ones
            self._record.observed((trial.index, self._j), np.array(self._windows) / 1000)
        self.sink.series_completed(trial.index, self._j, compensation, motion)
        for (index, j), late in self._late_compensations:  # by this record's fit, later
            self.sink.series_compensated(index, j, late)
        self._late_compensations = []
        applied = preferred(motion)
        problem = self._motion.tracking_problem(trial, applied)
        if problem is not None:
            self.fail(problem, kind="mis-tracking")
            return
        self._window = None
        self._windows = []
        if self._j == 1:
            self._j, self._k, self._values = 2, 1, []
            self._send(self._rocking_commands(), Phase.TRACKING)
        else:
            self._send([Command("stop")], Phase.DONE)

    def _on_roll(self, sample: RollSample) -> None:
        """A measuring source's roll sample: kept while the rocking series is observed."""
        if self._j == 2 and self.phase is Phase.OBSERVE:
            self._motion.sample(sample)

    def _series_motion(self, trial: TrialPlan) -> tuple[MeasuredMotion, ...]:
        """The rocking series' measured motion per source (and what the trial applies)."""
        found = self._motion.series(trial)
        for note in found.notes:
            self.sink.event("measured motion", "warning", note, trial.index, 2, self.now_ms)
        applied = preferred(found.motions)
        if applied is not None:
            reported = next((m for m in found.motions if m.direction_deg is not None), None)
            direction = None if reported is None else reported.direction_deg
            self._measured = Measured(
                direction, applied.amplitude_cm, applied.period_s, applied.source
            )
        return found.motions

    def _compensation(self) -> SeriesCompensation | None:
        """Compensated series: the fitted transient over each observation window of this run
        (the fit now includes the observations themselves). None otherwise, or when the record
        cannot be fitted (the analysis then says the series is not compensated)."""
        estimate = self._estimate_plan()
        if estimate is None or not estimate.compensated or not self._windows:
            return None
        if self._early is None or self._early.last is None or not self._early.last.compensates:
            return None  # settled by the bound (a free state) or resumed mid-series
        estimate = self._identify(estimate, self.now_ms)  # the record now has the observations
        # the period and damping the whole record gives now, their uncertainty in the SE (issue
        # 34): held at the plan's, a damping 0.05 off that the record did not yet contradict at
        # 3 SE, or at an earlier record's estimate, they biased the compensation by 1-4 SE
        fitted = self._record.fit(estimate.model, free=True)
        if fitted is None:
            return None
        fit, j = fitted
        ms = np.array(self._windows, dtype=float)
        t_s, width_s = ms.mean(axis=1) / 1000, (ms[:, 1] - ms[:, 0]) / 1000
        values, _ = fit.transient(j, t_s, width_s)
        first_k = self.plan.n_obs - len(self._windows) + 1
        tau_k = self.plan.observation.correlation_time_s  # the reading's (None: not stated)
        own, lates = self._record.late_compensations(fit, t_s, width_s, self.plan.n_obs, tau_k)
        d_period, d_ratio, previous = own
        assert fit.pd_covariance is not None
        shared = SharedError(
            (-d_period, -d_ratio),  # the compensated mean is the observations' less the transient
            tuple(tuple(float(v) for v in row) for row in fit.pd_covariance),  # type: ignore[arg-type]
            round(self._record.start_s * 1000),
            self.now_ms,
            previous,
            self._record.earlier_covariances(fit, t_s, width_s, self.plan.n_obs, tau_k),
        )
        values_deg = tuple(float(v) for v in values)
        se = self._record.compensation_se(fit, t_s, width_s, tau_k)  # of the compensated mean
        self._late_compensations = [
            (
                key,
                SeriesCompensation(
                    1,
                    tuple(float(v) for v in late),
                    late_se,
                    replace(
                        shared,
                        sensitivity=(-g[0], -g[1]),
                        previous_deg2=previous,
                        earlier_deg2=(),
                    ),
                ),
            )
            for key, late, late_se, g, previous in lates
        ]
        return SeriesCompensation(first_k, values_deg, se, shared)

    def _trial_completed(self) -> None:
        assert self._trial is not None
        self.sink.trial_completed(self._trial.index, self._measured)
        self._trial = None
        self._next_trial()

    # -------------------------------------------------------------------------------- progress
    def snapshot(self) -> Snapshot:
        spread = None
        if self.phase is Phase.SETTLE and len(self._blocks) >= 2:
            means = [m for _, _, m in self._blocks[-5:] if not math.isnan(m)]
            if means:
                spread = (max(means) - min(means)) / NANO / 2
        return Snapshot(
            trial=self._tidx or 0,
            n_trials=len(self.plan.trials),
            j=self._j,
            k=min(self._k, self.plan.n_obs),
            n_obs=self.plan.n_obs,
            phase=self.phase,
            now_ms=self.now_ms,
            values_deg=tuple(self._values),
            settle_spread_deg=spread,
            remaining_ms=self._remaining_ms(),
        )

    def _remaining_ms(self) -> int:
        """Rough stand time still needed: settles (as long as the ones seen) plus windows."""
        plan = self.plan
        settle_ms = (
            sum(self._settle_durations) / len(self._settle_durations)
            if self._settle_durations
            else plan.settle.hold_s * 1000
        )
        spacing = plan.observation.spacing_s * 1000

        def series_ms(trial: TrialPlan, j: int, obs: int) -> float:
            w = plan.observation.window_ms(trial.period_s if j == 2 else None)
            return settle_ms + obs * (w + spacing)

        total = 0.0
        if self._trial is not None:
            left = plan.n_obs - self._k + 1
            total += series_ms(self._trial, self._j, left)
            if self._j == 1:
                total += series_ms(self._trial, 2, plan.n_obs)
        for trial in self.todo:
            total += series_ms(trial, 1, plan.n_obs) + series_ms(trial, 2, plan.n_obs)
        return round(total)


_NONE = TrialState()
