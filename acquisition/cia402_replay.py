"""Replay of a CiA 402 campaign's raw logs (`cia402_log`): per run, gyrostand's master and stand
adapter run again against the logged drive, the engine fed in the same batches as live with the
logged compass and inclinometer frames: the acks, statuses (motion measured from the drive's
actual position), drive faults and so the observations and failed trials are those of the live
runs. Each run's engine starts where the live one did: the campaign's progress so far, on the
campaign clock of the run's RUN record."""

from __future__ import annotations

import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import can
import canopen

from gyrostand.acquisition.cia402_run import _to_rest
from gyrostand.acquisition.cia402_sim import STEP_S, Cia402Lockstep, feed, merged
from gyrostand.acquisition.cia402_stand import Cia402Stand, axis_config
from gyrostand.acquisition.engine import Engine, Phase
from gyrostand.acquisition.procedures import ReplayedProcedures
from gyrostand.acquisition.store import CampaignStore
from gyrostand.devices.cia402 import MASTER_NODE_ID, Cia402Axis, DriveError
from gyrostand.devices.cia402_log import (
    DriveLogError,
    LoggedDrive,
    LoggedRun,
    logged_runs,
    starts_a_run,
)
from gyrostand.devices.decoder import source_info
from gyrostand.devices.roll_trajectory import Kinematics
from gyrostand.devices.sim_drive import SIM_DRIVE_EDS
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import Plan

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

    from gyrostand.acquisition.runner import ReplayLog, RunResult

LOG_ENDS = "the raw log's run ends here (stopped, or its writer killed)"
LOG_CUT = "its raw log ends after its last batch, not with the axis brought to rest (killed?)"


class _Answered:
    """The live run's operator as its engine took it, from the run's log: the prompts before a
    trial were answered when the log goes on with another batch after the one they came in;
    when it does not, the live run stopped there (the operator stopped the campaign rather than
    confirm: a "confirm" prompt has no other answer; or the process was killed)."""

    def __init__(self, sim: ReplayedCia402) -> None:
        self.sim = sim

    def before_trial(self, trial: int) -> str | None:
        if self.sim.goes_on():
            return None
        return f"{LOG_ENDS}, at the operator's prompt before trial {trial}: not answered"


class ReplayedCia402:
    """A logged run as `cia402_sim.SimulatedCia402` offers it to the engine's loop: the master
    on a virtual bus whose drive is the log, the other frames the log's per batch."""

    def __init__(self, plan: Plan, run: LoggedRun) -> None:
        s = plan.stand
        assert s.node_id is not None and s.counts_per_degree and s.arm_length_cm
        channel = f"gyrostand-cia402-{uuid.uuid4().hex}-replay"
        self._network = canopen.Network()
        self._network.NOTIFIER_CYCLE = 0.05
        self._network.connect(interface="virtual", channel=channel)
        config = axis_config(plan, SIM_DRIVE_EDS)
        self.drive = LoggedDrive(self._network, channel, run.drive)
        try:
            self.drive.start(s.node_id, config.master_node_id)
            self.axis = Cia402Axis(self._network, config)
            self.axis.start()
        except BaseException:
            self.close()
            raise
        self.codec = codec_for(plan)
        kinematics = Kinematics(s.counts_per_degree, s.arm_length_cm)
        self.stand = Cia402Stand(self.axis, kinematics, s.ramp_s, self.codec, clock_ms=run.clock_ms)
        self._steps: Iterator[list[can.Message]] = run.steps
        self._step: list[can.Message] | None = None
        self._next: list[can.Message] | None = None  # (read ahead: `goes_on`)

    def next_step(self) -> bool:
        """Whether the log holds another batch the live engine was fed."""
        self._step = self._next if self._next is not None else next(self._steps, None)
        self._next = None
        return self._step is not None

    def goes_on(self) -> bool:
        """Whether the run's log holds another batch after the one being fed."""
        if self._next is None:
            self._next = next(self._steps, None)
        return self._next is not None

    def advance_to(self, t_s: float) -> list[can.Message]:
        """The master's frames up to `t_s` and the logged batch's others, as live."""
        step, self._step = self._step, None
        assert step is not None
        return merged(self.stand.advance_to(t_s), step, [])

    def close(self) -> None:
        self.drive.close()
        self._network.disconnect()


