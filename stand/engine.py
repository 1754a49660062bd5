"""The simulated gyrocompass + roll stand as a deterministic machine advanced in STAND time.

`advance_to(t)` returns every frame the stand and the compass send up to stand time t (their
`timestamp` is the stand time in seconds); `receive(msg)` applies a command at the current stand
time and returns the acknowledgement (a command takes effect from the next heading sample). No
bus and no clock here: the live `Simulator` paces this against wall time, the standalone
schedule runs it as fast as the machine allows."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import can
import numpy as np

from gyrostand.stand.inclinometer import SimInclinometerFrames
from gyrostand.stand.packing import BatchEncoder, EncodedFrames, Part
from gyrostand.stand.physics import CorrelatedNoise, DampedPrecession
from gyrostand.stand.protocol import HEADING_KEYS, STATUS_KEYS, Codec, CommandFrame, Reason
from gyrostand.stand.simconfig import FaultParams, SimConfig

# columns of the per-sample uniform draws for the fault knobs (always drawn, so switching one
# knob on does not change the noise or the other faults)
_DROP, _JUMP, _JUMP_SIZE, _INVALID, _OOR, _OOR_VALUE, _CORRUPT, _CORRUPT_BIT, _ERROR = range(9)
_N_FAULT_DRAWS = 9
_EPS = 1e-9  # tolerance when turning stand times into sample indices
COMPASS_FRAME = "compass"  # `can.Message.channel` of the transmitter's frames (`Simulator`)


@dataclass(frozen=True)
class ReceivedCommand:
    """A command the stand received: its stand time, the command, and what the stand did
    ("accepted", a refusal `Reason`, or "unanswered" under `no_ack` or a silence)."""

    stand_time_s: float
    command: CommandFrame
    answer: str


class HeadingTransmitter(Protocol):
    """A compass that speaks another protocol than the stand's DBC (`devices.sim_nmea2000`):
    it sends the readings of heading samples `index` (stand times `t_s`) as its own frames."""

    def frames(
        self, t_s: np.ndarray, reading_deg: np.ndarray, index: np.ndarray
    ) -> list[can.Message]: ...


@runtime_checkable
class Answering(Protocol):
    """A compass that also answers frames of its protocol (NMEA 2000: requests, claims)."""

    def answers(self, msg: can.Message) -> bool: ...

    def answer(self, msg: can.Message, t_s: float) -> list[can.Message]: ...


class StandEngine:
    """`clock_ms`: the stand clock at power-up, which the frames' STAND_TIME count from (a
    resumed campaign's stand, whose controller clock continues; the physics starts at 0)."""

    def __init__(
        self,
        config: SimConfig,
        codec: Codec | None = None,
        clock_ms: int = 0,
        transmitter: HeadingTransmitter | None = None,
    ) -> None:
        self.config = config
        self.clock_ms = clock_ms
        self.codec = codec or Codec()
        self.transmitter = transmitter  # None: the compass sends the DBC's heading frame
        compass = config.compass
        seeds = np.random.SeedSequence(config.seed).spawn(4)  # (a 4th leaves the 3 as they were)
        noise_seed, white_seed, fault_seed, inclinometer_seed = seeds
        self._dt = 1.0 / config.heading_rate_hz
        self._corr = CorrelatedNoise(
            config.noise.corr_sigma_deg,
            config.noise.corr_mu_per_s,
            self._dt,
            np.random.default_rng(noise_seed),
        )
        self._white_rng = np.random.default_rng(white_seed)
        self._fault_rng = np.random.default_rng(fault_seed)
        w0 = 2.0 * math.pi / compass.undamped_period_s
        self._precession = DampedPrecession(
            w0, compass.damping_ratio * w0, self._dt, nonlinear=compass.nonlinear
        )
        if compass.transient:
            self._precession.x_rad = math.radians(compass.initial_error_deg)
        self._equilibrium_deg = 0.0
        self._time_s = 0.0
        self._next_heading = 0  # index of the next heading sample (at index / heading rate)
        self._next_status = 0
        self._counter = 0
        self._last_reading_deg = compass.heading_deg
        self._stuck_reading_deg: float | None = None
        ((heading_message, heading_signals),) = self.codec.layout(HEADING_KEYS)
        self._heading_encoder = BatchEncoder(heading_message, heading_signals, "heading_crc")
        self._status_encoders = [BatchEncoder(*g) for g in self.codec.layout(STATUS_KEYS)]
        self._setting: tuple[float, float, float] | None = None  # commanded K deg, A cm, tau s
        self._rocking_since_s: float | None = None
        self._compass_status = self._compass_status_frame()
        self.received: list[ReceivedCommand] = []  # every command, in order
        self._inclinometer: SimInclinometerFrames | None = None
        if config.inclinometer.node_id is not None:
            rng = np.random.default_rng(inclinometer_seed)
            self._inclinometer = SimInclinometerFrames(config.inclinometer, rng)

    def _compass_status_frame(self) -> can.Message:
        """GYRO_STATUS: constant while the fault knobs stay as they are."""
        return self.codec.encode_compass_status(
            True, self.config.compass.fluid_temp_c, self.config.faults.compass_fault_bits
        )

    def set_faults(self, faults: FaultParams) -> None:
        """Change the fault knobs from the current stand time on (the rolling error of a stand
        already rocking keeps the amplitude it started with)."""
        self.config = dataclasses.replace(self.config, faults=faults)
        self._compass_status = self._compass_status_frame()

    # ------------------------------------------------------------------------------ state
    @property
    def stand_time_s(self) -> float:
        return self._time_s

    @property
    def rocking(self) -> bool:
        return self._rocking_since_s is not None

    @property
    def equilibrium_deg(self) -> float:
        """Current equilibrium reading shift from the true heading (model 1.1 while rocking)."""
        return self._equilibrium_deg

    def _actual_motion(self) -> tuple[float, float, float]:
        """Direction deg, amplitude cm and period s the stand really rocks at."""
        assert self._setting is not None
        direction, amplitude, period = self._setting
        return direction, amplitude * self.config.faults.amplitude_factor, period

    def _silent(self, t_s: np.ndarray | float) -> np.ndarray:
        f = self.config.faults
        return _within(t_s, f.silence_at_s, f.silence_for_s)

    # ------------------------------------------------------------------------------ frames
    def advance_to(self, t_s: float, *, compass_only: bool = False) -> list[can.Message]:
        """Every frame due in (current stand time, t_s], in stand-time order; `compass_only`:
        the compass's heading frames alone (a listener that decodes nothing else need not pay
        for the stand's status frames, three for every heading sample at 2 Hz)."""
        parts = self._advance(t_s, heading=True, others=not compass_only)
        frames = [m for p in parts for m in (p.messages() if isinstance(p, EncodedFrames) else p)]
        frames.sort(key=lambda m: m.timestamp)  # stable: keeps the order within one instant
        return frames

    def advance_parts(self, t_s: float) -> list[Part]:
        """`advance_to`'s frames mostly as arrays, not yet sorted (`Part`): no `can.Message` per
        frame (three quarters of the in-process stand's cost a frame)."""
        return self._advance(t_s, heading=True, others=True)

    def pass_to(self, t_s: float) -> None:
        """Advance to stand time t_s with nobody listening (a procedure's wait): the physics and
        every random draw as `advance_to` makes them, so what is heard afterwards is the same
        to the bit; no frame is built."""
        self._advance(t_s, heading=False, others=False)

    def _advance(self, t_s: float, *, heading: bool, others: bool) -> list[Part]:
        """The frames due up to t_s, in parts, unsorted."""
        heading_end = math.floor(t_s * self.config.heading_rate_hz + _EPS) + 1
        status_end = math.floor(t_s * self.config.status_rate_hz + _EPS) + 1
        parts = self._heading_frames(self._next_heading, heading_end, build=heading)
        if others:
            parts += self._status_frames(self._next_status, status_end)
        if self._inclinometer is not None:  # its noise drawn whether or not anyone listens
            sensed = self._inclinometer.frames(t_s, self._roll_rad)
            parts.append([m for m in sensed if others and not self._silent(m.timestamp)])
        self._next_heading = max(self._next_heading, heading_end)
        self._next_status = max(self._next_status, status_end)
        self._time_s = max(self._time_s, t_s)
        return parts

    def _roll_rad(self, t: np.ndarray) -> np.ndarray:
        """The platform's true roll angle at stand times: A / arm (rad) at the rocking phase
        the compass feels (`_readings_deg`); 0 at rest."""
        if not self.rocking:
            return np.zeros(len(t))
        _, amplitude, period = self._actual_motion()
        phase = 2.0 * math.pi / period * (t - self._rocking_since_s)
        return amplitude / self.config.inclinometer.arm_length_cm * np.sin(phase)

    def _readings_deg(self, t: np.ndarray) -> np.ndarray:
        """The compass reading at the sample times, before sensor faults."""
        compass, noise = self.config.compass, self.config.noise
        n = len(t)
        deviation = self._precession.run(n) if compass.transient else np.zeros(n)
        reading = (
            compass.heading_deg
            + compass.settle_point_error_deg
            + self._equilibrium_deg
            + np.degrees(deviation)
        )
        if self.rocking:
            _, amplitude, period = self._actual_motion()
            p = 2.0 * math.pi / period
            accel_g = amplitude * p**2 / compass.g_cm_s2
            phase = p * (t - self._rocking_since_s)
            reading += accel_g * (
                compass.harmonic_p_deg_per_g * np.sin(phase)
                + compass.harmonic_2p_deg_per_g * np.sin(2.0 * phase)
            )
        reading += noise.drift_deg_per_h * t / 3600.0
        # seed 004 eq 8.90: a harmonic a cos(nu t + phi) hidden in the stationary noise X(t)
        reading += noise.spurious_amplitude_deg * np.sin(
            2.0 * math.pi * t / noise.spurious_period_s
        )
        reading += self._corr.sample(n)
        reading += noise.white_sigma_deg * self._white_rng.standard_normal(n)
        if noise.quantum_deg > 0:
            reading = np.round(reading / noise.quantum_deg) * noise.quantum_deg
        return np.round(np.mod(reading, 360.0), 3) % 360.0  # on the frame's 0.001 deg grid

    def _heading_frames(self, start: int, end: int, *, build: bool = True) -> list[Part]:
        """The heading frames of samples start..end-1 (`build` False: their draws only)."""
        n = end - start
        if n <= 0:
            return []
        f = self.config.faults
        index = np.arange(start, end)
        t = index * self._dt
        readings = self._stick(t, self._readings_deg(t))
        u = self._fault_rng.random((n, _N_FAULT_DRAWS))
        jumps = np.where(u[:, _JUMP] < f.counter_jump_rate, 1 + (u[:, _JUMP_SIZE] * 14), 0)
        counter = (self._counter + np.arange(n) + np.cumsum(jumps.astype(np.int64))) % 16
        self._counter = int(counter[-1] + 1) % 16
        if not build:
            return []
        if self.transmitter is not None:  # its own frames: the stand's DBC faults do not apply
            sent = (u[:, _DROP] >= f.drop_rate) & ~self._silent(t)
            return [_compass(self.transmitter.frames(t[sent], readings[sent], index[sent]))]
        out_of_range = u[:, _OOR] < f.out_of_range_rate  # up to the 19-bit raw maximum
        readings = np.where(out_of_range, 360.0 + np.round(u[:, _OOR_VALUE] * 164.0, 3), readings)
        values = {
            "heading_time": np.round(index * (1000.0 / self.config.heading_rate_hz))
            + self.clock_ms,
            "heading": readings,
            "heading_valid": u[:, _INVALID] >= f.invalid_rate,
            "heading_counter": counter,
        }
        data = self._heading_encoder.pack(values, n)
        corrupt = np.nonzero(u[:, _CORRUPT] < f.corrupt_rate)[0]
        bits = (u[corrupt, _CORRUPT_BIT] * 8 * data.shape[1]).astype(np.int64)
        data[corrupt, bits // 8] ^= (1 << (bits % 8)).astype(np.uint8)
        sent = (u[:, _DROP] >= f.drop_rate) & ~self._silent(t)
        error_times = t[sent & (u[:, _ERROR] < f.error_frame_rate)]
        errors = [can.Message(is_error_frame=True, timestamp=float(e)) for e in error_times]
        # first in the list: advance_to's stable sort puts each before its heading frame
        return [errors, self._heading_encoder.frames(data[sent], t[sent])]

    def _stick(self, t: np.ndarray, readings: np.ndarray) -> np.ndarray:
        """A stuck sensor repeats the last reading it gave before sticking."""
        f = self.config.faults
        stuck = _within(t, f.stuck_at_s, f.stuck_for_s)
        if stuck.any():
            first = int(np.argmax(stuck))
            if self._stuck_reading_deg is None:
                self._stuck_reading_deg = (
                    float(readings[first - 1]) if first > 0 else self._last_reading_deg
                )
            readings = np.where(stuck, self._stuck_reading_deg, readings)
        self._last_reading_deg = float(readings[-1])
        return readings

    def _status_frames(self, start: int, end: int) -> list[Part]:
        index = np.arange(start, max(start, end))
        t = index / self.config.status_rate_hz
        heard = ~self._silent(t)
        index, t = index[heard], t[heard]
        n = len(index)
        if n == 0:
            return []
        direction = self._setting[0] if self._setting else 0.0
        amplitude = period = 0.0
        cycles = np.zeros(n)
        if self._rocking_since_s is not None:
            direction, amplitude, period = self._actual_motion()
            if self.config.faults.amplitude_unreported:
                amplitude = self._setting[1] if self._setting else 0.0
            cycles = np.maximum(t - self._rocking_since_s, 0.0) / period
        values = {
            "status_time": np.round(index * (1000.0 / self.config.status_rate_hz)) + self.clock_ms,
            "status_rocking": np.full(n, self.rocking),
            "status_direction": np.full(n, direction),
            "status_amplitude": np.full(n, amplitude),
            "status_period": np.full(n, period),
            "status_cycle": np.floor(cycles) % 32768,
            "status_phase": np.round((cycles % 1.0) * 360.0, 2) % 360.0,
        }
        # the part completing the status goes last
        frames: list[Part] = [e.frames(e.pack(values, n), t) for e in self._status_encoders]
        compass = self._compass_status
        data = np.tile(np.frombuffer(compass.data, np.uint8), (n, 1))
        frames.append(EncodedFrames(compass.arbitration_id, compass.is_extended_id, data, t))
        return frames

    # ------------------------------------------------------------------------------ commands
    def for_compass(self, msg: can.Message) -> bool:
        """Whether the compass answers `msg` (a request or claim of its own protocol)."""
        return isinstance(self.transmitter, Answering) and self.transmitter.answers(msg)

    def receive(self, msg: can.Message) -> list[can.Message]:
        """Handle a frame from the bus at the current stand time; return the ack (or the
        compass's answer) to send."""
        if isinstance(self.transmitter, Answering) and self.transmitter.answers(msg):
            return _compass(self.transmitter.answer(msg, self._time_s))
        frame = self.codec.decode(msg)
        if not isinstance(frame, CommandFrame):
            return []
        if self.config.faults.no_ack or self._silent(self._time_s):
            self.received.append(ReceivedCommand(self._time_s, frame, "unanswered"))
            return []
        reason = self._apply(frame)
        self.received.append(ReceivedCommand(self._time_s, frame, reason or "accepted"))
        ack = self.codec.encode_ack(
            frame.command,
            reason is None,
            reason or "",
            seq=frame.seq,
            stand_time_ms=round(self._time_s * 1000.0) + self.clock_ms,
        )
        ack.timestamp = self._time_s
        return [ack]

    def _apply(self, cmd: CommandFrame) -> Reason | None:
        """Carry out a command; the refusal reason, or None when accepted."""
        limits = self.config.stand
        if cmd.command == "set":
            if self.rocking:
                return Reason.BUSY
            if not 0.0 < cmd.amplitude_cm <= limits.max_amplitude_cm:
                return Reason.AMPLITUDE
            if not limits.min_period_s <= cmd.period_s <= limits.max_period_s:
                return Reason.PERIOD
            self._setting = (cmd.direction_deg, cmd.amplitude_cm, cmd.period_s)
        elif cmd.command == "start":
            if self._setting is None:
                return Reason.NOT_CONFIGURED
            if not self.rocking:
                self._rocking_since_s = self._time_s
                self._move_equilibrium(
                    self.config.compass.settled_shift_deg(*self._actual_motion())
                )
        elif cmd.command == "stop" and self.rocking:
            self._rocking_since_s = None
            self._move_equilibrium(0.0)
        return None

    def _move_equilibrium(self, shift_deg: float) -> None:
        """The compass starts its transient from where it is toward the new equilibrium."""
        if self.config.compass.transient:
            self._precession.shift_equilibrium(math.radians(shift_deg - self._equilibrium_deg))
        self._equilibrium_deg = shift_deg


def _compass(frames: list[can.Message]) -> list[can.Message]:
    """The transmitter's frames, marked as the compass's (a bus of its own may carry them)."""
    for msg in frames:
        msg.channel = COMPASS_FRAME
    return frames


def _within(t: np.ndarray | float, start_s: float | None, length_s: float) -> np.ndarray:
    """Which times fall in the window [start, start + length) (none when start is None)."""
    t = np.asarray(t)
    if start_s is None:
        return np.zeros(t.shape, dtype=bool)
    return (t >= start_s) & (t < start_s + length_s)
