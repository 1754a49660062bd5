"""The simulated CiA 402 stand in virtual time, and the engine fed from it in lockstep.

On an in-process virtual CAN bus: the simulated drive (`devices.sim_drive`, its own canopen
network) and gyrostand's master (`devices.cia402`, another one), the master sending every SYNC
itself (`sync="lockstep"`): each SYNC is one communication cycle of stand time for the drive, so
the roll is the same whatever the host's load; after each frame it sends the master waits for
the drive's answers (`cia402_log.BusTap`, which records the traffic for the raw log). The
compass on the platform is the stand simulator's compass physics (`stand.engine.StandEngine`,
the plan's [bus.simulator]) speaking a real protocol timed by reception (NMEA 2000: a CiA 402
stand has no clock to put in a compass frame); its rolling error follows the platform's motion
as the master commands it (the roll begins, the stop ramp begins), at the platform's true
amplitude (the commanded one times the simulator's `faults.amplitude_factor`, which the drive's
encoder does not see: its `platform_scale`). With a CiA 410 [inclinometer] in the plan, the
simulated one (`stand.inclinometer`, [bus.simulator.inclinometer]'s noise, bias, rate and
faults) sends the platform's true roll: the drive's position at each SYNC times that scale."""

from __future__ import annotations

import bisect
import dataclasses
import uuid
from collections.abc import Iterator
from typing import TYPE_CHECKING

import can
import canopen
import numpy as np

from gyrostand.acquisition.bus import transmitter
from gyrostand.acquisition.cia402_stand import Cia402Stand, DriveFault, Motion, axis_config
from gyrostand.acquisition.engine import Command, Engine, Phase
from gyrostand.analysis.measured_motion import DRIVE_POSITION
from gyrostand.devices.cia402 import Cia402Axis, DriveError
from gyrostand.devices.cia402_log import RUN, STEP, BusTap, record
from gyrostand.devices.decoder import SourceDecoder, frame_decoder
from gyrostand.devices.roll_trajectory import Kinematics
from gyrostand.devices.sim_drive import SIM_DRIVE_EDS, DriveFaults, ServoModel, SimDrive
from gyrostand.frames.batch import BatchDecoder, FrameBatch, RawFrames
from gyrostand.plan.codec import codec_for, stand_config
from gyrostand.plan.model import Plan
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.inclinometer import SimInclinometerFrames

if TYPE_CHECKING:
    from gyrostand.acquisition.cia402_live import LiveCia402, LiveTap, SharedStand

STEP_S = 5.0  # stand time per batch fed to the engine


class LoggedFrames:
    """A CiA 402 stand's raw log frames (`cia402_log`): its `tap`'s drive traffic, the other
    devices' frames (`_others`, as `merged` gave them to the engine) and the master's records."""

    tap: BusTap | LiveTap
    stand: Cia402Stand | SharedStand

    def __init__(self, clock_ms: int) -> None:
        self._others: list[can.Message] = []  # the compass's and inclinometer's, not yet logged
        self._run_record: can.Message | None = record(RUN, clock_ms, 0.0)

    def take_logged(self, step: bool = True) -> list[can.Message]:
        """The raw log's frames since the last call (`cia402_log`): the drive's CANopen
        traffic, the compass's and inclinometer's frames, and the master's records (RUN first,
        STEP at the end of a batch the engine was fed; `step` False after the last one)."""
        frames = sorted(self.tap.take() + self._others, key=lambda m: m.timestamp)
        self._others = []
        if self._run_record is not None:
            frames.insert(0, self._run_record)
            self._run_record = None
        if step:
            frames.append(record(STEP, round(self.stand.t_s * 1e6), self.stand.t_s))
        return frames


