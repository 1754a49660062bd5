"""A simulated CiA 402 servo drive: the roll axis of a stand as a CANopen node (canopen's
LocalNode with the object dictionary of devices/data/sim-drive.eds).

It does what a real drive on the bus does and nothing more: NMT, the power state machine
(controlword 0x6040 / statusword 0x6041), cyclic synchronous position (mode 8: the target 0x607A
of RPDO1 applied on every SYNC) and profile position (mode 1: a set-point on controlword bit 4,
the drive ramps at 0x6081/0x6083/0x6084), TPDO1 (statusword, actual position 0x6064, mode display
0x6061) on every SYNC, heartbeat producer 0x1017 and consumer 0x1016 with the reaction of the
abort connection option code 0x6007, EMCY on every fault, following-error supervision (window
0x6065, time-out 0x6066; statusword bit 13, then a fault).

Virtual time: the drive has no clock of its own. Each SYNC is one communication cycle (0x1006) of
stand time; `advance` runs stand time without SYNC (a master that died). Its heartbeat is produced
in that time too, so a run is the same frames in the same order whatever the host's load.

Servo: the position demand (the CSP target, or the profile generator's output in PP and while
stopping) is followed by a second-order lag x'' = wn^2 (d - x) - 2 zeta wn x', acceleration
limited to 0x60C5 and velocity to 0x607F, integrated in fixed sub-steps of at most 1 ms.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

import canopen
from canopen.nmt import NMT_STATES

SIM_DRIVE_EDS = Path(str(files("gyrostand.devices") / "data" / "sim-drive.eds"))

# statusword values of the power states (CiA 402 / canopen's State402.SW_MASK), bit 4 voltage
# enabled where the power stage is on
SWITCH_ON_DISABLED = 0x40
READY_TO_SWITCH_ON = 0x31
SWITCHED_ON = 0x33
OPERATION_ENABLED = 0x37
QUICK_STOP_ACTIVE = 0x17
FAULT_REACTION_ACTIVE = 0x1F
FAULT = 0x08
SW_TARGET_REACHED = 1 << 10
SW_FOLLOWING = 1 << 12  # CSP: following the target; PP: set-point acknowledge
SW_FOLLOWING_ERROR = 1 << 13

CSP, PP = 8, 1
# EMCY error codes (CiA 301 / CiA 402)
EMCY_OVERCURRENT = 0x2310  # continuous over-current (the fault knob)
EMCY_HEARTBEAT = 0x8130  # life guard error or heartbeat error
EMCY_FOLLOWING_ERROR = 0x8611  # following error

_PARAMETERS = (0x1017, 0x6007, 0x6065, 0x6066, 0x607F, 0x6081, 0x6083, 0x6084, 0x6085, 0x60C5)
_NMT_CODE = {name: code for code, name in NMT_STATES.items()}


@dataclass(frozen=True)
class ServoModel:
    natural_hz: float = 10.0  # position loop bandwidth
    damping: float = 1.0
    max_substep_ms: float = 1.0


@dataclass(frozen=True)
class DriveFaults:
    """Fault knobs, at drive (stand) time in seconds since boot."""

    overcurrent_at_s: float | None = None  # an internal fault: EMCY 0x2310, fault reaction
    jam_at_s: float | None = None  # the axis seizes: the following error grows until it trips
    heartbeat_silent_at_s: float | None = None  # the drive's heartbeat producer stops
    silent_at_s: float | None = None  # the drive stops answering (power lost): no PDO, heartbeat
    platform_scale: float = 1.0  # platform roll / roll the encoder counts (kinematics error)

    def scaled(self, factor: float) -> DriveFaults:
        """These faults with the platform rolling `factor` times more again (the simulator's
        `amplitude_factor`)."""
        return dataclasses.replace(self, platform_scale=self.platform_scale * factor)


class SimDrive:
    """One CiA 402 axis on `network` (a canopen Network whose notifier calls it)."""

    def __init__(
        self,
        network: canopen.Network,
        node_id: int,
        *,
        eds: Path = SIM_DRIVE_EDS,
        servo: ServoModel = ServoModel(),
        faults: DriveFaults = DriveFaults(),
    ):
        self.node = canopen.LocalNode(node_id, str(eds))
        network.add_node(self.node)
        # heartbeat in stand time (`_tick`), not canopen's wall-clock periodic task
        self.node._write_callbacks.remove(self.node.nmt.on_write)
        self.node.add_write_callback(self._on_write)
        self.node.rpdo.read(from_od=True)
        self.node.rpdo.subscribe()
        self.node.tpdo.read(from_od=True)
        network.subscribe(0x80, self._on_sync)
        self.network = network
        self.servo = servo
        self.faults = faults
        self._lock = threading.RLock()
        self.t_s = 0.0
        self.x = 0.0  # actual position, counts (float; reported rounded)
        self.sampled_x = 0.0  # the position at the last SYNC
        self.v = 0.0  # counts/s
        self.demand = 0.0  # position demand, counts
        self.demand_v = 0.0
        self.status = SWITCH_ON_DISABLED
        self.mode = 0
        self.error_code = 0
        self.following_error_since_s: float | None = None
        self._controlword = 0
        self._pp_target: float | None = None
        self._producer_due_s = 0.0
        self._consumer_seen_s = 0.0
        self._consumer_id = 0
        self._consumer_ms = 0
        self._consumer_stale = True
        self.emcy_sent: list[int] = []
        self.syncs = 0

    # -- bus ----------------------------------------------------------------------------------

    def boot(self) -> None:
        """Power-up: boot-up message, PRE-OPERATIONAL (as if commanded), SWITCH ON DISABLED."""
        with self._lock:
            self.network.send_message(0x700 + self.node.id, bytes([0]))
            self.node.nmt.on_command(0, bytes([0x80, self.node.id]), 0.0)
            self._publish()

    def _od(self, index: int, sub: int = 0) -> int:
        obj = self.node.object_dictionary[index]
        od = obj if sub == 0 and isinstance(obj, canopen.objectdictionary.ODVariable) else obj[sub]
        return int(od.decode_raw(self.node.get_data(index, sub)))

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        # called before the value is stored: act on the new value
        if index == 0x1016:
            self._consumer_stale = True  # read again once stored
        if index == 0x6040:
            with self._lock:
                self._command(int.from_bytes(data, "little"))

    def _configure_consumer(self) -> None:
        self._consumer_stale = False
        if self._consumer_id:
            self.network.unsubscribe(0x700 + self._consumer_id, self._on_heartbeat)
        value = self._od(0x1016, 1)
        self._consumer_id = (value >> 16) & 0x7F
        self._consumer_ms = value & 0xFFFF
        if self._consumer_id:
            self.network.subscribe(0x700 + self._consumer_id, self._on_heartbeat)
        self._consumer_seen_s = math.inf  # CiA 301: monitoring begins at the first heartbeat

    def _on_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        with self._lock:
            self._consumer_seen_s = self.t_s

    def _silent(self) -> bool:
        return self.faults.silent_at_s is not None and self.t_s >= self.faults.silent_at_s

    def _operational(self) -> bool:
        return self.node.nmt.state == "OPERATIONAL"

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        """A SYNC: apply RPDO1, send TPDO1, run one communication cycle."""
        with self._lock:
            self.syncs += 1
            if self._operational() and not self._silent():
                rpdo = self.node.rpdo[1]
                if rpdo.is_received:  # a synchronous RPDO: applied on this SYNC
                    rpdo.is_received = False
                    self.mode = int(rpdo["Modes of operation"].raw)
                    target = int(rpdo["Target position"].raw)
                    self.node.set_data(0x607A, 0, rpdo["Target position"].get_data())
                    self._command(int(rpdo["Controlword"].raw))
                    if self.status == OPERATION_ENABLED and self.mode == CSP:
                        self.demand = float(target)
                # TPDO1: the state after this SYNC's command, the position sampled at the SYNC
                self.sampled_x = self.x
                self._publish()
                self.node.tpdo[1].transmit()
            self.advance(self._od(0x1006) * 1e-6)

    def _publish(self) -> None:
        """The objects the master reads (SDO or TPDO1), from the simulation's state."""
        status = self.status | (0x200)  # bit 9 remote
        if self.status == OPERATION_ENABLED:
            if self.mode == CSP:
                status |= SW_FOLLOWING
            else:
                if self._controlword & 0x10:  # PP: set-point acknowledge while bit 4 is set
                    status |= SW_FOLLOWING
                if self._pp_target is not None and self._pp_target == self.demand:
                    status |= SW_TARGET_REACHED
        if self.following_error_since_s is not None or self.error_code == EMCY_FOLLOWING_ERROR:
            status |= SW_FOLLOWING_ERROR
        values = {
            0x6041: status,
            0x6064: round(self.x),
            0x6061: self.mode,
            0x60F4: round(self.demand - self.x),
            0x603F: self.error_code,
        }
        for index, value in values.items():
            self.node.set_data(index, 0, self.node.object_dictionary[index].encode_raw(value))
        tpdo = self.node.tpdo[1]
        tpdo["Statusword"].raw = status
        tpdo["Position actual value"].raw = round(self.x)
        tpdo["Modes of operation display"].raw = self.mode

    # -- power state machine (CiA 402 controlword commands) -----------------------------------

    def _command(self, cw: int) -> None:
        previous, self._controlword = self._controlword, cw
        s = self.status
        if s == FAULT:
            if cw & 0x80 and not previous & 0x80:  # fault reset: rising edge of bit 7
                self.status, self.error_code = SWITCH_ON_DISABLED, 0
                self.node.emcy.reset()
            return
        if s == FAULT_REACTION_ACTIVE or cw & 0x80:
            return
        if cw & 0x02 == 0:  # disable voltage
            self._power_off()
        elif cw & 0x04 == 0:  # quick stop
            if s == OPERATION_ENABLED:
                self._begin_stop(QUICK_STOP_ACTIVE)
            elif s != QUICK_STOP_ACTIVE:
                self._power_off()
        elif cw & 0x0F == 0x06:  # shutdown
            if s in (SWITCH_ON_DISABLED, SWITCHED_ON, OPERATION_ENABLED):
                self._power_off(READY_TO_SWITCH_ON)
        elif cw & 0x0F == 0x07:  # switch on / disable operation
            if s in (READY_TO_SWITCH_ON, OPERATION_ENABLED):
                self._power_off(SWITCHED_ON)
        elif cw & 0x0F == 0x0F and s in (SWITCHED_ON, QUICK_STOP_ACTIVE):  # enable operation
            self.status = OPERATION_ENABLED
            self.demand, self.demand_v = self.x, 0.0
            self._pp_target = None
        new_set_point = cw & 0x10 and not previous & 0x10  # PP: rising edge of bit 4
        if self.status == OPERATION_ENABLED and self.mode == PP and new_set_point:
            self._pp_target = float(self._od(0x607A))

    def _power_off(self, status: int = SWITCH_ON_DISABLED) -> None:
        """The power stage off: the holding brake stops the axis where it is."""
        self.status = status
        self.v = self.demand_v = 0.0
        self.demand = self.x
        self.following_error_since_s = None

    def _fault(self, code: int) -> None:
        if self.status in (FAULT, FAULT_REACTION_ACTIVE):
            return
        self.error_code = code
        self.emcy_sent.append(code)
        self.node.emcy.send(code, 0x01)  # error register bit 0: generic error
        if self.status in (OPERATION_ENABLED, QUICK_STOP_ACTIVE):
            self._begin_stop(FAULT_REACTION_ACTIVE)
        else:
            self.status = FAULT

    def _begin_stop(self, status: int) -> None:
        """Quick stop or fault reaction: the demand ramps from the axis's motion to rest."""
        if self.status not in (QUICK_STOP_ACTIVE, FAULT_REACTION_ACTIVE):
            self.demand, self.demand_v = self.x, self.v
        self.status = status

    # -- stand time ---------------------------------------------------------------------------

    def advance(self, seconds: float) -> None:
        """Run `seconds` of stand time: servo, supervision, heartbeat."""
        with self._lock:
            n = max(1, math.ceil(seconds * 1000.0 / self.servo.max_substep_ms - 1e-9))
            dt = seconds / n
            self._p = {i: self._od(i) for i in _PARAMETERS}  # the drive reads them per cycle
            for _ in range(n):
                self._tick(dt)
            self._publish()

    def _tick(self, dt: float) -> None:
        f = self.faults
        self.t_s += dt
        if self._consumer_stale:
            self._configure_consumer()
        if f.overcurrent_at_s is not None and self.t_s >= f.overcurrent_at_s:
            self._fault(EMCY_OVERCURRENT)
        self._consume_heartbeat()
        self._move(dt)
        self._supervise_following()
        if self.status == FAULT_REACTION_ACTIVE and self.at_rest:
            self._power_off(FAULT)
        hb_ms = self._p[0x1017]
        silent = self._silent() or (
            f.heartbeat_silent_at_s is not None and self.t_s >= f.heartbeat_silent_at_s
        )
        if hb_ms and self.t_s >= self._producer_due_s - 1e-9:
            self._producer_due_s = self.t_s + hb_ms / 1000.0
            if not silent:
                state = _NMT_CODE[self.node.nmt.state]
                self.network.send_message(0x700 + self.node.id, bytes([state]))

    def _consume_heartbeat(self) -> None:
        if not self._consumer_id or not self._consumer_ms:
            return
        if self.t_s - self._consumer_seen_s <= self._consumer_ms / 1000.0:
            return
        self._consumer_seen_s = math.inf  # one event per loss (until the master is heard)
        self.error_code = EMCY_HEARTBEAT
        self.emcy_sent.append(EMCY_HEARTBEAT)
        self.node.emcy.send(EMCY_HEARTBEAT, 0x10)  # error register bit 4: communication
        action = self._p[0x6007]  # abort connection option code
        if action == 1:
            self._fault(EMCY_HEARTBEAT)
        elif action == 2:
            self._power_off()
        elif action == 3 and self.status == OPERATION_ENABLED:
            self._begin_stop(QUICK_STOP_ACTIVE)

    def _move(self, dt: float) -> None:
        if self.status in (QUICK_STOP_ACTIVE, FAULT_REACTION_ACTIVE):
            self._ramp_demand(dt, None, self._p[0x6085])
        elif self.status == OPERATION_ENABLED and self.mode == PP and self._pp_target is not None:
            self._ramp_demand(dt, self._pp_target, self._p[0x6084])
        elif self.status != OPERATION_ENABLED:
            return
        if self.faults.jam_at_s is not None and self.t_s >= self.faults.jam_at_s:
            self.v = 0.0
            return
        wn = 2.0 * math.pi * self.servo.natural_hz
        a = wn * wn * (self.demand - self.x) - 2.0 * self.servo.damping * wn * self.v
        a_max = float(self._p[0x60C5])
        v_max = float(self._p[0x607F])
        self.v = max(-v_max, min(v_max, self.v + max(-a_max, min(a_max, a)) * dt))
        self.x += self.v * dt

    def _ramp_demand(self, dt: float, target: float | None, decel: float) -> None:
        """Profile generator: toward `target` at profile velocity/acceleration, or (None) to rest
        at `decel`."""
        if target is None:
            dv = decel * dt
            self.demand_v = (
                0.0
                if abs(self.demand_v) <= dv
                else self.demand_v - math.copysign(dv, self.demand_v)
            )
            self.demand += self.demand_v * dt
            return
        v_max, accel = float(self._p[0x6081]), float(self._p[0x6083])
        remaining = target - self.demand
        stop_distance = self.demand_v**2 / (2.0 * decel)
        if abs(remaining) <= abs(self.demand_v) * dt and abs(self.demand_v) <= decel * dt:
            self.demand, self.demand_v = target, 0.0
            return
        if abs(remaining) <= stop_distance and self.demand_v * remaining > 0:
            wanted = 0.0
            rate = decel
        else:
            wanted = math.copysign(v_max, remaining)
            rate = accel
        step = max(-rate * dt, min(rate * dt, wanted - self.demand_v))
        self.demand_v += step
        self.demand += self.demand_v * dt

    def _supervise_following(self) -> None:
        if self.status != OPERATION_ENABLED:
            self.following_error_since_s = None
            return
        if abs(self.demand - self.x) <= self._p[0x6065]:
            self.following_error_since_s = None
            return
        if self.following_error_since_s is None:
            self.following_error_since_s = self.t_s
        elif self.t_s - self.following_error_since_s >= self._p[0x6066] / 1000.0:
            self._fault(EMCY_FOLLOWING_ERROR)

    @property
    def at_rest(self) -> bool:
        """No demanded motion and the axis settled (below 1 count/s)."""
        return self.demand_v == 0.0 and abs(self.v) < 1.0

    def platform_deg(self, counts_per_degree: float) -> float:
        """The platform's true roll at the last SYNC (what an inclinometer on it sees), for the
        plan's counts per degree: the encoder's angle times the kinematics error."""
        with self._lock:
            return self.sampled_x / counts_per_degree * self.faults.platform_scale


def serve(
    drive: SimDrive, stop: threading.Event, poll_s: float = 0.02, grace_s: float = 1.0
) -> None:
    """Run a drive in a process of its own until `stop`: stand time follows the master's SYNC;
    once no SYNC has come for `grace_s` of wall time (the master stopped or died, not merely
    late on a loaded host) it follows the wall clock from the last SYNC, so the heartbeat
    consumer notices a dead master as a real drive would."""
    seen, last_sync, advanced_s = drive.syncs, time.monotonic(), 0.0
    while not stop.wait(poll_s):
        now = time.monotonic()
        if drive.syncs != seen:
            seen, last_sync, advanced_s = drive.syncs, now, 0.0
            continue
        silent_s = now - last_sync
        if silent_s >= grace_s:
            drive.advance(silent_s - advanced_s)
            advanced_s = silent_s
