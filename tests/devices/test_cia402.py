"""The CiA 402 master against the simulated drive on python-can's virtual bus, in lockstep
virtual time (one SYNC = one cycle of stand time): deterministic whatever the host's load."""

from __future__ import annotations

import cmath
import itertools
import math
import signal
import threading
import time

import canopen
import numpy as np
import pytest

from gyrostand.analysis.measured_roll import measure_roll
from gyrostand.devices import cia402, sim_drive
from gyrostand.devices.cia402 import (
    AxisConfig,
    Cia402Axis,
    DriveError,
    power_state,
    stop_on_signals,
)
from gyrostand.devices.cia410 import Cia410Inclinometer
from gyrostand.devices.roll_trajectory import RollTrajectory
from gyrostand.devices.sim_drive import SIM_DRIVE_EDS, DriveFaults, ServoModel, SimDrive
from gyrostand.devices.sim_inclinometer import SIM_INCLINOMETER_EDS, SimInclinometer

CPD = 10_000.0  # counts per degree
CYCLE_MS = 10
_channels = itertools.count()


def _networks(channel: str) -> tuple[canopen.Network, canopen.Network]:
    nets = canopen.Network(), canopen.Network()
    for net in nets:
        net.NOTIFIER_CYCLE = 0.05  # a quick disconnect
        net.connect(interface="virtual", channel=channel)
    return nets


@pytest.fixture
def stand(request):
    """(axis, drive) on a fresh virtual bus; the drive booted, the axis not yet started."""
    faults = getattr(request, "param", DriveFaults())
    channel = f"cia402-{next(_channels)}"
    drive_net, master_net = _networks(channel)
    drive = SimDrive(drive_net, 3, faults=faults)
    axis = Cia402Axis(master_net, AxisConfig(3, SIM_DRIVE_EDS, cycle_ms=CYCLE_MS))
    drive.boot()
    yield axis, drive
    master_net.disconnect()
    drive_net.disconnect()


def test_start_reaches_operation_enabled_in_csp(stand):
    axis, drive = stand
    axis.start()
    assert power_state(axis.statusword) == "OPERATION ENABLED"
    assert axis.statusword & sim_drive.SW_FOLLOWING  # CSP: following the target
    assert drive.mode == 8 and drive.node.nmt.state == "OPERATIONAL"
    # what the master configured, read on the drive's side
    assert drive._od(0x1016, 1) == (127 << 16) | 300
    assert drive._od(0x6007) == 3 and drive._od(0x1006) == CYCLE_MS * 1000


def _lag(servo: ServoModel, period_s: float, cycle_s: float) -> complex:
    """Closed form: the second-order lag x/d = wn^2 / (wn^2 - w^2 + 2j zeta wn w), after the
    cycle's zero-order hold (a delay of half a cycle)."""
    wn, w = 2 * math.pi * servo.natural_hz, 2 * math.pi / period_s
    return wn**2 / (wn**2 - w**2 + 2j * servo.damping * wn * w) * cmath.exp(-0.5j * w * cycle_s)


def test_the_axis_follows_the_roll_as_the_servo_model_says(stand):
    axis, drive = stand
    axis.start()
    roll = RollTrajectory(amplitude_deg=3.0, period_s=2.0, ramp_s=1.0, stop_at_s=7.0)
    rec = axis.rock(roll, CPD)
    assert rec.failure is None and rec.stopped_by is None and rec.events == ()
    steady = (rec.t_s >= rec.t_s[0] + 1.0) & (rec.t_s < rec.t_s[0] + 7.0)
    t = rec.t_s[steady]
    target = measure_roll(t, rec.target_counts[steady] / CPD, 2.0)
    actual = measure_roll(t, rec.actual_counts[steady] / CPD, 2.0)
    h = _lag(ServoModel(), 2.0, CYCLE_MS / 1000)
    assert target.amplitude == pytest.approx(3.0, abs=1e-4)
    # (5e-4: the drive integrates its servo in 1 ms Euler steps, not exactly)
    assert actual.amplitude / target.amplitude == pytest.approx(abs(h), rel=5e-4)
    lag = cmath.phase(cmath.exp(1j * (actual.cycles[0].phase_rad - target.cycles[0].phase_rad)))
    assert lag == pytest.approx(cmath.phase(h), abs=2e-3)
    assert actual.period_s == pytest.approx(2.0, abs=1e-4)
    # at rest at the end, and switched off
    assert drive.at_rest and abs(drive.x) < 5
    assert power_state(axis.statusword) == "SWITCH ON DISABLED"


