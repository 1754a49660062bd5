"""A CiA 402 roll axis as the campaign engine's stand.

The engine commands a stand that takes "set K, A, tau", "start" and "stop", acknowledges each at
its clock and reports its motion every 500 ms (STAND_MOTION / STAND_STATUS). A CiA 402 drive
does none of that: gyrostand is its master (`devices.cia402`). This adapter is that stand:

- "set" keeps K, A, tau (A in cm becomes a roll angle by the plan's kinematics); K is the
  operator's (a single-axis stand is turned by hand, confirmed at a prompt before the trial).
- "start" enables the axis (power state machine to OPERATION ENABLED) and begins the roll
  trajectory (quintic start ramp, sinusoid); its ack is at the stand time the roll begins.
- "stop" begins the stop ramp (acknowledged then); the statuses say "rocking" until the axis is
  at rest and disabled.
- Every STATUS_MS: a status with the motion MEASURED from the drive's actual position (0x6064,
  TPDO1 at every SYNC): amplitude and period by a fitted sinusoid over the last MEASURE_PERIODS
  commanded periods (`analysis.measured_roll`), "rocking" while a roll is under way.

Clock: a drive has no clock to report. The campaign clock is the SYNC count x cycle_ms (stand
time; stored with the campaign's time base, `devices.clock.CIA402_STAND_CLOCK`), from `clock_ms`
(a resumed campaign's clock goes on from its last stored time): every ack and status carries it,
and a compass timed by reception is put on it by its statuses (`devices.clock.ReceptionClock`).
The frames' reception times are the SYNC count x cycle_ms of this run.

The acks and statuses go into the engine's stream in the encoding of the plan's stand codec,
never onto the CANopen bus (whose identifiers they would collide with) nor into the raw log,
which holds the drive's CANopen traffic: a replay runs this adapter again against the logged
drive (`devices.cia402_log`) and so derives them again. A drive fault, a lost drive
heartbeat or a following-error trip is one `DriveFault` (`take_faults`) for the caller to fail
the trial with.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import can
import numpy as np

from gyrostand.acquisition.engine import Command
from gyrostand.analysis.measured_roll import RollFitError, measure_roll
from gyrostand.devices.cia402 import SETTLE_CYCLES, AxisConfig, Cia402Axis, DriveError, Rocking
from gyrostand.devices.roll_trajectory import Kinematics, RollTrajectory
from gyrostand.stand.protocol import Codec, Reason

if TYPE_CHECKING:
    from gyrostand.plan.model import Plan

STATUS_MS = 500  # a status every 500 ms of stand time, as a gyrostand stand controller sends
MEASURE_PERIODS = 2  # the motion is fitted over the last two commanded periods
IDLE_CONTROLWORD = 0x00  # disable voltage: the axis off between rolls (SYNC goes on)


def axis_config(
    plan: Plan, eds: Path, sync: Literal["lockstep", "periodic"] = "lockstep"
) -> AxisConfig:
    """The master's configuration of the plan's [stand] drive (described by `eds`)."""
    s = plan.stand
    assert s.node_id is not None
    return AxisConfig(
        s.node_id,
        eds,
        s.cycle_ms,
        heartbeat_ms=s.drive_heartbeat_ms,
        drive_timeout_ms=s.drive_timeout_ms,
        sync=sync,
    )


@dataclass(frozen=True)
class DriveFault:
    """Why the drive ended a roll (one line, the drive's error code named) and its event kind."""

    kind: str  # "drive fault", "following error" or "heartbeat lost"
    reason: str
    t_ms: int  # its reception time (ms of this run's SYNC count), where it cuts the stream


@dataclass(frozen=True)
class Motion:
    """A change of the platform's motion at stand time `t_s` (for a simulated compass on it):
    "set" (K, A, tau commanded), "start" (the roll begins) or "stop" (the stop ramp begins)."""

    t_s: float
    kind: str
    direction_deg: float
    amplitude_cm: float
    period_s: float


class Cia402Stand:
    """The engine's commander (`issue`) and the stand's frames (`advance_to`) for a started
    `Cia402Axis`. `on_motion` hears every motion change (a simulated compass)."""

    def __init__(
        self,
        axis: Cia402Axis,
        kinematics: Kinematics,
        ramp_s: float,
        codec: Codec,
        on_motion: Callable[[Motion], None] = lambda m: None,
        clock_ms: int = 0,
    ) -> None:
        self.axis = axis
        self.clock_ms = clock_ms
        self.kinematics = kinematics
        self.ramp_s = ramp_s
        self.codec = codec
        self.on_motion = on_motion
        self.zero_counts = axis.actual  # the platform is level where the axis was started
        self._out: list[can.Message] = []
        self._setting: tuple[float, float, float] | None = None  # K deg, A cm, tau s
        self._start_pending = False
        self._rocking: Rocking | None = None
        self._started_s = 0.0
        self._samples: deque[tuple[float, float]] = deque()  # (stand s, actual deg)
        self._faults: list[DriveFault] = []
        self._reported = False  # this roll's failure was reported
        self._next_status_ms = (self.t_ms // STATUS_MS + 1) * STATUS_MS
        axis.on_cycle = self._status_due  # also in the cycles of enabling and stopping

    @property
    def t_s(self) -> float:
        return self.axis.t_s

    @property
    def t_ms(self) -> int:
        """The campaign clock (what acks and statuses carry)."""
        return self.clock_ms + self.axis.cycle * self.axis.config.cycle_ms

    def _fault(self, kind: str, reason: str) -> None:
        self._faults.append(DriveFault(kind, reason, self.axis.cycle * self.axis.config.cycle_ms))

    @property
    def rocking(self) -> bool:
        return self._rocking is not None

    # -- commands -------------------------------------------------------------------------

    def issue(self, command: Command, now_ms: int = 0) -> None:
        """Take the engine's command at the current stand time (its echo enters the stream)."""
        K, A, tau = command.direction_deg, command.amplitude_cm, command.period_s
        self._emit([self.codec.encode_command(command.kind, K, A, tau)])
        if command.kind == "set":
            if self.rocking:
                self._ack("set", Reason.BUSY)
            elif A <= 0.0 or tau <= 0.0:
                self._ack("set", Reason.AMPLITUDE if A <= 0.0 else Reason.PERIOD)
            else:
                self._setting = (K, A, tau)
                self.on_motion(Motion(self.t_s, "set", K, A, tau))
                self._ack("set")
        elif command.kind == "start":
            if self._setting is None:
                self._ack("start", Reason.NOT_CONFIGURED)
            elif self.rocking:
                self._ack("start")
            else:
                self._start_pending = True  # enabled and begun at the next cycle
        else:  # stop: the statuses say "rocking" until the axis is at rest and disabled
            if self._rocking is not None:
                self._begin_stop()
            self._start_pending = False
            self._ack("stop")

    def _ack(self, command: str, refusal: Reason | None = None) -> None:
        msg = self.codec.encode_ack(
            command, refusal is None, refusal or "", stand_time_ms=self.t_ms
        )
        self._emit([msg])

    def _emit(self, msgs: list[can.Message]) -> None:
        for msg in msgs:
            msg.timestamp = self.t_s
        self._out += msgs

    def _begin_stop(self) -> None:
        assert self._rocking is not None and self._setting is not None
        before = self._rocking.trajectory.stop_at_s
        self._rocking.stop()
        if self._rocking.trajectory.stop_at_s < before:
            self.on_motion(Motion(self.t_s, "stop", *self._setting))

    # -- stand time -----------------------------------------------------------------------

    def advance_to(self, t_s: float) -> list[can.Message]:
        """Run SYNC cycles up to stand time `t_s`; the stand's frames meanwhile (acks and
        statuses, stamped with their stand time)."""
        while self.t_s < t_s - 1e-9:
            self._cycle()
        out, self._out = self._out, []
        return out

    @property
    def rest_limit_s(self) -> float:
        """The stand time a roll takes to rest from a stop: its stop ramp, the master holding
        the last target until the servo has settled (at most SETTLE_CYCLES), disabling the axis
        (2 cycles), and one cycle more."""
        return self.ramp_s + (SETTLE_CYCLES + 3) * self.axis.cycle_s

    def to_rest(self) -> bool:
        """Bring the roll under way, if any, to rest by its stop ramp (begun now where no stop
        was commanded: a campaign that ended on a trial failed mid-roll, whose engine sends no
        stop of its own) and disable the axis, running on (SYNC in stand time): whether it did
        within `rest_limit_s` of stand time (a drive that keeps moving is not cycled longer)."""
        self._start_pending = False
        if self._rocking is not None:
            self._begin_stop()
        end = self.t_s + self.rest_limit_s
        while self.rocking and self.t_s < end:
            self._cycle()
        return not self.rocking

    def take_faults(self, until_ms: int | None = None) -> list[DriveFault]:
        """The drive faults so far (up to this run's stand time `until_ms`: later ones wait)."""
        cut = len(self._faults)
        if until_ms is not None:
            cut = sum(f.t_ms <= until_ms for f in self._faults)  # (in time order)
        faults, self._faults = self._faults[:cut], self._faults[cut:]
        return faults

    def _cycle(self) -> None:
        if self._start_pending:
            self._start_pending = False
            self._start()
        if self._rocking is None:
            self.axis.step(IDLE_CONTROLWORD, self.axis.actual)
        elif self._rocking.cycle():
            self._samples.append(
                (
                    self.axis.actual_t_s,
                    (self.axis.actual - self.zero_counts) / self.kinematics.counts_per_degree,
                )
            )
            self._check_failure()
        else:
            self._finish()

    def _status_due(self) -> None:
        """After every cycle, also those the axis runs itself (enabling, a fault reaction,
        settling at rest): a failure is told at once, a status when one is due."""
        if self._rocking is not None:
            self._check_failure()
        if self.t_ms >= self._next_status_ms:
            self._status()
            self._next_status_ms += STATUS_MS

    def _start(self) -> None:
        assert self._setting is not None
        K, A, tau = self._setting
        try:
            self.axis.enable()
        except DriveError as exc:  # (no ack: the fault fails the trial, naming the drive's error)
            self._fault("drive fault", str(exc))
            return
        roll = RollTrajectory(self.kinematics.amplitude_deg(A), tau, self.ramp_s)
        self._rocking = Rocking(
            self.axis, roll, self.kinematics.counts_per_degree, self.zero_counts
        )
        self._started_s = self.t_s
        self._samples.clear()
        self._reported = False
        self.on_motion(Motion(self.t_s, "start", K, A, tau))
        self._ack("start")

    def _check_failure(self) -> None:
        rocking = self._rocking
        assert rocking is not None
        if rocking.failure is None or self._reported:
            return
        self._reported = True
        code = "0x8611" in rocking.failure  # the drive's following-error trip (CiA 402)
        kind = "following error" if code else "drive fault"
        if "heartbeat" in rocking.failure:
            kind = "heartbeat lost"
        self._fault(kind, f"CiA 402 drive: {rocking.failure}")
        if self._setting is not None:
            self.on_motion(Motion(self.t_s, "stop", *self._setting))

    def _finish(self) -> None:
        """The roll ended (at rest after the stop ramp, or the drive's fault reaction)."""
        rocking = self._rocking
        assert rocking is not None
        rocking.finish()
        self._check_failure()
        self._rocking = None

    # -- statuses ---------------------------------------------------------------------------

    def _status(self) -> None:
        K, A_cmd, tau = self._setting or (0.0, 0.0, 0.0)
        rocking = self._rocking is not None  # (until at rest and disabled)
        amplitude_cm = period_s = cycles = 0.0
        if rocking:
            amplitude_cm, period_s = self._measured(tau)
            cycles = (self.t_s - self._started_s) / tau
        self._emit(
            self.codec.encode_status(
                self.t_ms,
                rocking,
                K,
                round(amplitude_cm, 2),
                round(period_s, 3),
                math.floor(cycles) % 32768,
                round((cycles % 1.0) * 360.0, 2) % 360.0,
            )
        )

    def _measured(self, tau: float) -> tuple[float, float]:
        """Amplitude (cm) and period (s) of the last MEASURE_PERIODS periods of the actual
        position; 0, 0 until that much has been rolled."""
        span = MEASURE_PERIODS * tau
        while self._samples and self._samples[0][0] < self.t_s - span - 1e-9:
            self._samples.popleft()
        if not self._samples or self.t_s - self._started_s < span:
            return 0.0, 0.0
        t, deg = np.array(self._samples).T
        try:
            fit = measure_roll(t, deg, tau)
        except RollFitError:
            return 0.0, 0.0
        return self.kinematics.amplitude_cm(fit.amplitude), fit.period_s
