"""gyrostand as the CANopen master of a CiA 402 roll axis (canopen's RemoteNode).

Setup (SDO, PRE-OPERATIONAL): the communication cycle 0x1006 and interpolation period 0x60C2,
the drive's heartbeat producer 0x1017, its consumer 0x1016 of gyrostand's heartbeat with the
abort connection option code 0x6007 = 3 (quick stop when gyrostand falls silent), the mode 0x6060
(8 cyclic synchronous position if 0x6502 offers it, else 1 profile position), the PDO mapping read
back from the drive. Then NMT start and the power state machine to OPERATION ENABLED.

Every cycle: RPDO1 (controlword, target, mode), gyrostand's heartbeat when due, SYNC, and the
drive's TPDO1 (statusword, actual position) of that SYNC. With `sync="lockstep"` gyrostand sends
each SYNC itself after the RPDO (virtual time: a simulated drive runs one cycle of stand time per
SYNC, so a run is deterministic); with `sync="periodic"` the bus's periodic sender produces SYNC
every `cycle_ms` (kernel timed on SocketCAN) and each RPDO is written after the TPDO of the
previous SYNC.

Supervision: the drive's heartbeat (lost after 3 producer periods without one), EMCY, statusword
bit 13 (following error) and the FAULT state are events; a fault or a lost drive fails the
rocking. A stop request (Ctrl-C, SIGTERM, the station, a failed trial) starts the trajectory's
stop ramp; at rest the axis is disabled (shutdown, then disable voltage).
"""

from __future__ import annotations

import logging
import math
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import canopen
import numpy as np
from canopen.emcy import EmcyError
from canopen.profiles.p402 import State402

from gyrostand.devices.roll_trajectory import RollTrajectory

if TYPE_CHECKING:
    from gyrostand.devices.cia410 import Cia410Inclinometer

CSP, PP = 8, 1
SDO_ERRORS = (canopen.SdoAbortedError, canopen.SdoCommunicationError)
_SUPPORTS = {CSP: 1 << 7, PP: 1 << 0}  # 0x6502 bits
SW_FOLLOWING_ERROR = 1 << 13
ANSWER_TIMEOUT_S = 2.0  # wall-clock bound on a drive's answer (a dead drive, not a timing)
BOOT_S = 60.0  # wall seconds a drive that does not answer yet may take to boot (CiA 302)
HEARTBEAT_MISSES = 3  # a heartbeat is lost after this many producer periods
MASTER_NODE_ID = 127  # the node id of gyrostand's heartbeat (the drive consumes it)
SETTLE_CYCLES = 200  # cycles the master holds the last target at most for the servo to settle


class DriveError(RuntimeError):
    """The drive refused or could not do what the master needs (one line)."""


def power_state(statusword: int) -> str:
    """The CiA 402 power state a statusword shows."""
    for state, (mask, value) in State402.SW_MASK.items():
        if statusword & mask == value:
            return state
    return "UNKNOWN"


@dataclass(frozen=True)
class AxisConfig:
    node_id: int
    eds: Path
    cycle_ms: int = 10
    master_node_id: int = MASTER_NODE_ID
    heartbeat_ms: int = 100  # gyrostand's and the drive's heartbeat producer period
    drive_timeout_ms: int = 300  # the drive's consumer time of gyrostand's heartbeat
    sync: Literal["lockstep", "periodic"] = "lockstep"


@dataclass(frozen=True)
class AxisEvent:
    t_s: float  # stand time (cycles since the axis was started)
    kind: Literal["emcy", "following_error", "fault", "heartbeat_lost", "stop"]
    detail: str


@dataclass(frozen=True)
class RollRecord:
    """One rocking on the axis: per SYNC, the stand time, commanded and actual position."""

    t_s: np.ndarray
    target_counts: np.ndarray
    actual_counts: np.ndarray
    slope_deg: np.ndarray  # the inclinometer's slope at each SYNC (empty without one)
    events: tuple[AxisEvent, ...]
    failure: str | None  # why the rocking failed (the drive's error named), None if it did not
    stopped_by: str | None  # what started the stop ramp early, None for the planned end