def test_a_stop_request_ramps_to_rest_then_disables(stand):
    axis, drive = stand
    axis.start()
    roll = RollTrajectory(3.0, 2.0, 1.0, stop_at_s=60.0)
    rec = axis.rock(roll, CPD, stop_check=lambda t: "stop request" if t >= 2.5 else None)
    assert rec.stopped_by == "stop request" and rec.failure is None
    assert [e.kind for e in rec.events] == ["stop"]
    assert rec.t_s[-1] - rec.t_s[0] == pytest.approx(2.5 + 1.0, abs=0.011)
    assert drive.at_rest and power_state(axis.statusword) == "SWITCH ON DISABLED"


def test_sigterm_and_ctrl_c_request_the_stop(stand):
    axis, _ = stand
    before = signal.getsignal(signal.SIGTERM)
    with stop_on_signals(axis):
        signal.raise_signal(signal.SIGTERM)
        assert axis.stop_requested == "SIGTERM"
        signal.raise_signal(signal.SIGINT)
        assert axis.stop_requested == "SIGINT"
    assert signal.getsignal(signal.SIGTERM) is before


def test_gyrostand_killed_mid_roll_the_drive_quick_stops_to_rest(stand):
    axis, drive = stand
    axis.start()
    roll = RollTrajectory(3.0, 2.0, 1.0)
    for k in range(150):  # 1.5 s of rocking, then gyrostand falls silent
        axis.step(0x0F, round(CPD * float(roll.position_deg(k * CYCLE_MS / 1000))))
    v0, x0 = drive.v, drive.x
    assert abs(v0) > 1000  # moving when killed
    drive.advance(0.15)  # last heartbeat 0.1 s before: within the consumer time (0.3 s)
    assert drive.status == sim_drive.OPERATION_ENABLED
    drive.advance(1.0)
    assert drive.emcy_sent == [sim_drive.EMCY_HEARTBEAT]
    assert drive.status == sim_drive.QUICK_STOP_ACTIVE and drive.at_rest
    # it stopped by the quick-stop ramp: within v^2 / (2 d) (plus the servo's settling) of
    # where it was when the loss was noticed
    assert abs(drive.x - x0) < abs(v0) * 0.3 + v0**2 / (2 * drive._od(0x6085)) + 500


@pytest.mark.parametrize(
    "stand, code, kinds",
    [
        (DriveFaults(overcurrent_at_s=2.0), "0x2310", ["emcy", "fault"]),
        (DriveFaults(jam_at_s=2.0), "0x8611", ["following_error", "emcy", "fault"]),
    ],
    indirect=["stand"],
    ids=["emcy-fault", "following-error-trip"],
)
def test_a_drive_fault_fails_the_rocking_naming_the_code(stand, code, kinds):
    axis, drive = stand
    axis.start()
    rec = axis.rock(RollTrajectory(3.0, 2.0, 1.0, stop_at_s=8.0), CPD)
    assert rec.failure is not None and code in rec.failure
    assert sorted(e.kind for e in rec.events) == sorted(kinds)
    assert power_state(axis.statusword) == "FAULT"
    assert drive.at_rest and drive.status == sim_drive.FAULT
    assert rec.t_s[-1] - rec.t_s[0] < 3.0  # not rocked on


@pytest.mark.parametrize("stand", [DriveFaults(heartbeat_silent_at_s=2.0)], indirect=True)
def test_a_lost_drive_heartbeat_fails_the_rocking_and_stops_the_axis(stand):
    axis, drive = stand
    axis.start()
    rec = axis.rock(RollTrajectory(3.0, 2.0, 1.0, stop_at_s=8.0), CPD)
    assert rec.failure is not None and "no heartbeat from drive" in rec.failure
    assert [e.kind for e in rec.events] == ["heartbeat_lost", "stop"]
    # the last heartbeat in (1.9, 2.0] s of stand time; lost 3 periods (0.3 s) after it
    assert 2.2 < rec.events[0].t_s <= 2.0 + 0.3 + 0.01
    assert drive.at_rest and power_state(axis.statusword) == "SWITCH ON DISABLED"
    assert np.abs(np.diff(rec.target_counts)).max() < 3.0 * 2 * math.pi / 2.0 * CPD * 0.011


