"""The simulated CiA 402 roll stand as a process on a real bus (`gyrostand simulate-drive --plan`):
the drive (`sim_drive`), a CiA 410 inclinometer on its platform (`sim_inclinometer`) when the plan
names one, and the compass on the platform speaking NMEA 2000 (the stand simulator's compass
physics, `stand.engine.StandEngine`, with the plan's [bus.simulator] parameters), all driven by
the master's SYNC: their stand time is the drive's (one communication cycle per SYNC).

The compass feels the roll the drive makes, not the one gyrostand commanded: once the axis is
enabled and its start ramp (the plan's ramp_s) is over, the platform's roll over the next
commanded period (the drive's sampled position times its kinematics error, as the inclinometer
sees it) is fitted (`analysis.measured_roll`), and the compass rolls from then at that amplitude
and period; it stops rolling when the axis is disabled again. The direction K is the operator's
(the compass turned by hand on a single-axis stand): the simulated operator turns it to the K of
the plan's trials in order, one trial per roll. Its frames carry no time: the master times them
by reception.
"""

from __future__ import annotations

import dataclasses

import can
import canopen
import numpy as np

from gyrostand.analysis.measured_roll import RollFitError, measure_roll
from gyrostand.devices.roll_trajectory import Kinematics
from gyrostand.devices.sim_drive import OPERATION_ENABLED, DriveFaults, SimDrive
from gyrostand.devices.sim_inclinometer import SimInclinometer
from gyrostand.plan.model import Plan
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec

SYNC_ID = 0x080
LATE_S = 0.2  # compass samples older than this at a SYNC are not sent (no bus time then)
MOVED_DEG = 0.01  # the axis enabled and the platform this far from where it was: a roll


class PlatformCompass(can.Listener):
    """The compass on the drive's platform: advanced to the drive's stand time at each SYNC
    (after the drive's own answer), its frames sent at once; it answers ISO requests."""

    def __init__(
        self,
        drive: SimDrive,
        compass: StandEngine,
        codec: Codec,
        kinematics: Kinematics,
        trials: list[tuple[float, float]],
        ramp_s: float,
    ) -> None:
        self.drive = drive
        self.compass = compass
        self.codec = codec
        self.kinematics = kinematics
        self.trials = trials  # (K deg, commanded tau s) of the plan's trials, in order
        self.ramp_s = ramp_s
        self.rolls = 0  # rolls begun
        self.felt: list[tuple[float, float, float, float]] = []  # t, K, A cm, tau (each roll)
        self._enabled_s: float | None = None
        self._level_deg: float | None = None  # the platform's angle when enabled, until it moves
        self._samples: list[tuple[float, float]] = []
        self._rocking = False
        drive.network.subscribe(SYNC_ID, self._on_sync)  # (after the drive's subscription)

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        drive = self.drive
        t = drive.t_s - drive._od(0x1006) * 1e-6  # the SYNC's stand time (sampled there)
        self._follow(t, drive.status == OPERATION_ENABLED)
        if t - self.compass.stand_time_s > LATE_S:  # (the first SYNC after a silence: what
            self.compass.pass_to(t - LATE_S)  # it would have sent then went unheard)
        self._send(self.compass.advance_to(t, compass_only=True))  # (its frames alone: sent)

    def _follow(self, t: float, enabled: bool) -> None:
        if not enabled:
            if self._rocking:
                self._command("stop", 0.0, 0.0, 0.0)
            self._enabled_s, self._rocking = None, False
            return
        cpd = self.kinematics.counts_per_degree
        angle = self.drive.platform_deg(cpd)
        if self._enabled_s is None:  # (the master also enables the axis once at its start)
            self._enabled_s, self._samples, self._level_deg = t, [], angle
        elif self._level_deg is not None and abs(angle - self._level_deg) > MOVED_DEG:
            self._level_deg = None  # it moves: a roll
            self.rolls += 1
        if self._rocking or self._level_deg is not None or self.rolls > len(self.trials):
            return
        direction, tau = self.trials[self.rolls - 1]
        since = t - self._enabled_s
        if since < self.ramp_s:
            return
        self._samples.append((t, angle))
        if since < self.ramp_s + tau:
            return
        times, angles = np.array(self._samples).T
        try:
            roll = measure_roll(times, angles, tau)
        except RollFitError:
            return
        amplitude = self.kinematics.amplitude_cm(roll.amplitude)
        self.felt.append((t, direction, amplitude, roll.period_s))
        self._command("set", direction, amplitude, roll.period_s)
        self._command("start", direction, amplitude, roll.period_s)
        self._rocking = True

    def _command(self, kind: str, direction: float, amplitude: float, period: float) -> None:
        self.compass.receive(self.codec.encode_command(kind, direction, amplitude, period))

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_extended_id and self.compass.for_compass(msg):
            self._send(self.compass.receive(msg))

    def _send(self, frames: list[can.Message]) -> None:
        bus = self.drive.network.bus
        assert bus is not None
        for m in frames:
            if m.is_extended_id:  # (the compass's own; not the simulator's stand frames)
                bus.send(can.Message(arbitration_id=m.arbitration_id, data=m.data))