@dataclass(frozen=True)
class Frame:
    """A frame from the drive (TPDO1, EMCY, heartbeat) or a SYNC, as the master received it."""

    can_id: int
    data: bytes
    rx_s: float  # its reception time (the bus's timestamp)


class Cia402Axis:
    """The roll axis: a drive on `network` (connected), commanded in stand-time cycles."""

    def __init__(
        self,
        network: canopen.Network,
        config: AxisConfig,
        inclinometer: Cia410Inclinometer | None = None,
    ):
        """`inclinometer`: on the same bus and SYNC, started before the axis."""
        self.network = network
        self.inclinometer = inclinometer
        self.slope_deg = float("nan")
        self.config = config
        self.node = canopen.RemoteNode(config.node_id, str(config.eds))
        # canopen waits 0.3 s for an SDO answer: too short for a simulated drive on a loaded host
        self.node.sdo.RESPONSE_TIMEOUT = ANSWER_TIMEOUT_S
        network.add_node(self.node)
        self.cycle_s = config.cycle_ms / 1000.0
        self.cycle = 0  # SYNCs sent (lockstep) or received
        self.mode = CSP
        self.statusword = 0
        self.actual = 0
        self.stop_requested: str | None = None
        # the drive's frames and the SYNCs in the order of reception (the notifier thread's)
        self._inbox: deque[Frame] = deque()
        self._arrived = threading.Condition()
        self.late_cycles = 0  # SYNC cycles the master was too late to send a set-point for
        self.answers = 0  # the drive's TPDO1s taken (the answer k is to SYNC k)
        self._events: list[AxisEvent] = []
        self._since = 0  # the events of the current rocking start here
        self._heartbeat_cycle = 0
        self._drive_heard_cycle = 0
        self._target = 0
        self.on_cycle: Callable[[], None] = lambda: None  # after every cycle (a stand's status)
        # the frames each cycle took, in order (a live run's raw log, `acquisition.cia402_live`)
        self.on_frames: Callable[[list[Frame]], None] = lambda frames: None
        self.sync_rx_s = math.nan  # the reception time of the last SYNC taken (periodic)

    @property
    def t_s(self) -> float:
        return self.cycle * self.cycle_s

    @property
    def answer_timeout_s(self) -> float:
        """Wall seconds without the drive's TPDO1 after which it is taken for silent: as long as
        its heartbeat may be missing (HEARTBEAT_MISSES periods), at least ANSWER_TIMEOUT_S."""
        return max(ANSWER_TIMEOUT_S, HEARTBEAT_MISSES * self.config.heartbeat_ms / 1000.0)

    @property
    def actual_t_s(self) -> float:
        """The stand time of `actual` (on the convention of `t_s`: the cycle after its SYNC):
        live, a drive that answers late gives the position of an earlier SYNC than the last one
        received (its TPDO1s answer the SYNCs in order); in lockstep `t_s`."""
        return self.answers * self.cycle_s

    # -- setup ----------------------------------------------------------------------------

    def start(self) -> None:
        """Configure the drive, NMT start, OPERATION ENABLED. DriveError names what failed."""
        c, sdo = self.config, self.node.sdo
        try:
            supported = self._await_boot()
            modes = [m for m in (CSP, PP) if supported & _SUPPORTS[m]]
            if not modes:
                raise DriveError(
                    f"drive {c.node_id} offers neither cyclic synchronous nor profile position "
                    f"(0x6502 = 0x{supported:08X})"
                )
            self.mode = modes[0]
            sdo[0x1006].raw = c.cycle_ms * 1000
            sdo[0x60C2][1].raw = c.cycle_ms
            sdo[0x60C2][2].raw = -3  # 10^-3 s
            sdo[0x1017].raw = c.heartbeat_ms
            sdo[0x1016][1].raw = (c.master_node_id << 16) | c.drive_timeout_ms
            sdo[0x6007].raw = 3  # abort connection: quick stop
            self.node.pdo.read()  # the drive's own mapping, by SDO
        except SDO_ERRORS as exc:
            raise DriveError(f"drive {c.node_id} refused its configuration: {exc}") from None
        self._check_mapping()
        rpdo, tpdo = self.node.rpdo[1], self.node.tpdo[1]
        self._tpdo_id, self._emcy_id = tpdo.cob_id, 0x80 + c.node_id
        ids = [self._tpdo_id, self._emcy_id, 0x700 + c.node_id]
        for cob_id in ids + ([0x80] if c.sync == "periodic" else []):
            self.network.subscribe(cob_id, self._on_frame)
        rpdo["Modes of operation"].raw = self.mode
        self.node.nmt.state = "OPERATIONAL"
        if c.sync == "periodic":
            self.network.sync.start(self.cycle_s)
        self._enable()

    def _await_boot(self) -> int:
        """The drive's supported modes 0x6502, read once it answers (PRE-OPERATIONAL): a drive
        still booting (a simulated stand's process still starting) is waited for BOOT_S."""
        deadline = time.monotonic() + BOOT_S
        log = logging.getLogger("canopen.sdo.client")  # (its line for each unanswered try)
        log.disabled = True
        try:
            while True:
                self.node.nmt.state = "PRE-OPERATIONAL"
                try:
                    return int(self.node.sdo[0x6502].raw)
                except canopen.SdoCommunicationError:
                    if time.monotonic() > deadline:
                        raise DriveError(
                            f"drive {self.config.node_id} did not answer within {BOOT_S:g} s "
                            f"(is it powered, on this bus, with node id {self.config.node_id}?)"
                        ) from None
        finally:
            log.disabled = False

    def _check_mapping(self) -> None:
        need = {"RPDO1": (self.node.rpdo[1], (0x6040, 0x607A, 0x6060))}
        need["TPDO1"] = (self.node.tpdo[1], (0x6041, 0x6064))
        for name, (pdo, indexes) in need.items():
            mapped = {var.index for var in pdo}
            missing = [f"0x{i:04X}" for i in indexes if i not in mapped]
            if missing or not pdo.enabled or not 1 <= (pdo.trans_type or 0) <= 240:
                raise DriveError(
                    f"drive {self.config.node_id}: {name} must be synchronous and map "
                    f"{', '.join(f'0x{i:04X}' for i in indexes)} (missing: {', '.join(missing)})"
                )

    def _enable(self, max_cycles: int = 200) -> None:
        self.step(0, 0)
        fault_reset = False
        for _ in range(max_cycles):
            state = power_state(self.statusword)
            if state == "OPERATION ENABLED":
                return
            if state == "FAULT":
                if fault_reset:
                    break  # it faults again: the drive's error code says why
                fault_reset = True  # one reset: 0, then bit 7 (a rising edge)
                self.step(State402.CW_DISABLE_VOLTAGE, self.actual)
                self.step(State402.CW_SWITCH_ON_DISABLED, self.actual)
                continue
            nxt = State402.next_state_indirect(state)
            if (state, "OPERATION ENABLED") in State402.TRANSITIONTABLE:
                nxt = "OPERATION ENABLED"
            code = State402.TRANSITIONTABLE.get((state, nxt))
            if code is None:
                break
            self.step(code, self.actual)
        raise DriveError(
            f"drive {self.config.node_id} did not reach OPERATION ENABLED "
            f"(state {power_state(self.statusword)}, error code 0x{self._error_code():04X})"
        )

    def _error_code(self) -> int:
        try:
            return int(self.node.sdo[0x603F].raw)
        except (*SDO_ERRORS, KeyError):
            return 0

    # -- notifier thread ------------------------------------------------------------------

    def _on_frame(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._arrived:
            self._inbox.append(Frame(can_id, bytes(data), timestamp))
            self._arrived.notify()

    def _answered(self, sent_s: float) -> bool:
        """Live (periodic SYNC): whether the drive's TPDO1 answering the first SYNC received
        after `sent_s` (the wall time the last RPDO was on the bus: the drive applies it at
        that SYNC at the earliest) is in. A lagging drive's answer to an older SYNC is not
        enough: the next RPDO would then reach the drive before the SYNC this one waits for,
        and overwrite it (a set-point lost: a fault reset's edge, a step of the power state
        machine). The drive's TPDO1s answer the SYNCs in order (its m-th, SYNC m)."""
        syncs, answers, due = self.cycle, self.answers, None
        for f in self._inbox:
            if f.can_id == 0x80:
                syncs += 1
                if due is None and f.rx_s > sent_s:
                    due = syncs
            elif f.can_id == self._tpdo_id:
                answers += 1
        return due is not None and answers >= due

    def _take(self, sent_s: float) -> list[Frame]:
        """The frames up to the drive's next TPDO1 (the answer to the next SYNC) in the order
        received; in lockstep also those the drive sent after it in that cycle (all arrived:
        the simulation's lockstep waits for them). Live (periodic SYNC), once the drive has
        answered the SYNC the RPDO sent at `sent_s` applies to (`_answered`), up to the last
        TPDO1 received: a master that fell behind goes on from the drive's latest state, the
        cycles it missed counted (`late_cycles`: no set-point of their own), the stand time
        advanced by the SYNCs received (`cycle`). A frame received after
        the TPDO1 of a live cycle is the next cycle's, so a replay (lockstep) takes the same
        frames in the same cycle as the live run did."""
        tpdo = self._tpdo_id
        if self.config.sync == "lockstep":
            ready: Callable[[], bool] = lambda: any(f.can_id == tpdo for f in self._inbox)  # noqa: E731
        else:
            ready = lambda: self._answered(sent_s)  # noqa: E731
        with self._arrived:
            if not self._arrived.wait_for(ready, self.answer_timeout_s):
                raise DriveError(
                    f"drive {self.config.node_id} sent no TPDO within "
                    f"{self.answer_timeout_s:g} s of a SYNC"
                )
            frames = list(self._inbox)
            if self.config.sync == "lockstep":
                cut = len(frames)
            else:
                cut = max(i for i, f in enumerate(frames) if f.can_id == tpdo) + 1
            for _ in range(cut):
                self._inbox.popleft()
        return frames[:cut]

    def _tpdo_values(self, data: bytes) -> tuple[int, int]:
        """Statusword and actual position from TPDO1's data (the drive's mapping)."""
        values = {}
        for var in self.node.tpdo[1]:
            start = var.offset // 8
            values[var.index] = int(var.od.decode_raw(data[start : start + var.length // 8]))
        return values[0x6041], values[0x6064]

    # -- one cycle ------------------------------------------------------------------------

    def step(self, controlword: int, target_counts: int) -> None:
        """One SYNC cycle: send the RPDO, (lockstep) the SYNC, take the drive's TPDO."""
        rpdo = self.node.rpdo[1]
        rpdo["Controlword"].raw = controlword
        rpdo["Target position"].raw = target_counts
        self._target = target_counts
        rpdo.transmit()
        sent_s = time.time()  # (after it is on the bus: a SYNC received later follows it)
        c = self.config
        if self.cycle >= self._heartbeat_cycle:
            self.network.send_message(0x700 + c.master_node_id, bytes([5]))  # OPERATIONAL
            self._heartbeat_cycle = self.cycle + max(1, round(c.heartbeat_ms / c.cycle_ms))
        if c.sync == "lockstep":
            self.network.sync.transmit()
        frames = self._take(sent_s)
        self.on_frames(frames)
        if self.inclinometer is not None:
            self.slope_deg = self.inclinometer.take()
        self.answers += sum(f.can_id == self._tpdo_id for f in frames)
        if c.sync == "lockstep":
            cycles = 1
        else:  # stand time is the SYNCs received (a TPDO lost or late does not stop it)
            cycles = sum(f.can_id == 0x80 for f in frames)
            self.late_cycles += max(0, cycles - 1)
        self.cycle += cycles
        self._supervise(frames)
        self.on_cycle()

    def _supervise(self, frames: list[Frame]) -> None:
        heard = False
        for f in frames:
            if f.can_id == self._tpdo_id:
                self.statusword, self.actual = self._tpdo_values(f.data)
            elif f.can_id == self._emcy_id:
                e = EmcyError(int.from_bytes(f.data[:2], "little"), f.data[2], f.data[3:], f.rx_s)
                if e.code:
                    self._event("emcy", f"EMCY 0x{e.code:04X} ({e.get_desc()})")
            elif f.can_id == 0x80:
                self.sync_rx_s = f.rx_s
            else:
                heard = True
        if heard:
            self._drive_heard_cycle = self.cycle
        silent_s = (self.cycle - self._drive_heard_cycle) * self.cycle_s
        limit_s = HEARTBEAT_MISSES * self.config.heartbeat_ms / 1000.0
        if silent_s > limit_s and not self._has("heartbeat_lost"):
            self._event("heartbeat_lost", f"no heartbeat from drive for {silent_s:.2f} s")
        if self.statusword & SW_FOLLOWING_ERROR and not self._has("following_error"):
            self._event("following_error", "statusword bit 13 (following error)")
        faulted = power_state(self.statusword) in ("FAULT", "FAULT REACTION ACTIVE")
        if faulted and not self._has("fault"):
            self._event("fault", f"drive fault, error code 0x{self._error_code():04X}")

    def _event(self, kind: str, detail: str) -> None:
        self._events.append(AxisEvent(self.t_s, kind, detail))  # type: ignore[arg-type]

    def _has(self, kind: str) -> bool:
        return any(e.kind == kind for e in self._events[self._since :])

    # -- rocking ----------------------------------------------------------------------------

    def rock(
        self,
        trajectory: RollTrajectory,
        counts_per_degree: float,
        zero_counts: int = 0,
        stop_check: Callable[[float], str | None] | None = None,
    ) -> RollRecord:
        """Run `trajectory` (its stop ramp set, or set by a stop request) from the axis's current
        cycle, then disable the axis at rest. `stop_check(t)` (the station's stop request) gives
        a reason to stop, or None; signals set `stop_requested`."""
        rocking = Rocking(self, trajectory, counts_per_degree, zero_counts, stop_check)
        while rocking.cycle():
            pass
        return rocking.finish()

    def enable(self) -> None:
        """To OPERATION ENABLED (a fault reset once if needed); DriveError names why not."""
        self._enable()

    def _failure(self) -> str | None:
        events = self._events[self._since :]
        for e in events:
            if e.kind in ("fault", "heartbeat_lost"):
                emcy = next((x.detail for x in events if x.kind == "emcy"), None)
                return f"{e.detail}" + (f": {emcy}" if emcy and e.kind == "fault" else "")
        return None

    def _load_profile(self, distance: float, duration_s: float) -> None:
        """Profile position: the triangular velocity profile that covers `distance` in
        `duration_s`, a = 4 d / T^2, v = a T / 2 = 2 d / T."""
        a = max(1, math.ceil(4.0 * distance / duration_s**2))
        self.node.sdo[0x6081].raw = max(1, math.ceil(a * duration_s / 2.0))
        self.node.sdo[0x6083].raw = a
        self.node.sdo[0x6084].raw = a

    def _await_fault_reaction(self, max_cycles: int = 3000) -> None:
        """The drive stops the axis itself (its fault reaction) and switches it off."""
        for _ in range(max_cycles):
            if power_state(self.statusword) == "FAULT":
                return
            self.step(State402.CW_OPERATION_ENABLED, self.actual)

    def _settle(self, controlword: int, max_cycles: int = SETTLE_CYCLES) -> None:
        """Hold the last target until the axis has stopped moving (the servo's lag settled)."""
        if power_state(self.statusword) != "OPERATION ENABLED":
            return
        target, previous = self._target, None
        for _ in range(max_cycles):
            if self.actual == previous:
                return
            previous = self.actual
            self.step(controlword, target)

    def _disable(self) -> None:
        """At rest: shutdown (power stage off), then disable voltage."""
        if power_state(self.statusword) not in ("FAULT", "FAULT REACTION ACTIVE"):
            self.step(State402.CW_SHUTDOWN, self.actual)
            self.step(State402.CW_DISABLE_VOLTAGE, self.actual)

    def close(self) -> None:
        if self.config.sync == "periodic":
            self.network.sync.stop()


class Rocking:
    """One rocking of the axis in progress, one SYNC cycle per `cycle()`, then `finish()`."""

    def __init__(
        self,
        axis: Cia402Axis,
        trajectory: RollTrajectory,
        counts_per_degree: float,
        zero_counts: int = 0,
        stop_check: Callable[[float], str | None] | None = None,
    ):
        self.axis = axis
        self.trajectory = trajectory
        self.counts_per_degree = counts_per_degree
        self.zero_counts = zero_counts
        self.stop_check = stop_check
        self.t0 = axis.t_s
        axis._since = len(axis._events)
        self.failure: str | None = None
        self.stopped_by: str | None = None
        self._rows: list[tuple[float, int, int, float]] = []  # t, target, actual, slope
        self._set_point, self._due = zero_counts, 0.0  # profile position: the current set-point

    def stop(self, reason: str | None = None) -> None:
        """Begin the stop ramp now: the planned end (None) or early, for `reason` (an event)."""
        t = self.axis.t_s - self.t0
        if t < self.trajectory.stop_at_s:
            self.trajectory = self.trajectory.stopped_at(t)
            if reason is not None:
                self.stopped_by = reason
                self.axis._event("stop", f"stop ramp: {reason}")

    def cycle(self) -> bool:
        """One SYNC cycle of the roll; False (nothing sent) once the roll has ended, or the
        drive faulted (its fault reaction then ran to the end)."""
        axis = self.axis
        t = axis.t_s - self.t0
        if self.stop_check is not None and axis.stop_requested is None:
            axis.stop_requested = self.stop_check(t)
        reason = axis.stop_requested or self.failure
        if reason:
            self.stop(reason)
        if t >= self.trajectory.end_s:
            return False
        cw = State402.CW_OPERATION_ENABLED
        cpd, zero = self.counts_per_degree, self.zero_counts
        if axis.mode == CSP:
            target = zero + round(cpd * float(self.trajectory.position_deg(t)))
            axis.step(cw, target)
        else:
            new = t >= self._due - 1e-9
            if new:
                self._due, peak_deg = _next_peak(self.trajectory, t)
                start, self._set_point = self._set_point, zero + round(cpd * peak_deg)
                axis._load_profile(abs(self._set_point - start), self._due - t)
            target = self._set_point
            axis.step(cw | (0x10 if new else 0), target)  # bit 4: new set-point
        self._rows.append((axis.t_s, target, axis.actual, axis.slope_deg))
        if self.failure is None:
            self.failure = axis._failure()
        if power_state(axis.statusword) in ("FAULT", "FAULT REACTION ACTIVE"):
            axis._await_fault_reaction()
            return False
        return True

    def finish(self) -> RollRecord:
        """The axis brought to rest and disabled; what the rocking did."""
        axis = self.axis
        axis._settle(State402.CW_OPERATION_ENABLED)
        axis._disable()
        t, target, actual, slope = zip(*self._rows, strict=True) if self._rows else ((), (), (), ())
        return RollRecord(
            np.asarray(t, dtype=float),
            np.asarray(target, dtype=np.int64),
            np.asarray(actual, dtype=np.int64),
            np.asarray(slope if axis.inclinometer is not None else [], dtype=float),
            tuple(axis._events[axis._since :]),
            self.failure,
            self.stopped_by,
        )


def _next_peak(trajectory: RollTrajectory, t: float) -> tuple[float, float]:
    """Profile position's next set-point after `t`: the sinusoid's next peak (t = tau/4 +
    k tau/2) and its angle, or the rest position at the trajectory's end."""
    quarter = trajectory.period_s / 4.0
    k = max(0, math.floor((t - quarter) / (2.0 * quarter) + 1e-9) + 1)
    peak = quarter + 2.0 * quarter * k
    if peak + quarter > trajectory.end_s:  # the last segment: back to rest at the end
        return trajectory.end_s, 0.0
    return peak, float(trajectory.position_deg(peak))


@contextmanager
def stop_on_signals(axis: Cia402Axis) -> Iterator[None]:
    """Ctrl-C and SIGTERM start the axis's stop ramp instead of killing gyrostand mid-roll."""

    def handler(signum: int, frame: object) -> None:
        axis.stop_requested = signal.Signals(signum).name

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