def test_a_run_is_the_same_frames_whatever_the_load(stand):
    axis, _ = stand
    axis.start()
    rec = axis.rock(RollTrajectory(3.0, 2.0, 0.5, stop_at_s=1.0), CPD)
    assert np.array_equal(rec.actual_counts, _replay())


def _replay() -> np.ndarray:
    channel = f"cia402-{next(_channels)}"
    dn, mn = _networks(channel)
    try:
        drive = SimDrive(dn, 3)
        axis = Cia402Axis(mn, AxisConfig(3, SIM_DRIVE_EDS, cycle_ms=CYCLE_MS))
        drive.boot()
        axis.start()
        return axis.rock(RollTrajectory(3.0, 2.0, 0.5, stop_at_s=1.0), CPD).actual_counts
    finally:
        mn.disconnect()
        dn.disconnect()


def test_profile_position_when_the_drive_has_no_csp(stand):
    axis, drive = stand
    drive.node.set_data(0x6502, 0, (0x01).to_bytes(4, "little"))  # profile position only
    axis.start()
    assert drive.mode == 1
    rec = axis.rock(RollTrajectory(3.0, 2.0, 1.0, stop_at_s=7.0), CPD)
    assert rec.failure is None and drive.at_rest
    # set-points at the peaks, reached with a triangular velocity: between peaks the position
    # is a parabola per half segment, whose fundamental is 32 / pi^3 of the peak
    steady = (rec.t_s >= rec.t_s[0] + 1.5) & (rec.t_s < rec.t_s[0] + 6.5)
    fit = measure_roll(rec.t_s[steady], rec.actual_counts[steady] / CPD, 2.0)
    assert fit.amplitude == pytest.approx(3.0 * 32 / math.pi**3, rel=0.01)
    assert fit.period_s == pytest.approx(2.0, rel=1e-3)


@pytest.mark.parametrize("stand", [DriveFaults(platform_scale=1.03)], indirect=True)
def test_an_inclinometer_sees_the_amplitude_the_encoder_cannot(stand):
    """The platform rolls 3 % more than the encoder says (a kinematics error): the drive's
    actual position shows the commanded roll (through the servo lag), a CiA 410 inclinometer on
    the platform the real one, within its SE; the commanded amplitude is far outside it."""
    axis, drive = stand
    sim = SimInclinometer(drive, 4, CPD, bias_deg=0.05, noise_deg=0.02, seed=7)
    sim.boot()
    inclinometer = Cia410Inclinometer(axis.network, 4, SIM_INCLINOMETER_EDS)
    axis.inclinometer = inclinometer
    inclinometer.start()
    axis.start()
    assert inclinometer.step_deg == 0.01
    rec = axis.rock(RollTrajectory(3.0, 2.0, 1.0, stop_at_s=9.0), CPD)
    assert rec.failure is None and len(rec.slope_deg) == len(rec.t_s)
    steady = (rec.t_s >= rec.t_s[0] + 1.0) & (rec.t_s < rec.t_s[0] + 9.0)
    t = rec.t_s[steady]
    gain = abs(_lag(ServoModel(), 2.0, CYCLE_MS / 1000))
    encoder = measure_roll(t, rec.actual_counts[steady] / CPD, 2.0)
    platform = measure_roll(t, rec.slope_deg[steady], 2.0)
    assert encoder.amplitude == pytest.approx(3.0 * gain, rel=5e-4)
    assert abs(platform.amplitude - 1.03 * encoder.amplitude) < 3 * platform.amplitude_se
    assert abs(platform.amplitude - 3.0) > 20 * platform.amplitude_se
    assert platform.period_s == pytest.approx(2.0, abs=3 * platform.period_se_s + 1e-4)


def test_a_drive_refusing_its_configuration_is_one_line(stand):
    axis, drive = stand

    def refuse(index, subindex, od, data):
        if index == 0x1016:
            raise canopen.SdoAbortedError(0x06010002)  # attempt to write a read-only object

    drive.node.add_write_callback(refuse)
    with pytest.raises(DriveError, match=r"^drive 3 refused its configuration: .*0x06010002"):
        axis.start()


