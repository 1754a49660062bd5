"""Run a campaign live on the bus, resume one, or re-derive one offline from its raw log.

Live and replay share everything downstream of the frames: `BatchDecoder` (with the plan's heading
source, `devices.decoder.frame_decoder`) -> `Engine` ->
`CampaignStore`. Live adds the bus, the stand controller, signals and the wall-clock watchdog."""

from __future__ import annotations

import os
import signal
import struct
import threading
import time
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from itertools import chain, count
from pathlib import Path
from typing import IO

import can
import numpy as np
from can.io.blf import BLFParseError
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.acquisition.bus import BusFault, LiveBus
from gyrostand.acquisition.engine import Command, CommandNotSent, Engine, Phase, TrialState
from gyrostand.acquisition.operator import OperatorLink
from gyrostand.acquisition.procedures import ReplayedProcedures, store_procedures
from gyrostand.acquisition.progress import LiveFile, ProgressDisplay
from gyrostand.acquisition.serial_input import SerialInput, replay_stream
from gyrostand.acquisition.store import CampaignStore
from gyrostand.acquisition.virtual_time import Grants
from gyrostand.db.merge import database_identity
from gyrostand.db.models import Campaign, Observation, RawLogSegment, Series, Trial
from gyrostand.db.queries import (
    RUN_START,
    last_stand_time_ms,
    latest_attempt,
    live_file_of,
    raw_log_segments,
    stand_campaign,
)
from gyrostand.db.removal import discard_campaign, newest_instrument
from gyrostand.db.wal import checkpoint
from gyrostand.devices.decoder import SourceDecoder, frame_decoder, source_info
from gyrostand.devices.serial_replay import logged_pieces, serial_log_path
from gyrostand.devices.source import SourceInfo
from gyrostand.frames.batch import BatchDecoder, Headings, RawFrames
from gyrostand.frames.logfile import LogFileError, read_raw_frames, read_segments, sha256_of
from gyrostand.frames.stream_clock import StreamClock
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import MIN_FIT_TRIALS, Plan
from gyrostand.stand.controller import StandController, StandError
from gyrostand.stand.protocol import Codec

BATCH_FRAMES = 50_000
VIRTUAL_STALL_WALL_S = 60.0  # virtual time: no frame at all for this long = no simulator


@dataclass(frozen=True)
class RunResult:
    campaign_id: int
    outcome: str  # completed | failed (cannot be analysed) | paused | stopped
    trials_completed: int
    trials_failed: int
    observations: int
    raw_log: Path | None
    raw_log_sha256: str | None


class LiveCommander:
    """Sends the engine's commands through the stand controller without waiting: acks and
    refusals are judged by the engine from the stream (as in replay), so only a failure to send
    is reported here. In virtual time each command follows a SIM_SYNC naming the stand time the
    engine had reached when it decided."""

    def __init__(self, controller: StandController, grants: Grants | None) -> None:
        self.controller = controller
        self.grants = grants

    def issue(self, command: Command, now_ms: int) -> None:
        try:
            if self.grants is not None:
                self.grants.sync(now_ms)
            self.controller.post(
                command.kind, command.direction_deg, command.amplitude_cm, command.period_s
            )
        except (StandError, can.CanError) as exc:
            raise CommandNotSent(str(exc)) from exc


