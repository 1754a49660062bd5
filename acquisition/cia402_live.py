"""A CiA 402 stand on a real bus: gyrostand's master in real time (`campaign run` with
[stand] protocol = "cia402" and [bus] simulated = false).

The same stand adapter (`cia402_stand.Cia402Stand`), engine loop, store and raw log as the
simulated stand in virtual time (`cia402_run.run_cia402`, `cia402_sim.SimulatedCia402`); what
differs is where the cycles come from:

- SYNC: produced every `cycle_ms` by the bus's periodic sender (SocketCAN: the kernel's
  broadcast manager, BCM) on a bus handle of its own, so that the master's handle receives the
  SYNCs it produces on any interface (a SocketCAN socket does not receive its own frames). Each
  cycle the master sends the RPDO (controlword, CSP target) after the drive's TPDO of the last
  SYNC, so before the SYNC it applies to (`devices.cia402`, `sync="periodic"`).
- The cycles run in a thread of their own (`_Cycles`), so that the target stream and gyrostand's
  heartbeat go on while the engine digests a batch or the operator answers a prompt; the engine
  takes the stand's acks and statuses and the other devices' frames up to a stand time, as in
  virtual time.
- Stand time is the SYNC count x cycle_ms, as in virtual time. The compass's and the
  inclinometer's frames are timed by reception (SocketCAN: kernel timestamps): the SYNCs'
  reception times against their stand times are the reception clock's "statuses"
  (`devices.clock.ReceptionClock`: rate and minimum offset over the last SYNCs), which puts each
  frame's reception time on the stand clock.
- The raw log (`devices.cia402_log`) holds the drive's traffic in the order a replay's master
  reproduces it (`LiveTap`): each cycle's RPDO and heartbeat, then the SYNC and the drive's
  frames that cycle took, SDO answers as received; stamped with the run's stand time.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable

import can
import canopen
import numpy as np

from gyrostand.acquisition.bus import open_bus, request_identity
from gyrostand.acquisition.cia402_sim import LoggedFrames, merged
from gyrostand.acquisition.cia402_stand import Cia402Stand, DriveFault, axis_config
from gyrostand.acquisition.engine import Command
from gyrostand.devices.cia402 import CSP, Cia402Axis, DriveError, Frame
from gyrostand.devices.cia402_log import drive_ids, stamped_copy, wrap_send
from gyrostand.devices.clock import NO_CLOCK, ReceptionClock
from gyrostand.devices.roll_trajectory import Kinematics
from gyrostand.plan.codec import codec_for, drive_eds
from gyrostand.plan.model import Plan

SYNC_ID = 0x080
NOTIFIER_CYCLE_S = 0.05
SYNCS_KEPT = 100_000  # the last SYNCs' reception times (the benchmark's jitter)
STALL_S = 10.0  # wall seconds without a cycle: the stand is gone (the drive or the bus)


class LiveTap:
    """The live run's drive traffic in the raw log's order (`devices.cia402_log`): what the
    master sends as it sends it, the SYNCs and drive frames of each cycle as the cycle takes
    them (`Cia402Axis.on_frames`), the drive's SDO answers as they come; stamped by `clock`
    (the run's stand time)."""

    def __init__(self, network: canopen.Network, node_id: int, clock: Callable[[], float]) -> None:
        self.clock = clock
        self.frames: list[can.Message] = []
        self._lock = threading.Lock()
        wrap_send(network, lambda msg: None, self._add)
        network.subscribe(0x580 + node_id, self._on_sdo)

    def _add(self, msg: can.Message) -> None:
        with self._lock:
            self.frames.append(stamped_copy(msg, self.clock()))

    def _on_sdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        self._add(can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=False))

    def cycle(self, frames: list[Frame]) -> None:
        for f in frames:
            self._add(can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False))

    def take(self) -> list[can.Message]:
        with self._lock:
            frames, self.frames = self.frames, []
        return frames