class SimulatedCia402(LoggedFrames):
    """The simulated drive and compass with gyrostand's master and the stand adapter."""

    def __init__(
        self,
        plan: Plan,
        drive_faults: DriveFaults = DriveFaults(),
        servo: ServoModel = ServoModel(),
        clock_ms: int = 0,
    ) -> None:
        """`clock_ms`: the campaign clock at this run's first SYNC (a resumed campaign's)."""
        s = plan.stand
        assert s.node_id is not None and s.counts_per_degree and s.arm_length_cm
        config = stand_config(plan)
        channel = f"gyrostand-cia402-{uuid.uuid4().hex}-sim"
        self._networks = (canopen.Network(), canopen.Network())
        for net in self._networks:
            net.NOTIFIER_CYCLE = 0.05  # a quick disconnect
            net.connect(interface="virtual", channel=channel)
        drive_net, master_net = self._networks
        self.tap = BusTap(master_net, drive_net, self._stand_s)
        super().__init__(clock_ms)
        try:
            self.drive = SimDrive(
                drive_net,
                s.node_id,
                servo=servo,
                faults=drive_faults.scaled(config.faults.amplitude_factor),
            )
            self.drive.boot()
            self.axis = Cia402Axis(master_net, axis_config(plan, SIM_DRIVE_EDS))
            self.axis.start()
        except BaseException:
            self.close()
            raise
        self.codec = codec_for(plan)
        off = dataclasses.replace(config.inclinometer, node_id=None)  # (ours below)
        compass = dataclasses.replace(config, inclinometer=off)
        self.compass = StandEngine(compass, self.codec, transmitter=transmitter(plan))
        kinematics = Kinematics(s.counts_per_degree, s.arm_length_cm)
        self.stand = Cia402Stand(
            self.axis, kinematics, s.ramp_s, self.codec, self._motion, clock_ms
        )
        self._compass_frames: list[can.Message] = []
        self.inclinometer: SimInclinometerFrames | None = None
        self._platform: tuple[list[float], list[float]] = ([], [])  # SYNC stand s, roll deg
        if config.inclinometer.node_id is not None:
            seed = np.random.SeedSequence(config.seed).spawn(4)[3]  # the smart stand's one
            self.inclinometer = SimInclinometerFrames(
                config.inclinometer, np.random.default_rng(seed)
            )
            status_due = self.axis.on_cycle

            def on_cycle() -> None:
                self._sample_platform(s.counts_per_degree)
                status_due()

            self.axis.on_cycle = on_cycle

    def _stand_s(self) -> float:
        """The run's stand time (0 while the drive boots and is set up)."""
        axis = self.__dict__.get("axis")
        return axis.t_s if axis is not None else 0.0

    def _sample_platform(self, counts_per_degree: float) -> None:
        """The platform's true roll at the SYNC whose TPDO the master just took."""
        t, deg = self._platform
        t.append(self.axis.t_s - self.axis.cycle_s)
        deg.append(self.drive.platform_deg(counts_per_degree))

    def _inclinometer_frames(self) -> list[can.Message]:
        """The inclinometer's frames up to the last SYNC sampled (its roll between SYNCs
        interpolated), the samples before then dropped."""
        t, deg = self._platform
        if self.inclinometer is None or not t:
            return []
        times, angles = np.array(t), np.radians(deg)
        frames = self.inclinometer.frames(t[-1], lambda at: np.interp(at, times, angles))
        self._platform = ([t[-1]], [deg[-1]])
        return frames

    def _motion(self, m: Motion) -> None:
        """The compass's rolling error follows the platform: its simulation runs up to the
        change, which then takes effect (its own acks and stand frames are not sent)."""
        self._compass_frames += self._compass_only(self.compass.advance_to(m.t_s))
        self.compass.receive(
            self.codec.encode_command(m.kind, m.direction_deg, m.amplitude_cm, m.period_s)
        )

    @staticmethod
    def _compass_only(msgs: list[can.Message]) -> list[can.Message]:
        """The compass's own frames (29-bit NMEA 2000), not the simulator's stand frames (nor
        its inclinometer's, which rolls with the simulator's idea of the platform)."""
        return [m for m in msgs if m.is_extended_id]

    def advance_to(self, t_s: float) -> list[can.Message]:
        """Every frame of the stand (the master's acks and statuses), the compass and the
        inclinometer up to stand time `t_s`, in time order: what the engine takes."""
        frames = self.stand.advance_to(t_s)
        others = self._inclinometer_frames() + self._compass_frames
        others += self._compass_only(self.compass.advance_to(t_s))
        self._compass_frames = []
        return merged(frames, others, self._others)

    def close(self) -> None:
        for net in self._networks:
            net.disconnect()