@contextmanager
def _stop_on_signals(stop: threading.Event) -> Iterator[None]:
    """SIGINT/SIGTERM set `stop` (the loop then stops the stand and commits) instead of
    killing the process mid-write. Only possible from the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum: int, _frame: object) -> None:
        stop.set()

    for s in previous:
        signal.signal(s, handler)
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def raw_log_path(store: CampaignStore, plan: Plan, segments: Sequence[RawLogSegment]) -> Path:
    """DB-campaign-ID.blf for the first run, DB the database's name (its file's stem), so that
    databases sharing a folder never share a name (DB-IDENTITY-campaign-ID.blf when one of the
    same name elsewhere wrote that one: `db.merge.database_identity`); then the first run's name
    with -resumeN for each resume (`segments`: the campaign's so far). Never an existing file;
    absolute, so that the database finds it from any working directory."""
    folder = Path(plan.raw_log_dir).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    if segments:
        first = Path(segments[0].path).stem
        names: Iterator[str] = (f"{first}-resume{n}" for n in count(len(segments)))
    else:
        url = store.sessions.kw["bind"].url
        database = Path(url.database).stem if url.database else url.get_backend_name()
        with store.sessions() as session:
            identity = (database_identity(session) or "")[:8]
        base = f"{database}-{identity}-campaign-{store.campaign_id}"
        names = chain(
            [f"{database}-campaign-{store.campaign_id}", base], (f"{base}-{n}" for n in count(2))
        )
    suffix = f".{plan.raw_log_format}"
    return next(p for name in names if not (p := folder / f"{name}{suffix}").exists())


def run_live(
    plan: Plan,
    store: CampaignStore,
    *,
    start: str = "new",
    quiet: bool = False,
    stop: threading.Event | None = None,
    answers: Mapping[str, str] | None = None,
    terminal: IO[str] | None = None,
) -> RunResult:
    """Acquire the trials the database does not hold yet, on the plan's bus. `start` (a raw log
    segment's start, `resume_start`): "new" for a new campaign; "restarted" continues at the
    first incomplete series; "continued" re-runs a simulation in virtual time from its start,
    skipping what the database holds (`CampaignStore.re_run`), and logs only the frames after
    the earlier segments' ones, so that the segments read in order are one stream. The plan's
    prompts before a trial are answered from `answers`, the station or `terminal`
    (`OperatorLink`), which also sees the station's stop requests."""
    stop = stop or threading.Event()
    if plan.stand.protocol == "cia402":
        from gyrostand.acquisition.cia402_run import run_cia402

        return run_cia402(
            plan, store, start=start, quiet=quiet, stop=stop, answers=answers, terminal=terminal
        )
    codec = codec_for(plan)
    with store.sessions() as session:
        segments = raw_log_segments(session, store.campaign_id)
    first_frame, progress, clock_ms = resume_point(store, plan, start, segments)
    _remove_live_files(segments)  # left by killed runs: never to be taken for this one's
    raw_log = raw_log_path(store, plan, segments)
    serial = _serial_input(plan, codec, raw_log, clock_ms, segments if start == "continued" else ())
    segment = store.open_segment(str(raw_log), start if segments else "new", first_frame)
    store.set_status("running")
    try:
        live = LiveBus(plan, codec, raw_log, clock_ms, serial and serial.transmitter)
    except BaseException:
        if serial is not None:
            serial.close()
        raise
    grants = Grants(live.bus, start_ms=clock_ms) if live.virtual else None
    stream_clock = StreamClock()
    display = ProgressDisplay(quiet=quiet)
    operator = OperatorLink(store, plan, stop, answers or {}, terminal, display.console)
    commander = LiveCommander(live.controller, grants)
    source = serial.info if serial else _can_source_info(plan, codec)
    engine = Engine(plan, store, commander, progress, operator, source, start_ms=clock_ms)
    decoder = serial.decoder if serial else can_decoder(plan, codec)
    if grants is None:
        silence_wall_s = max(plan.timeouts.bus_silence_s / plan.bus.speedup, 2.0)
        silence = f"bus silence: no frame at all for {silence_wall_s:g} s (wall clock)"
    else:  # the stand's own silence shows in stand time (SIM_CLOCK); this is a dead simulator
        silence_wall_s = VIRTUAL_STALL_WALL_S
        silence = (
            f"bus silence: the simulated stand sent nothing for {silence_wall_s:g} s of wall "
            "time (is it running, in virtual time?)"
        )
    position, dropped, errors = 0, 0, 0
    run_start = start == "restarted"  # a boundary of the compass's record, at its first frame
    last_frame = time.monotonic()
    live_file = LiveFile(live_file_of(raw_log))
    try:
        with _stop_on_signals(stop), display:
            operator.waiting = lambda: _show(engine, display, live_file)
            while engine.phase is not Phase.DONE:
                if (why := operator.stop_requested()) is not None:
                    engine.interrupt(why)
                    break
                if live.merge is not None:  # (virtual time: no overflow, the stand waits)
                    msgs = live.merge.order(live.recorder.drain(BATCH_FRAMES, 0.05))
                    if live.merge.error is not None:
                        engine.interrupt(live.merge.error)
                        break
                    raw = RawFrames.from_messages(position, msgs, channels=live.own_bus)
                else:  # (msgs None: the frames came as arrays)
                    raw, msgs = live.recorder.drain_frames(position, BATCH_FRAMES, 0.05)
                if live.recorder.dropped > dropped:
                    lost = live.recorder.dropped - dropped
                    dropped = live.recorder.dropped
                    store.run_event(
                        "queue overflow",
                        "error",
                        f"the acquisition's queue overflowed: {lost} frames dropped",
                    )
                overflows = live.recorder.overflows
                if live.recorder.log_error is not None:  # as a database refusing writes
                    engine.interrupt(f"the raw log cannot be written: {live.recorder.log_error}")
                    break
                while errors < len(live.recorder.errors):
                    exc = live.recorder.errors[errors]
                    errors += 1
                    what = str(exc) if isinstance(exc, BusFault) else repr(exc)
                    engine.fail(f"bus or listener error: {what}", kind="bus error")
                if live.simulator is not None and live.simulator.error is not None:
                    engine.interrupt(f"simulated stand failed: {live.simulator.error!r}")
                    break
                if serial is not None and serial.error is not None:
                    engine.interrupt(serial.error)
                    break
                if len(raw):
                    batch = decoder.decode(raw)
                    for before, overflow in overflows:
                        at = position + before  # (a serial line's pieces among the frames)
                        engine.frames_dropped(serial.stream_pos(before) if serial else at, overflow)
                    engine.feed(batch)
                    run_start = run_start and not mark_run_start(store, batch.headings)
                    live_file.headings(batch.headings)
                    if grants is not None and serial is not None:  # (timed by the decoder)
                        keep = serial.decoder.frames_before(engine.consumed)
                        raw, msgs = raw.head(keep), msgs and msgs[:keep]
                        restamp(raw, msgs, raw.timestamp)
                        _granted(engine, grants.progress, engine.now_ms)
                    elif grants is not None:  # the log ends where the campaign did
                        keep = engine.consumed - position
                        times_s = stream_clock.times_s(batch, position)[:keep]
                        raw, msgs = raw.head(keep), msgs and msgs[:keep]
                        restamp(raw, msgs, times_s)
                        _granted(engine, grants.progress, engine.now_ms)
                    skip = min(max(first_frame - position, 0), len(raw))  # in earlier logs
                    live.recorder.log(raw.tail(skip), msgs and msgs[skip:])
                    if serial is not None:
                        serial.log_batch(engine.consumed)
                    position += len(raw)
                    # silence counts from when the acquisition listens again: a slow batch here
                    # (a first import, an emulated machine) is not the stand's silence
                    last_frame = time.monotonic()
                else:
                    if grants is not None:
                        _granted(engine, grants.idle)
                    if time.monotonic() - last_frame > silence_wall_s:
                        engine.fail(silence, kind="bus silence")
                        last_frame = time.monotonic()
                _show(engine, display, live_file)
    finally:
        live_file.close()
        live.close()
        serial_log = _close_serial(store, serial) if serial is not None else None
        sha = sha256_of(raw_log)
        log_error = live.recorder.log_error
        if log_error is None:
            store.close_segment(segment, live.recorder.logged, sha, serial=serial_log)
            store.run_event("raw log", "info", f"raw frames in {raw_log} (sha256 {sha})")
        else:  # it ends before the run did, as a killed run's does
            frames = _readable_frames(raw_log)
            store.close_segment(segment, frames, sha, ending="killed", serial=serial_log)
            store.run_event(
                "raw log",
                "error",
                f"raw log {raw_log} incomplete: {frames} frames readable of the run's; "
                f"writing it failed: {log_error}",
            )
        outcome = engine.outcome if engine.outcome != "running" else "stopped"
        if outcome == "completed":
            outcome = _judged(store, plan)
        store.set_status(outcome)
        checkpoint(store.sessions.kw["bind"])  # the file alone holds the run (a copy of it)
    if log_error is not None:
        raise RawLogFailed(f"the raw log {raw_log} cannot be written: {log_error}")
    return result(store, outcome, raw_log, sha)


def resume_point(
    store: CampaignStore, plan: Plan, start: str, segments: Sequence[RawLogSegment]
) -> tuple[int, dict[int, TrialState] | None, int]:
    """Where a run of the campaign begins (`start` as `run_live` takes it): the frames of the
    earlier raw logs (`segments`) a re-run derives again without logging them, the progress the
    engine continues from (None: the campaign's start) and the stand clock it goes on from, ms."""
    if start == "continued":
        store.re_run()
        return sum(s.frames or 0 for s in segments), None, 0  # all closed, or found killed
    clock_ms = 0
    if start == "restarted":
        store.redo_uncompensated()
        store.complete_acquired()
        # its clock goes on, as a stand's does: one campaign time (a CiA 402 stand's is ours)
        if plan.bus.simulated or plan.stand.protocol == "cia402":
            with store.sessions() as session:
                clock_ms = -(-last_stand_time_ms(session, store.campaign_id) // 1000) * 1000
    return 0, store.progress(), clock_ms


def mark_run_start(store: CampaignStore, headings: Headings) -> bool:
    """The RUN_START event of a restarted run at its first heading, if `headings` has one."""
    if not headings.t_ms.size:
        return False
    t_ms = int(headings.t_ms[0])
    first = f"this run's first heading at stand time {t_ms / 1000:g} s"
    store.run_event(RUN_START, "info", first, t_ms)
    return True


def can_decoder(plan: Plan, codec: Codec) -> BatchDecoder | SourceDecoder:
    """The decoder of a compass on CAN (live and replay)."""
    own_bus = plan.compass.own_bus
    return frame_decoder(codec, *plan.heading_source, plan.inclinometer_mount, own_bus=own_bus)


def _can_source_info(plan: Plan, codec: Codec) -> SourceInfo:
    """A compass on CAN as the engine and the campaign record take it (live and replay): on a
    bus of its own, its silence names that bus."""
    info = source_info(codec, plan.compass.protocol, encoder=plan.compass.encoder())
    if plan.compass.own_bus:
        return replace(info, silence=f"{plan.compass.bus_label} silent")
    return info


def _serial_input(
    plan: Plan, codec: Codec, raw_log: Path, clock_ms: int, earlier: Sequence[RawLogSegment]
) -> SerialInput | None:
    """A serial compass's input (None for a compass on CAN); `earlier`: the segments whose
    serial logs hold the start of a re-run's line."""
    if plan.compass.protocol != "iec61162":
        return None
    return SerialInput(plan, codec, raw_log, clock_ms, logged_pieces([s.path for s in earlier]))


def _close_serial(store: CampaignStore, serial: SerialInput) -> tuple[int | None, str | None]:
    """Close the serial input: its log's lines and hash, also in an event."""
    lines, sha = serial.close()
    store.run_event(
        "raw log", "info", f"serial sentences in {serial.path} ({lines} lines, sha256 {sha})"
    )
    return lines, sha


class RawLogFailed(RuntimeError):
    """A run's raw log could not be written (a full disk): the run stopped the stand and ended
    with what the database holds; the log holds the frames up to its last complete block."""


def _judged(store: CampaignStore, plan: Plan) -> str:
    """A campaign whose every trial was acquired or failed: "completed" when the analysis can use
    it (or it is `acquisition_only` and a trial completed), else "failed", with an event saying
    why (`campaign resume --retry-failed` takes it up again)."""
    with store.sessions() as session:
        completed = session.scalars(
            select(Trial.role).where(
                Trial.campaign_id == store.campaign_id,
                Trial.status == "completed",
                latest_attempt(),
            )
        ).all()
    fit = sum(role == "fit" for role in completed)
    if not completed:
        why = "no trial completed"
    elif fit < MIN_FIT_TRIALS and not plan.campaign.acquisition_only:
        why = f"{fit} fit trial{'s' * (fit != 1)} completed: the analysis needs {MIN_FIT_TRIALS}"
    else:
        return "completed"
    store.run_event("campaign failed", "error", f"the campaign cannot be analysed: {why}")
    return "failed"


def _remove_live_files(segments: Sequence[RawLogSegment]) -> None:
    for s in segments:
        LiveFile(live_file_of(s.path)).close()


def _show(engine: Engine, display: ProgressDisplay, live_file: LiveFile) -> None:
    snapshot = engine.snapshot()
    display.update(snapshot)
    live_file.update(snapshot)


def _granted(engine: Engine, send: Callable[..., None], *args: int) -> None:
    """Send a SIM_SYNC; a bus that refuses it fails the trial (as a failed command does)."""
    try:
        send(*args)
    except can.CanError as exc:
        engine.fail(f"could not send SIM_SYNC: {exc}", kind="bus error")


def restamp(raw: RawFrames, msgs: list[can.Message] | None, times_s: np.ndarray) -> None:
    """Give the frames their stream times (virtual time: the raw log's timestamps)."""
    raw.timestamp[:] = times_s
    if msgs is None:  # (the frames came as arrays)
        return
    for msg, t in zip(msgs, times_s.tolist(), strict=True):
        msg.timestamp = t


def result(store: CampaignStore, outcome: str, raw_log: Path | None, sha: str | None) -> RunResult:
    with store.sessions() as session:
        return RunResult(
            campaign_id=store.campaign_id,
            outcome=outcome,
            trials_completed=_count_trials(session, store.campaign_id, "completed"),
            trials_failed=_count_trials(session, store.campaign_id, "failed"),
            observations=observation_count(session, store.campaign_id),
            raw_log=raw_log,
            raw_log_sha256=sha,
        )


def _count_trials(session: Session, campaign_id: int, status: str) -> int:
    return (
        session.scalar(
            select(func.count(Trial.id)).where(
                Trial.campaign_id == campaign_id, Trial.status == status, latest_attempt()
            )
        )
        or 0
    )


def observation_count(session: Session, campaign_id: int) -> int:
    return (
        session.scalar(
            select(func.count(Observation.id))
            .join(Series, Series.id == Observation.series_id)
            .join(Trial, Trial.id == Series.trial_id)
            .where(Trial.campaign_id == campaign_id, latest_attempt())
        )
        or 0
    )


class _NoCommands:
    """Replay's commander: the commands were sent live; their acks are in the log."""

    def issue(self, command: Command, now_ms: int) -> None:
        pass


LOG_ERRORS = (OSError, ValueError, EOFError, struct.error, zlib.error, can.CanError, BLFParseError)
"""What reading a raw log raises when it cannot be read (python-can's readers, `frames.logfile`)."""


class _LoggedPrompts:
    """A replay's frames and its operator (`engine.Operator`) as the live run's engine took
    it: the prompts before a trial were answered when the log holds a frame after the point
    where the engine asked them; when it ends there, the live run stopped there (the operator
    stopped the campaign rather than confirm: a "confirm" prompt has no other answer; or the
    process was killed). Exact in virtual time, where the log ends with the last frame the
    engine took; a real-time log holds the rest of its last batch, so a stop at a prompt
    replays there as an answer, then the log's end."""

    def __init__(self, stream: Iterator[RawFrames]) -> None:
        self._stream = stream
        self._ahead: RawFrames | None = None
        self._end = 0  # the stream position after the batch being fed
        self.engine: Engine | None = None

    def __iter__(self) -> Iterator[RawFrames]:
        while self._more():
            raw, self._ahead = self._ahead, None
            assert raw is not None
            self._end = raw.start + len(raw)
            yield raw

    def _more(self) -> bool:
        if self._ahead is None:
            self._ahead = next(self._stream, None)
        return self._ahead is not None

    def before_trial(self, trial: int) -> str | None:
        assert self.engine is not None
        if self.engine.consumed < self._end or self._more():
            return None
        return f"the log ends at the operator's prompt before trial {trial}: not answered"


class ReplayLogError(ValueError):
    """A raw log that cannot be replayed: unreadable, corrupt, or without a CAN frame. The
    message starts with the file's name and says what is wrong."""


@dataclass(frozen=True)
class ReplayLog:
    """A raw log read whole once, before a replay writes anything."""

    path: Path
    sha256: str
    frames: int
    truncated: str | None  # how the log is known to end early (a killed writer, a cut copy)


def _blf_truncation(log: Path) -> str | None:
    """How a BLF file ends early, from its header (python-can's reader): a writer that closes
    the file writes its final size there; a killed one leaves the initial header."""
    with can.BLFReader(log) as reader:
        declared = reader.file_size
    actual = log.stat().st_size
    if actual == declared:
        return None
    if actual < declared:
        return f"cut short: {actual} of the {declared} bytes its header declares"
    return "never closed by its writer (killed?): its last frames were not written"


def check_replay_log(log: Path) -> ReplayLog:
    """Read the whole log (ReplayLogError when it cannot be replayed); a BLF file that ends
    early but holds frames can be replayed up to its last complete container."""
    try:
        sha = sha256_of(log)
        frames = sum(len(raw) for raw in read_raw_frames(log))
        blf = log.suffix.lower() == ".blf"
        truncated = _blf_truncation(log) if blf else None
    except LOG_ERRORS as exc:
        what = str(exc) if isinstance(exc, LogFileError) else f"{log}: {exc}"
        raise ReplayLogError(what) from exc
    if frames == 0:
        if blf and truncated is not None:
            why = f"truncated before its first complete container ({truncated})"
        elif blf:
            why = "a BLF file header and nothing else"
        else:
            why = f"no line of it is a CAN frame of a {log.suffix.lstrip('.').upper()} log"
        raise ReplayLogError(f"{log}: no CAN frames in it: {why}")
    return ReplayLog(log, sha, frames, truncated)


def replay(
    plan: Plan,
    sessions: sessionmaker[Session],
    logs: Sequence[Path],
    checked: Sequence[ReplayLog] | None = None,
    procedures: ReplayedProcedures | None = None,
) -> RunResult:
    """Re-derive a campaign offline from raw logs read in order as one stream (the segments of
    a campaign, `RawLogSegment`) into a new campaign (source "replay"). Each log is read whole
    first (`check_replay_log`, unless `checked` holds their results): one that cannot be
    replayed (ReplayLogError) leaves the database untouched. A log that ends early is replayed
    up to its end, with a warning event. The plan's procedures, re-derived from their raw log
    (`procedures`: `campaign_procedures.replay_procedures_log`), are stored first."""
    if plan.procedure and procedures is None:
        raise ReplayLogError("the plan has the standard's procedures: their replay is missing")
    codec = codec_for(plan)
    checked = checked or [check_replay_log(log) for log in logs]
    paths = [log.path for log in checked]
    if plan.stand.protocol == "cia402":  # the drive's CANopen traffic, through our master
        from gyrostand.acquisition.cia402_replay import replay_cia402

        return replay_cia402(plan, sessions, checked, procedures)
    if plan.compass.protocol == "iec61162":  # its sentences from the serial logs beside
        try:
            decoder, stream = replay_stream(plan, codec, paths)
        except LogFileError as exc:
            raise ReplayLogError(str(exc)) from exc
        info = decoder.source.info
    else:
        decoder = can_decoder(plan, codec)
        stream = read_segments(paths)
        info = _can_source_info(plan, codec)
    with replay_store(sessions, plan, procedures) as store:
        frames = _LoggedPrompts(_changed_since(stream, paths))
        engine = Engine(plan, store, _NoCommands(), operator=frames, source=info)
        frames.engine = engine
        with store.deferred():
            replayed_segments(store, checked)
            for raw in frames:
                engine.feed(decoder.decode(raw))
                if engine.phase is Phase.DONE:
                    break
            if engine.phase is not Phase.DONE:
                engine.interrupt("the log ends before the campaign does")
        outcome = engine.outcome if engine.outcome != "completed" else _judged(store, plan)
        store.set_status(outcome)
        return result(store, outcome, checked[-1].path, checked[-1].sha256)


@contextmanager
def replay_store(
    sessions: sessionmaker[Session], plan: Plan, procedures: ReplayedProcedures | None
) -> Iterator[CampaignStore]:
    """A replay's new campaign (source "replay"), with the re-derived procedures (if any). A
    replay that fails part-way (a log that does not match, Ctrl-C or SIGTERM, a database error)
    takes it out again with everything it wrote and its lease: the database is as it was
    before. (A kill -9 leaves it, marked running: `campaign remove` takes it out.)"""
    instruments = newest_instrument(sessions)
    with _terminate_interrupts():
        store = CampaignStore.create(sessions, plan, source="replay")
        try:
            if procedures is not None:
                store_procedures(sessions, store.campaign_id, procedures.results, procedures.log)
            yield store
        except BaseException:
            store.lease.release()
            discard_campaign(sessions, store.campaign_id, instruments)
            raise


@contextmanager
def _terminate_interrupts() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt, as Ctrl-C does (instead of ending the process where
    it is). Only possible from the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, _frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _changed_since(stream: Iterator[RawFrames], paths: Sequence[Path]) -> Iterator[RawFrames]:
    """The logs' frames; a log that can no longer be read (changed since `check_replay_log`
    read it whole) is a ReplayLogError naming it."""
    try:
        yield from stream
    except LOG_ERRORS as exc:
        what = str(exc) if isinstance(exc, LogFileError) else f"{', '.join(map(str, paths))}: {exc}"
        raise ReplayLogError(f"{what} (changed since it was read)") from exc


def replayed_segments(store: CampaignStore, checked: Sequence[ReplayLog]) -> None:
    """The replayed campaign's raw log segments, with a warning for each that ends early."""
    position = 0
    for log in checked:
        seq = store.open_segment(
            str(log.path.resolve()), "continued" if position else "new", position
        )
        store.close_segment(seq, log.frames, log.sha256, serial=serial_log_of(log.path))
        position += log.frames
        if log.truncated is not None:
            store.run_event(
                "raw log",
                "warning",
                f"raw log {log.path.name} truncated after {log.frames} frames "
                f"({log.truncated}): replayed up to there",
            )


def resume_store(sessions: sessionmaker[Session], campaign_id: int) -> tuple[Plan, CampaignStore]:
    """The plan stored with a stand campaign (else CampaignNotFound, NotOnTheStand) and a store
    to continue it, holding the campaign's lease (CampaignBusy while another process acquires
    into it). A campaign still marked running was left by a process that is gone: an
    "interrupted" event says so; the resume is an event; raw logs left open by a killed run are
    closed in the database (`close_killed_segments`)."""
    from gyrostand.plan.model import parse_plan

    with sessions() as session:  # CampaignNotFound, NotOnTheStand
        text = stand_campaign(session, campaign_id).plan_toml
    plan, store = parse_plan(text), CampaignStore(sessions, campaign_id)
    with store.sessions() as session:  # read under the lease: nobody else is running it now
        left_running = session.get_one(Campaign, campaign_id).status == "running"
    if left_running:
        store.run_event(
            "interrupted",
            "warning",
            "the previous run ended without closing the campaign (killed or crashed); "
            "what it committed is kept",
        )
    store.run_event("resume", "info", f"resumed by process {os.getpid()}")
    close_killed_segments(store)
    return plan, store


def close_killed_segments(store: CampaignStore) -> None:
    """Raw logs a killed run left open: their frames (up to the last complete block) and hash
    go into the database, ending "killed", with an event."""
    with store.sessions() as session:
        left = [
            (s.seq, Path(s.path))
            for s in raw_log_segments(session, store.campaign_id)
            if s.ending is None
        ]
    for seq, path in left:
        frames, sha = _readable_frames(path), sha256_of(path) if path.is_file() else None
        store.close_segment(seq, frames, sha, ending="killed", serial=serial_log_of(path))
        store.run_event(
            "raw log",
            "warning" if sha else "error",
            f"raw log {path} left open by the stopped run: {frames} frames readable"
            + (f" (sha256 {sha})" if sha else "; the file is missing"),
        )


def serial_log_of(can_log: Path) -> tuple[int | None, str | None] | None:
    """The complete lines (None: a line not ours in it) and hash of the serial log beside a
    CAN log; None when there is none."""
    path = serial_log_path(can_log)
    if not path.is_file():
        return None
    try:
        lines: int | None = logged_pieces([can_log])
    except LogFileError:
        lines = None
    return lines, sha256_of(path)


def _readable_frames(path: Path) -> int:
    """Frames of a log that can be read, up to where it is cut off."""
    frames = 0
    try:
        for raw in read_raw_frames(path):
            frames += len(raw)
    except (OSError, ValueError, EOFError, can.CanError):
        pass
    return frames


def resume_start(store: CampaignStore, stored: Plan, plan: Plan) -> str:
    """How a resumed run starts (`run_live`): "continued" for a simulation in virtual time on
    the stored plan's bus whose every earlier run was killed (the last one left the campaign
    planned or running) and no trial retried (so the database holds a prefix of what re-running
    the simulation gives: the resumed campaign equals an uninterrupted one); else "restarted",
    at the first incomplete series."""
    with store.sessions() as session:
        segments = raw_log_segments(session, store.campaign_id)
        attempts = session.scalar(
            select(func.max(Trial.attempt)).where(Trial.campaign_id == store.campaign_id)
        )
        status = session.get_one(Campaign, store.campaign_id).status
    killed = status in ("planned", "running")  # left so by a killed run
    rerun = (
        killed  # (a run that stopped itself, e.g. on a raw log it could not write, is no prefix)
        and plan.bus.simulated
        and plan.bus.timing == "virtual"
        and plan.bus == stored.bus
        and all(s.ending == "killed" and s.start != "restarted" for s in segments)
        and attempts == 1
    )
    return "continued" if rerun else "restarted"
