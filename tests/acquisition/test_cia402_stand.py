"""The CiA 402 stand adapter on the simulated drive, without the engine: a drive fault, a lost
drive heartbeat and a following-error trip are each one `DriveFault` naming the cause, and the
axis ends at rest; a stop is acknowledged at once and the statuses say "rocking" until the axis
is at rest and disabled."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
import scipy.linalg

from gyrostand.acquisition.cia402_sim import SimulatedCia402
from gyrostand.acquisition.engine import Command
from gyrostand.devices import sim_drive
from gyrostand.devices.sim_drive import DriveFaults
from gyrostand.plan.model import Plan, PlanError, parse_plan
from gyrostand.stand.protocol import AckFrame, Codec, StandStatusFrame
from tests.acquisition.test_cia402_campaign import SERVO, cia402_plan


def _rock(faults: DriveFaults, seconds: float) -> tuple[SimulatedCia402, list]:
    sim = SimulatedCia402(cia402_plan(), faults, SERVO)
    sim.stand.issue(Command("set", 45.0, 48.0, 4.0))  # 3.7 deg: 36 700 counts
    sim.stand.issue(Command("start"))
    frames = sim.stand.advance_to(seconds)
    return sim, frames


def _decoded(frames: list) -> list:
    codec = Codec()
    return [f for f in map(codec.decode, frames) if f is not None]


@pytest.mark.parametrize(
    "faults, kind, cause",
    [
        (DriveFaults(overcurrent_at_s=3.0), "drive fault", "error code 0x2310: EMCY 0x2310"),
        # (the axis seizes; the target goes on beyond the window of 20 000 counts)
        (DriveFaults(jam_at_s=3.0), "following error", "error code 0x8611"),
        (DriveFaults(heartbeat_silent_at_s=3.0), "heartbeat lost", "no heartbeat from drive"),
    ],
    ids=["emcy", "following-error-trip", "heartbeat-lost"],
)
def test_a_drive_fault_is_one_fault_naming_the_cause_and_the_axis_at_rest(faults, kind, cause):
    sim, _ = _rock(faults, 20.0)
    try:
        (fault,) = sim.stand.take_faults()
        assert fault.kind == kind and cause in fault.reason
        assert fault.reason.startswith("CiA 402 drive: ")
        assert 3000 < fault.t_ms < 4000  # noticed within a second of stand time
        assert not sim.stand.rocking  # the roll ended: the fault reaction or the stop ramp
        assert sim.drive.at_rest and abs(sim.drive.v) < 1.0
        assert sim.drive.status in (sim_drive.FAULT, sim_drive.SWITCH_ON_DISABLED)
        assert sim.stand.take_faults() == []  # one, not one per cycle
    finally:
        sim.close()


def test_a_stop_is_acknowledged_at_once_and_the_axis_rests_before_still_is_reported():
    sim, frames = _rock(DriveFaults(), 12.0)
    try:
        sim.stand.issue(Command("stop"))
        frames += sim.stand.advance_to(40.0)
        decoded = _decoded(frames)
        (ack,) = [f for f in decoded if isinstance(f, AckFrame) and f.command == "stop"]
        assert ack.accepted and ack.stand_time_ms == pytest.approx(12_000, abs=100)
        statuses = [f for f in decoded if isinstance(f, StandStatusFrame)]
        still = [s.stand_time_ms for s in statuses if not s.rocking and s.stand_time_ms > 1000]
        # the stop ramp (5 s) and the servo settling: still only once at rest and disabled
        assert still and 17_000 <= still[0] < 40_000
        assert sim.drive.at_rest and sim.drive.status == sim_drive.SWITCH_ON_DISABLED
        rocking = [s for s in statuses if s.rocking and s.amplitude_cm > 0]
        assert rocking and all(abs(s.amplitude_cm - 48.0) < 1.0 for s in rocking[-4:])
    finally:
        sim.close()


def test_a_drive_that_cannot_be_enabled_again_is_a_fault_not_an_ack():
    sim, _ = _rock(DriveFaults(overcurrent_at_s=3.0), 10.0)
    try:
        assert len(sim.stand.take_faults()) == 1
        for command in (Command("stop"), Command("set", 135.0, 24.0, 4.0), Command("start")):
            sim.stand.issue(command)
        frames = sim.stand.advance_to(15.0)
        (fault,) = sim.stand.take_faults()
        assert fault.kind == "drive fault"
        assert "did not reach OPERATION ENABLED (state FAULT, error code 0x2310)" in fault.reason
        acks = [f.command for f in _decoded(frames) if isinstance(f, AckFrame)]
        assert "start" not in acks and not sim.stand.rocking
    finally:
        sim.close()


def _with_heartbeat(heartbeat_ms: int, timeout_ms: int) -> Plan:
    keys = f"drive_heartbeat_ms = {heartbeat_ms}\ndrive_timeout_ms = {timeout_ms}\n"
    return parse_plan(cia402_plan().text.replace("ramp_s = 5\n", "ramp_s = 5\n" + keys))


def test_the_plans_heartbeat_period_is_the_drives_and_gyrostands():
    """[stand] drive_heartbeat_ms: the drive's producer 0x1017, gyrostand's own heartbeat
    period, and the drive's heartbeat lost after 3 of its periods."""
    plan = _with_heartbeat(500, 2000)
    sim = SimulatedCia402(plan, DriveFaults(heartbeat_silent_at_s=3.0), SERVO)
    master_beats: list[float] = []
    sim.drive.network.subscribe(0x77F, lambda *_: master_beats.append(sim.drive.t_s))
    try:
        sim.stand.issue(Command("set", 45.0, 48.0, 4.0))
        sim.stand.issue(Command("start"))
        sim.stand.advance_to(8.0)
        assert sim.drive._od(0x1017) == 500
        assert sim.drive._od(0x1016, 1) == (127 << 16) | 2000
        assert np.diff(master_beats) == pytest.approx(0.5, abs=1e-9)  # every 5 cycles of 0.1 s
        (fault,) = sim.stand.take_faults()
        # silent for more than 3 x 500 ms: noticed at the first cycle (0.1 s) beyond
        assert fault.kind == "heartbeat lost" and 3000 < fault.t_ms < 5100, fault
        assert fault.reason.endswith("no heartbeat from drive for 1.60 s")
    finally:
        sim.close()