def merged(
    stand: list[can.Message], others: list[can.Message], logged: list[can.Message]
) -> list[can.Message]:
    """The master's frames and the others (compass, inclinometer; also appended to `logged`)
    in time order, the master's first at a tie; times to the microsecond (as the raw log's
    replay restores them)."""
    for msg in stand + others:
        msg.timestamp = round(msg.timestamp, 6)
    others = sorted(others, key=lambda m: m.timestamp)
    logged += others
    return sorted(stand + others, key=lambda m: m.timestamp)


def feed(
    engine: Engine,
    decoder: BatchDecoder | SourceDecoder,
    position: int,
    frames: list[can.Message],
    faults: list[DriveFault],
) -> list[FrameBatch]:
    """Feed `frames` (from stream position `position`) to the engine; a drive fault fails the
    trial at its stand time, after the frames up to it. The batches fed."""
    batches, start = [], 0
    times_ms = [round(m.timestamp * 1000) for m in frames]
    for fault in faults:
        cut = bisect.bisect_right(times_ms, fault.t_ms, lo=start)
        batches.append(decoder.decode(RawFrames.from_messages(position + start, frames[start:cut])))
        engine.feed(batches[-1])
        engine.fail(fault.reason, kind=fault.kind)
        start = cut
    batches.append(decoder.decode(RawFrames.from_messages(position + start, frames[start:])))
    engine.feed(batches[-1])
    return batches


def next_step(
    sim: SimulatedCia402 | LiveCia402, engine: Engine, step_s: float
) -> list[can.Message] | None:
    """The stand's frames of its next `step_s` of stand time; None where the drive stopped
    answering: one "bus error" event naming it, the trial under way failed and the campaign
    paused (no frame to go on from; `campaign resume` once the drive answers again)."""
    try:
        return sim.advance_to(sim.stand.t_s + step_s)
    except DriveError as exc:
        engine.fail(f"the CiA 402 drive stopped answering: {exc}", "bus error", last=True)
        return None


class Cia402Lockstep:
    """The engine's commander and its stream of frames from a simulated CiA 402 stand; a drive
    fault fails the trial it ends (one event naming the drive's error). The statuses' motion is
    measured from the drive's actual position (`motion_source`)."""

    motion_source = DRIVE_POSITION

    def __init__(self, sim: SimulatedCia402, plan: Plan, step_s: float = STEP_S) -> None:
        self.sim = sim
        self.plan = plan
        self.step_s = step_s
        self.stream: list[can.Message] = []  # what `run` fed the engine

    def issue(self, command: Command, now_ms: int = 0) -> None:
        self.sim.stand.issue(command, now_ms)

    def decoder(self) -> BatchDecoder | SourceDecoder:
        return frame_decoder(
            self.sim.codec, *self.plan.heading_source, self.plan.inclinometer_mount
        )

    def steps(self, engine: Engine, max_stand_s: float = 200_000.0) -> Iterator[list[can.Message]]:
        """Feed the engine step by step until it is done (or `max_stand_s`)."""
        decoder = self.decoder()
        position = 0
        while engine.phase is not Phase.DONE and self.sim.stand.t_s < max_stand_s:
            frames = next_step(self.sim, engine, self.step_s)
            if frames is None:
                return
            feed(engine, decoder, position, frames, self.sim.stand.take_faults())
            position += len(frames)
            yield frames

    def run(self, engine: Engine, max_stand_s: float = 200_000.0) -> None:
        for frames in self.steps(engine, max_stand_s):
            self.stream += frames