def replay_runs(plan: Plan, store: CampaignStore, paths: Sequence[Path]) -> Engine | None:
    """Replay every run of the logs into `store`; the last run's engine (None: no run)."""
    from gyrostand.acquisition.runner import mark_run_start

    s = plan.stand
    assert s.node_id is not None
    engine, master_id = None, MASTER_NODE_ID
    for n, run in enumerate(logged_runs(paths, s.node_id, master_id)):
        if n:  # as a resumed run (`runner.resume_point`)
            store.redo_uncompensated()
            store.complete_acquired()
        try:
            sim = ReplayedCia402(plan, run)
        except (DriveError, DriveLogError) as exc:
            raise DriveLogError(f"run {n + 1} of the raw log: {exc}") from None
        try:
            stand = Cia402Lockstep(sim, plan)  # type: ignore[arg-type]
            source = source_info(sim.codec, plan.compass.protocol, True, s.protocol)
            progress = store.progress()
            with store.deferred():  # (a transaction per run: the next one reads its progress)
                engine = Engine(plan, store, stand, progress, _Answered(sim), source, run.clock_ms)
                decoder, position, run_start = stand.decoder(), 0, n > 0
                while engine.phase is not Phase.DONE and sim.next_step():
                    msgs = sim.advance_to(sim.stand.t_s + STEP_S)
                    for batch in feed(engine, decoder, position, msgs, sim.stand.take_faults()):
                        run_start = run_start and not mark_run_start(store, batch.headings)
                    position += len(msgs)
                if engine.phase is not Phase.DONE:
                    engine.interrupt(LOG_ENDS)
                try:
                    _to_rest(sim, store)  # type: ignore[arg-type]
                except DriveLogError as exc:  # (the live run went on: its log was cut here)
                    store.run_event("raw log", "warning", f"run {n + 1}: {LOG_CUT}: {exc}")
        finally:
            sim.close()
    return engine


def check_first_log(plan: Plan, path: Path) -> None:
    """DriveLogError (one line) unless `path` begins a CiA 402 campaign's raw log: a RUN
    record first (not so another stand's log, a later segment alone, or a log written before
    gyrostand logged the drive's traffic: the acks and statuses its master derived instead),
    of the simulated stand in virtual time."""
    if not plan.bus.simulated:  # (its SYNCs were the bus's, not one per cycle of the master)
        raise DriveLogError(
            "replay of a CiA 402 campaign run on a real bus is not supported yet (only the "
            "simulated stand's, in virtual time)"
        )
    if not starts_a_run(path):
        raise DriveLogError(
            f"{path}: not a CiA 402 stand's raw log from its start (no RUN record first: "
            "another stand's, a later segment, or written before gyrostand logged the drive's "
            "traffic)"
        )


def replay_cia402(
    plan: Plan,
    sessions: sessionmaker[Session],
    checked: Sequence[ReplayLog],
    procedures: ReplayedProcedures | None = None,
) -> RunResult:
    """`runner.replay` of a CiA 402 campaign: a new campaign (source "replay") from its raw
    logs; a log whose drive traffic is not what the master sends is one line (DriveLogError,
    a ValueError) and the database is left as it was (`runner.replay_store`)."""
    from gyrostand.acquisition.runner import _judged, replay_store, replayed_segments, result

    check_first_log(plan, checked[0].path)  # (before the database is written)
    with replay_store(sessions, plan, procedures) as store:
        with store.deferred():
            replayed_segments(store, checked)
        engine = replay_runs(plan, store, [log.path for log in checked])
        assert engine is not None  # (the first log starts a run)
        outcome = engine.outcome if engine.outcome != "completed" else _judged(store, plan)
        store.set_status(outcome)
        return result(store, outcome, checked[-1].path, checked[-1].sha256)