class Received(can.Listener):
    """The other devices' frames on the stand's bus (compass, inclinometer) timed by reception
    on the stand clock: SYNC k (stand time k x cycle) received at r is a reception-clock status
    (`ReceptionClock`); each SYNC's reception time is kept (`sync_rx_s`, the benchmark's)."""

    def __init__(
        self, node_id: int, master_id: int, cycle_ms: int, sync_tpdo: int | None = None
    ) -> None:
        self.ignored = drive_ids(node_id, master_id)
        self.cycle_ms = cycle_ms
        # a synchronous TPDO (a CiA 410 inclinometer's, transmission type 1) samples at its SYNC:
        # its m-th frame answers SYNC m (the first SYNC comes after the device was started), at
        # that SYNC's stand time, not at a reception time a slow host delays
        self.sync_tpdo = sync_tpdo
        self._sync_answers = 0
        self.clock = ReceptionClock()
        self.syncs = 0
        self.sync_rx_s: deque[float] = deque(maxlen=SYNCS_KEPT)
        self._position = 0
        self._frames: list[can.Message] = []
        self._cond = threading.Condition()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame or msg.is_remote_frame:
            return
        with self._cond:
            self._position += 1
            pos, rx = np.array([self._position]), np.array([msg.timestamp])
            if not msg.is_extended_id and msg.arbitration_id == SYNC_ID:
                self.clock.observe(pos, np.array([self.syncs * self.cycle_ms]), rx)
                self.sync_rx_s.append(msg.timestamp)
                self.syncs += 1
                self._cond.notify_all()
            elif not msg.is_extended_id and msg.arbitration_id == self.sync_tpdo:
                self._frames.append(_received(msg, self._sync_answers * self.cycle_ms / 1000.0))
                self._sync_answers += 1
            elif msg.is_extended_id or msg.arbitration_id not in self.ignored:
                (t_ms,) = self.clock.to_campaign_ms(pos, rx)
                if t_ms != NO_CLOCK:  # (before the first SYNC: no stand time yet)
                    self._frames.append(_received(msg, t_ms / 1000.0))

    def take(self, t_s: float, wait_s: float) -> list[can.Message]:
        """The frames up to stand time `t_s`, once the SYNC after it was received (or `wait_s`
        of wall time passed), in reception order."""
        with self._cond:
            self._cond.wait_for(lambda: self.syncs * self.cycle_ms > t_s * 1000.0, wait_s)
            cut = next((i for i, m in enumerate(self._frames) if m.timestamp > t_s + 1e-9), None)
            cut = len(self._frames) if cut is None else cut
            frames, self._frames = self._frames[:cut], self._frames[cut:]
        return frames


def _received(msg: can.Message, t_s: float) -> can.Message:
    return can.Message(
        timestamp=t_s,
        arbitration_id=msg.arbitration_id,
        is_extended_id=msg.is_extended_id,
        dlc=msg.dlc,
        data=bytes(msg.data),
    )


class _Cycles(threading.Thread):
    """The stand's SYNC cycles, one after another as the drive answers, in a thread of its own;
    `lock` held for each cycle (the engine's commands wait for its end)."""

    def __init__(self, stand: Cia402Stand) -> None:
        super().__init__(name="cia402-cycles", daemon=True)
        self.stand = stand
        self.lock = threading.Condition()
        self.frames: list[can.Message] = []  # the stand's acks and statuses not yet taken
        self.error: str | None = None
        self._halt = threading.Event()

    def run(self) -> None:
        cycle_s = self.stand.axis.cycle_s
        try:
            while not self._halt.is_set():
                with self.lock:
                    self.frames += self.stand.advance_to(self.stand.t_s + cycle_s)
                    self.lock.notify_all()
        except (DriveError, can.CanError) as exc:
            with self.lock:
                self.error = str(exc)
                self.lock.notify_all()

    def halt(self) -> None:
        """End the thread after its cycle (the caller then runs the stand itself)."""
        self._halt.set()
        if self.is_alive() and threading.current_thread() is not self:
            self.join()

    def take(self, t_s: float) -> list[can.Message]:
        """The stand's frames up to stand time `t_s`, once the cycles have reached it."""
        with self.lock:
            ok = self.lock.wait_for(
                lambda: self.error is not None or self.stand.t_s >= t_s - 1e-9,
                max(0.0, t_s - self.stand.t_s) + STALL_S,
            )
            if self.error is not None or not ok:
                raise DriveError(f"the stand stopped cycling: {self.error or 'stalled'}")
            cut = next((i for i, m in enumerate(self.frames) if m.timestamp > t_s + 1e-9), None)
            cut = len(self.frames) if cut is None else cut
            frames, self.frames = self.frames[:cut], self.frames[cut:]
        return frames