@dataclasses.dataclass
class SimulatedStand:
    drive: SimDrive
    compass: PlatformCompass
    inclinometer: SimInclinometer | None

    def boot(self) -> None:
        self.drive.boot()
        if self.inclinometer is not None:
            self.inclinometer.boot()


def simulated_stand(
    plan: Plan, network: canopen.Network, faults: DriveFaults = DriveFaults()
) -> SimulatedStand:
    """The plan's simulated CiA 402 stand on `network` (connected): its drive (with `faults`
    and the kinematics error of [bus.simulator.faults] amplitude_factor), the plan's CiA 410
    inclinometer ([bus.simulator.inclinometer] bias and noise; a slope at every SYNC) and the
    compass ([bus.simulator]; seed [bus] seed)."""
    from gyrostand.acquisition.bus import transmitter
    from gyrostand.plan.codec import codec_for, stand_config

    s = plan.stand
    assert s.node_id is not None and s.counts_per_degree and s.arm_length_cm
    config = stand_config(plan)
    drive = SimDrive(network, s.node_id, faults=faults.scaled(config.faults.amplitude_factor))
    inclinometer = None
    i = config.inclinometer
    if i.node_id is not None and plan.inclinometer and plan.inclinometer.protocol == "cia410":
        inclinometer = SimInclinometer(
            drive,
            i.node_id,
            s.counts_per_degree,
            bias_deg=i.bias_deg,
            noise_deg=i.noise_deg,
            seed=config.seed,
        )
    # the platform's roll is the drive's (its kinematics error included): the compass rolls
    # at the amplitude it feels, not the simulator's amplitude_factor times it again
    faults_off = dataclasses.replace(config.faults, amplitude_factor=1.0)
    off = dataclasses.replace(config.inclinometer, node_id=None)
    config = dataclasses.replace(config, faults=faults_off, inclinometer=off)
    codec = codec_for(plan)
    engine = StandEngine(config, codec, transmitter=transmitter(plan))
    trials = [(t.direction_deg, t.period_s) for t in plan.trials]
    kinematics = Kinematics(s.counts_per_degree, s.arm_length_cm)
    compass = PlatformCompass(drive, engine, codec, kinematics, trials, s.ramp_s)
    assert network.notifier is not None
    network.notifier.add_listener(compass)
    return SimulatedStand(drive, compass, inclinometer)


class StandThread:
    """The plan's simulated stand on the plan's bus, served in a thread (tests, benchmarks: a
    master in the same process on python-can's virtual bus)."""

    def __init__(self, plan: Plan, faults: DriveFaults = DriveFaults()) -> None:
        import threading

        from gyrostand.devices.sim_drive import serve

        self.network = canopen.Network()
        self.network.connect(interface=plan.bus.interface, channel=plan.bus.channel)
        try:
            self.stand = simulated_stand(plan, self.network, faults)
            self.stand.boot()
        except BaseException:
            self.network.disconnect()
            raise
        self.stop = threading.Event()
        self.thread = threading.Thread(target=serve, args=(self.stand.drive, self.stop))
        self.thread.start()

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.network.disconnect()