def test_the_master_waits_for_a_drive_still_booting():
    """A drive that comes on the bus after the master began (a simulated stand's process still
    starting): the master's first SDO goes unanswered, it asks again until the drive answers."""
    channel = f"cia402-{next(_channels)}"
    drive_net, master_net = _networks(channel)
    drives: list[SimDrive] = []

    def power_up() -> None:
        drives.append(SimDrive(drive_net, 3))
        drives[0].boot()

    boot = threading.Timer(0.5, power_up)
    try:
        axis = Cia402Axis(master_net, AxisConfig(3, SIM_DRIVE_EDS, cycle_ms=CYCLE_MS))
        boot.start()
        axis.start()
        assert drives and power_state(axis.statusword) == "OPERATION ENABLED"
        assert drives[0].mode == 8 and drives[0]._od(0x1006) == CYCLE_MS * 1000
    finally:
        boot.cancel()
        master_net.disconnect()
        drive_net.disconnect()


def test_a_drive_that_never_answers_is_one_line(monkeypatch):
    monkeypatch.setattr(cia402, "BOOT_S", 0.1)
    master_net = canopen.Network()
    master_net.NOTIFIER_CYCLE = 0.05
    master_net.connect(interface="virtual", channel=f"cia402-{next(_channels)}")
    try:
        axis = Cia402Axis(master_net, AxisConfig(3, SIM_DRIVE_EDS, cycle_ms=CYCLE_MS))
        with pytest.raises(DriveError, match=r"^drive 3 did not answer within 0.1 s \(is it "):
            axis.start()
    finally:
        master_net.disconnect()


def test_a_drive_without_csp_or_pp_is_one_line(stand):
    axis, drive = stand
    drive.node.set_data(0x6502, 0, (1 << 2).to_bytes(4, "little"))  # profile velocity only
    with pytest.raises(DriveError, match="offers neither cyclic synchronous nor profile"):
        axis.start()


def test_a_served_drive_quick_stops_when_its_master_dies():
    """`gyrostand simulate-drive` in another process: stand time follows SYNC, then (the master
    gone) the wall clock, so the heartbeat consumer stops the axis as on a real stand."""
    drive_net, master_net = _networks(f"cia402-{next(_channels)}")
    stop = threading.Event()
    try:
        drive = SimDrive(drive_net, 3)
        drive.boot()
        server = threading.Thread(target=sim_drive.serve, args=(drive, stop))
        server.start()
        axis = Cia402Axis(master_net, AxisConfig(3, SIM_DRIVE_EDS, cycle_ms=CYCLE_MS))
        axis.start()
        roll = RollTrajectory(3.0, 2.0, 1.0)
        for k in range(150):
            axis.step(0x0F, round(CPD * float(roll.position_deg(k * CYCLE_MS / 1000))))
        assert abs(drive.v) > 1000  # rocking when gyrostand dies
        deadline = time.monotonic() + 30.0  # a guard: the stop takes ~1.5 s of wall time
        while not (drive.status == sim_drive.QUICK_STOP_ACTIVE and drive.at_rest):
            assert time.monotonic() < deadline, "the drive did not stop"
            time.sleep(0.02)
        assert drive.emcy_sent == [sim_drive.EMCY_HEARTBEAT]
    finally:
        stop.set()
        master_net.disconnect()
        drive_net.disconnect()


def test_a_drive_starting_in_fault_is_reset_once(stand):
    axis, drive = stand
    drive._fault(sim_drive.EMCY_OVERCURRENT)  # left in FAULT by a previous run
    assert drive.status == sim_drive.FAULT
    axis.start()
    assert power_state(axis.statusword) == "OPERATION ENABLED" and drive.error_code == 0


@pytest.mark.parametrize("stand", [DriveFaults(overcurrent_at_s=0.0)], indirect=True)
def test_a_drive_that_cannot_be_enabled_is_one_line(stand):
    axis, _ = stand
    message = r"drive 3 did not reach OPERATION ENABLED \(state FAULT, error code 0x2310\)"
    with pytest.raises(DriveError, match=message):
        axis.start()