class SharedStand:
    """The stand adapter as the engine's loop sees it (`run_cia402`): its time is the stand
    time fed so far; commands, faults and the last stop to rest under the cycles' lock."""

    def __init__(self, stand: Cia402Stand, cycles: _Cycles) -> None:
        self._stand = stand
        self._cycles = cycles
        self.t_s = 0.0  # the stand time of the frames fed to the engine so far

    @property
    def t_ms(self) -> int:
        return self._stand.t_ms

    @property
    def axis(self) -> Cia402Axis:
        return self._stand.axis

    def issue(self, command: Command, now_ms: int = 0) -> None:
        with self._cycles.lock:
            self._stand.issue(command, now_ms)

    def take_faults(self) -> list[DriveFault]:
        """The drive faults up to the stand time fed (later ones: with the next batch)."""
        with self._cycles.lock:
            return self._stand.take_faults(round(self.t_s * 1000.0))

    @property
    def rest_limit_s(self) -> float:
        return self._stand.rest_limit_s

    def to_rest(self) -> bool:
        """The cycles in this thread from here: the roll under way, if any, to rest."""
        self._cycles.halt()
        return self._stand.to_rest()


class LiveCia402(LoggedFrames):
    """gyrostand's master of the plan's CiA 402 drive on the plan's bus, and the stand adapter
    (`stand`) cycling in real time; the other devices' frames by reception."""

    def __init__(self, plan: Plan, clock_ms: int = 0) -> None:
        s = plan.stand
        assert s.node_id is not None and s.counts_per_degree and s.arm_length_cm
        config = axis_config(plan, drive_eds(plan), sync="periodic")
        self.codec = codec_for(plan)
        self.network = canopen.Network(open_bus(plan.bus))
        self.network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
        self._sync_bus: can.BusABC | None = None
        self.cycles: _Cycles | None = None
        inclinometer = plan.inclinometer
        sync_tpdo = None
        if inclinometer is not None and inclinometer.protocol == "cia410" and inclinometer.node_id:
            sync_tpdo = 0x180 + inclinometer.node_id  # its TPDO1, on SYNC
        self.received = Received(s.node_id, config.master_node_id, s.cycle_ms, sync_tpdo)
        super().__init__(clock_ms)
        try:
            self.network.connect()
            assert self.network.notifier is not None
            self.network.notifier.add_listener(self.received)
            self._sync_bus = open_bus(plan.bus)
            self.network.sync = canopen.sync.SyncProducer(canopen.Network(self._sync_bus))
            if inclinometer is not None and inclinometer.node_id is not None:
                self.network.send_message(0x000, bytes([0x01, inclinometer.node_id]))  # start
            self.axis = Cia402Axis(self.network, config)
            self.tap = LiveTap(self.network, s.node_id, lambda: self.axis.t_s)
            self.axis.on_frames = self.tap.cycle
            self.axis.start()  # (SYNC from here: the other devices' frames have a stand time)
            if self.axis.mode != CSP:
                raise DriveError(
                    f"drive {s.node_id} offers no cyclic synchronous position (0x6502): profile "
                    "position on a real bus is not supported yet"
                )
            if plan.compass.protocol == "nmea2000":  # its claim and product, heard anew (from
                request_identity(self._sync_bus)  # another handle: not the drive's traffic)
            kinematics = Kinematics(s.counts_per_degree, s.arm_length_cm)
            stand = Cia402Stand(self.axis, kinematics, s.ramp_s, self.codec, clock_ms=clock_ms)
            self.cycles = _Cycles(stand)
            self.stand = SharedStand(stand, self.cycles)
            self.cycles.start()
        except BaseException:
            self.close()
            raise

    def advance_to(self, t_s: float) -> list[can.Message]:
        """The stand's acks and statuses and the other devices' frames up to stand time `t_s`
        (waiting for the cycles to get there), in time order: what the engine takes."""
        assert self.cycles is not None
        frames = self.cycles.take(t_s)
        others = self.received.take(t_s, wait_s=1.0)
        self.stand.t_s = t_s
        return merged(frames, others, self._others)

    def close(self) -> None:
        if self.cycles is not None:
            self.cycles.halt()
        axis = self.__dict__.get("axis")
        if axis is not None:
            axis.close()  # (the SYNC producer stops)
        self.network.disconnect()
        if self._sync_bus is not None:
            self._sync_bus.shutdown()