def test_a_heartbeat_consumer_time_not_above_the_period_is_one_line():
    message = r"^invalid plan: \[stand\] drive_timeout_ms: must be > drive_heartbeat_ms$"
    with pytest.raises(PlanError, match=message):
        _with_heartbeat(500, 500)


def _sampled_gain(period_s: float, cycle_s: float) -> float:
    """Closed form: the drive's position at each SYNC over the commanded roll's, for a target
    held over each cycle (zero-order hold) through the simulated servo's second-order lag
    wn^2 / (s^2 + 2 zeta wn s + wn^2), sampled at SYNC: the discretised system
    x[k+1] = Ad x[k] + Bd u[k], Ad = expm(Ac T), Bd = Ac^-1 (Ad - I) Bc, at z = exp(j w T)."""
    wn, zeta = 2 * math.pi * SERVO.natural_hz, SERVO.damping
    ac = np.array([[0.0, 1.0], [-(wn**2), -2 * zeta * wn]])
    bc = np.array([0.0, wn**2])
    ad = scipy.linalg.expm(ac * cycle_s)
    bd = np.linalg.solve(ac, (ad - np.eye(2)) @ bc)
    z = cmath.exp(2j * math.pi / period_s * cycle_s)
    return abs(np.linalg.solve(z * np.eye(2) - ad, bd)[0])


@pytest.mark.parametrize("cycle_ms", [100, 250])
def test_the_drive_follows_the_roll_up_to_the_longest_cycle(cycle_ms):
    """Up to the plan's longest cycle (250 ms: the interpolation period 0x60C2 is a byte of ms)
    the statuses' amplitude, measured from the drive's position at each SYNC, is the commanded
    one through the held targets and the servo's lag (closed form), and its period the
    commanded one."""
    plan = parse_plan(cia402_plan().text.replace("cycle_ms = 100", f"cycle_ms = {cycle_ms}"))
    sim = SimulatedCia402(plan, DriveFaults(), SERVO)
    try:
        sim.stand.issue(Command("set", 45.0, 48.0, 4.0))
        sim.stand.issue(Command("start"))
        statuses = [
            f for f in _decoded(sim.stand.advance_to(30.0)) if isinstance(f, StandStatusFrame)
        ]
        expected = 48.0 * _sampled_gain(4.0, cycle_ms / 1000)
        assert expected < 48.0 * (0.99 if cycle_ms == 250 else 0.999)  # (the lag shows)
        for s in statuses[-4:]:  # (from 20 s: the 5 s start ramp and 2 periods behind)
            # within 0.1 %: the simulated servo's 5 ms integration steps, the 0.01 cm statuses
            assert s.rocking and s.amplitude_cm == pytest.approx(expected, abs=0.05), (s, expected)
            assert s.period_s == pytest.approx(4.0, abs=0.002)
    finally:
        sim.close()
