"""`campaign run` on a CiA 402 stand: the simulated one in virtual time (`acquisition.cia402_sim`).

The same engine, store and operator link (prompts, stop requests) as `runner.run_live`; the
stream is the stand adapter's acks and statuses and the compass's frames, fed in stand-time
steps; the raw log holds the drive's CANopen traffic instead of the acks and statuses
(`devices.cia402_log`, replayed by `acquisition.cia402_replay`). A stop (Ctrl-C, SIGTERM,
the station's stop request, the end of the campaign) brings the axis to rest by the roll's stop
ramp, then disables it, before the run ends.

A resumed campaign (`runner.resume_point`) starts its run on an axis at rest and enabled (the
master's setup, `devices.cia402`): a killed run's simulation is run again from its start in
virtual time (the same frames: the stored record is re-derived, the campaign ends as an
uninterrupted one), a stopped one goes on at its first incomplete series with the campaign clock
going on from its last stored time."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import IO, TYPE_CHECKING

import can

from gyrostand.acquisition.bus import Recorder
from gyrostand.acquisition.cia402_sim import Cia402Lockstep, SimulatedCia402, feed, next_step
from gyrostand.acquisition.engine import Engine, Phase
from gyrostand.acquisition.operator import OperatorLink
from gyrostand.acquisition.progress import LiveFile, ProgressDisplay
from gyrostand.acquisition.runner import (
    RunResult,
    _judged,
    _remove_live_files,
    _show,
    _stop_on_signals,
    mark_run_start,
    raw_log_path,
    result,
    resume_point,
)
from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.queries import live_file_of, raw_log_segments
from gyrostand.db.wal import checkpoint
from gyrostand.devices.cia402 import DriveError
from gyrostand.devices.decoder import source_info
from gyrostand.frames.batch import RawFrames
from gyrostand.frames.logfile import sha256_of
from gyrostand.plan.model import Plan

if TYPE_CHECKING:
    from gyrostand.acquisition.cia402_live import LiveCia402


def run_cia402(
    plan: Plan,
    store: CampaignStore,
    *,
    start: str = "new",
    quiet: bool = False,
    stop: threading.Event | None = None,
    answers: Mapping[str, str] | None = None,
    terminal: IO[str] | None = None,
) -> RunResult:
    """Acquire the trials the database does not hold yet on the plan's simulated CiA 402 stand
    (virtual time); `start` as `runner.run_live` takes it."""
    stop = stop or threading.Event()
    with store.sessions() as session:
        segments = raw_log_segments(session, store.campaign_id)
    first_frame, progress, clock_ms = resume_point(store, plan, start, segments)
    try:
        sim = _stand(plan, clock_ms)
    except DriveError as exc:  # one line (the campaign stays as stored: nothing acquired)
        raise ValueError(f"the CiA 402 drive could not be started: {exc}") from None
    _remove_live_files(segments)
    raw_log = raw_log_path(store, plan, segments)
    segment = store.open_segment(str(raw_log), start if segments else "new", first_frame)
    store.set_status("running")
    display = ProgressDisplay(quiet=quiet)
    operator = OperatorLink(store, plan, stop, answers or {}, terminal, display.console)
    stand = Cia402Lockstep(sim, plan)
    source = source_info(sim.codec, plan.compass.protocol, plan.bus.simulated, plan.stand.protocol)
    engine = Engine(plan, store, stand, progress, operator, source, start_ms=clock_ms)
    decoder = stand.decoder()
    run_start = start == "restarted"  # a boundary of the compass's record
    recorder = Recorder(plan.bus.queue_size, raw_log, log_rest=False)
    live_file = LiveFile(live_file_of(raw_log))
    position = logged = 0  # frames fed to the engine; frames of this run's raw log
    try:
        with _stop_on_signals(stop), display:
            operator.waiting = lambda: _show(engine, display, live_file)
            while engine.phase is not Phase.DONE:
                if (why := operator.stop_requested()) is not None:
                    engine.interrupt(why)  # the stand is told to stop: its stop ramp begins
                    break
                msgs = next_step(sim, engine, stand.step_s)
                if msgs is None:
                    break
                for batch in feed(engine, decoder, position, msgs, sim.stand.take_faults()):
                    live_file.headings(batch.headings)
                    run_start = run_start and not mark_run_start(store, batch.headings)
                position += len(msgs)
                logged = _log(recorder, sim.take_logged(), logged, first_frame)
                _show(engine, display, live_file)
            _to_rest(sim, store)
            _log(recorder, sim.take_logged(step=False), logged, first_frame)
    finally:
        sim.close()
        live_file.close()
        recorder.stop()
        sha = sha256_of(raw_log)
        store.close_segment(segment, recorder.logged, sha)
        store.run_event("raw log", "info", f"raw frames in {raw_log} (sha256 {sha})")
        outcome = engine.outcome if engine.outcome != "running" else "stopped"
        if outcome == "completed":
            outcome = _judged(store, plan)
        store.set_status(outcome)
        checkpoint(store.sessions.kw["bind"])
    return result(store, outcome, raw_log, sha)


def _stand(plan: Plan, clock_ms: int) -> SimulatedCia402 | LiveCia402:
    """The plan's CiA 402 stand: the simulated one in virtual time, or the drive on the plan's
    bus in real time (`cia402_live`)."""
    if plan.bus.simulated:
        return SimulatedCia402(plan, clock_ms=clock_ms)
    from gyrostand.acquisition.cia402_live import LiveCia402

    return LiveCia402(plan, clock_ms=clock_ms)


def _log(recorder: Recorder, frames: list[can.Message], logged: int, first_frame: int) -> int:
    """Log the run's raw frames (`SimulatedCia402.take_logged`) from stream position `logged`
    but those in earlier logs (a killed run's, re-run: before `first_frame`); the position
    after them."""
    skip = min(max(first_frame - logged, 0), len(frames))
    rest = frames[skip:]
    recorder.log(RawFrames.from_messages(logged + skip, rest, channels=True), rest)
    return logged + len(frames)


def _to_rest(sim: SimulatedCia402, store: CampaignStore) -> None:
    """Run the axis on (SYNC in stand time) until the stop ramp (begun here if the engine ended
    mid-roll) has brought it to rest and it is disabled, within the stand's `rest_limit_s`; an
    event says when, or that it did not."""
    stand = sim.stand
    try:
        at_rest = stand.to_rest()
    except DriveError as exc:  # (a drive that stopped answering: its own reaction must stop it)
        store.run_event("stand", "error", f"the axis not brought to rest: {exc}")
        return
    if not at_rest:
        store.run_event(
            "stand",
            "error",
            f"the axis not at rest {stand.rest_limit_s:g} s after stopping (its stop ramp and "
            "the servo's settling): the drive's own reaction must stop it",
        )
    else:
        store.run_event(
            "stand", "info", f"the axis at rest and disabled at stand time {stand.t_ms / 1000:g} s"
        )
