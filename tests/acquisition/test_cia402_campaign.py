"""A campaign on the simulated CiA 402 stand in virtual time (SYNC in stand time): gyrostand as
the drive's master, the engine's stand commands as roll trajectories, its statuses measured from
the drive's actual position, the compass speaking NMEA 2000 timed by reception."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

import can
import numpy as np
import pytest

from gyrostand.acquisition.cia402_sim import STEP_S, Cia402Lockstep, SimulatedCia402
from gyrostand.acquisition.engine import Engine
from gyrostand.devices import sim_drive
from gyrostand.devices.decoder import source_info
from gyrostand.devices.sim_drive import DriveFaults, ServoModel
from gyrostand.plan.model import Plan, parse_plan
from gyrostand.stand.protocol import AckFrame, Codec, StandStatusFrame
from tests.acquisition.harness import FAST_SIM, Recorder, plan_text

CYCLE_MS = 100
STAND = f"""
[stand]
protocol = "cia402"
eds = "sim-drive.eds"
node_id = 2
counts_per_degree = 10000
arm_length_cm = 750
cycle_ms = {CYCLE_MS}
ramp_s = 5
"""
TRIALS = [(45.0, 24.0, 6.0, "fit"), (135.0, 20.0, 5.0, "fit"), (45.0, 16.0, 8.0, "fit")]
# a slow servo (2 Hz): its lag shows in the measured amplitude; a coarser integration: quicker
SERVO = ServoModel(natural_hz=2.0, max_substep_ms=5.0)


def cia402_plan(trials: list[tuple] = TRIALS, **kwargs: object) -> Plan:
    fast = FAST_SIM.replace("240.0", "120.0")  # a compass that settles in about a minute
    text = plan_text(trials, n_obs=2, hold_s=30.0, **kwargs) + fast  # type: ignore[arg-type]
    return parse_plan(text + STAND + '\n[compass]\nprotocol = "nmea2000"\n')


def run(
    plan: Plan, faults: DriveFaults = DriveFaults(), max_stand_s: float = 3000.0
) -> tuple[Recorder, Cia402Lockstep]:
    sim = SimulatedCia402(plan, faults, SERVO)
    try:
        sink = Recorder()
        stand = Cia402Lockstep(sim, plan)
        engine = Engine(plan, sink, stand, source=source_info(sim.codec, "nmea2000", virtual=True))
        stand.run(engine, max_stand_s)
        assert engine.outcome == "completed" or sim.stand.t_s >= max_stand_s
        return sink, stand
    finally:
        sim.close()


# a CiA 410 inclinometer on the platform, which rolls 3 % more than the encoder counts (the
# kinematics' error)
INCLINOMETER = """
[inclinometer]
protocol = "cia410"
node_id = 4
[bus.simulator.inclinometer]
rate_hz = 5.0
noise_deg = 0.005
[bus.simulator.faults]
amplitude_factor = 1.03
"""


@pytest.fixture(scope="module")
def campaign() -> tuple[Recorder, Cia402Lockstep]:
    return run(parse_plan(cia402_plan().text.replace("[stand]", INCLINOMETER + "[stand]", 1)))


def _gain(period_s: float) -> float:
    """Closed form: the target held over each cycle (its fundamental: sinc(w T / 2)) through the
    simulated servo's second-order lag |wn^2 / (wn^2 - w^2 + 2j zeta wn w)|."""
    wn, w = 2 * math.pi * SERVO.natural_hz, 2 * math.pi / period_s
    half = w * CYCLE_MS / 2000
    return math.sin(half) / half * abs(wn**2 / (wn**2 - w**2 + 2j * SERVO.damping * wn * w))


def _ours(stream: list[can.Message]) -> list[can.Message]:
    """The stand's frames: commands, acks, statuses (not the compass's nor the
    inclinometer's)."""
    c = Codec()
    ids = {c.command_arbitration_id, c.ack_arbitration_id, *c.status_arbitration_ids}
    return [m for m in stream if m.arbitration_id in ids]


def _frames(stream: list[can.Message]) -> list[object]:
    codec = Codec()
    return [codec.decode(m) for m in _ours(stream)]


def test_three_fit_trials_complete_with_the_motion_measured_on_the_drive(campaign):
    """The trials apply the inclinometer's measure of the roll; the drive's own measure (its
    actual position) does not see the platform's 3 % more."""
    sink, _ = campaign
    assert [args[0] for args in sink.of("trial_completed")] == [1, 2, 3]
    assert len(sink.observations) == 3 * 2 * 2 and not sink.of("trial_failed")
    series = [args[3] for args in sink.of("series_completed") if args[1] == 2]
    for measured, motions, (K, A, tau, _) in zip(sink.measured, series, TRIALS, strict=True):
        by_source = {m.source: m for m in motions}
        assert set(by_source) == {"inclinometer", "drive position"}
        drive, inclinometer = by_source["drive position"], by_source["inclinometer"]
        assert measured is not None and measured.direction_deg == K  # the operator's K
        assert measured.source == "inclinometer"
        assert measured.amplitude_cm == inclinometer.amplitude_cm
        # the encoder's roll: the commanded one through the servo's lag (0.7 to 1 % less),
        # within the statuses' 0.01 cm and the drive's 5 ms Euler steps
        assert drive.amplitude_cm == pytest.approx(A * _gain(tau), abs=0.006 + 3e-4 * A)
        assert A - drive.amplitude_cm > 0.05  # not the commanded amplitude
        assert drive.period_s == pytest.approx(tau, abs=0.002)
        # the platform's: 1.03 x, within 4 SE of the inclinometer's noise and 0.01 deg steps
        limit = 4 * inclinometer.amplitude_se_cm + 0.01
        assert inclinometer.amplitude_cm == pytest.approx(1.03 * A * _gain(tau), abs=limit)
        assert inclinometer.period_s == pytest.approx(tau, abs=0.002)


def test_acks_and_statuses_are_on_the_sync_clock(campaign):
    """The campaign clock is SYNC count x cycle_ms: every ack and status carries a whole number
    of cycles, and the frame's reception (virtual) time is that stand time."""
    _, stand = campaign
    frames = list(zip(_ours(stand.stream), _frames(stand.stream), strict=True))
    acks = [(m, f) for m, f in frames if isinstance(f, AckFrame)]
    statuses = [(m, f) for m, f in frames if isinstance(f, StandStatusFrame)]
    assert len(acks) >= 3 * 3 and len(statuses) > 1000
    for m, f in acks:
        assert f.accepted and f.stand_time_ms % CYCLE_MS == 0
        assert f.stand_time_ms == round(m.timestamp * 1000)
    for m, f in statuses:
        assert f.stand_time_ms % CYCLE_MS == 0 and f.stand_time_ms == round(m.timestamp * 1000)
    times = np.array([f.stand_time_ms for _, f in statuses])
    assert (np.diff(times) == 500).all()  # every 500 ms, none missing


def test_two_runs_are_the_same_frames(campaign):
    """Byte for byte, whatever the host's load (the first 150 s of stand time: the first
    trial's still series and its rocking's start)."""
    _, first = campaign
    _, second = run(first.plan, max_stand_s=150.0)
    ours = [(m.arbitration_id, bytes(m.data), m.timestamp) for m in second.stream]
    assert len(ours) > 1000
    assert (
        ours == [(m.arbitration_id, bytes(m.data), m.timestamp) for m in first.stream][: len(ours)]
    )


@contextlib.contextmanager
def _failing(plan: Plan, faults: DriveFaults) -> Iterator[tuple[SimulatedCia402, list, list]]:
    """The plan run with the drive's fault until the campaign ends (600 s of stand time at
    most): the stand, its error events and its failed trials (then the stand closed)."""
    sim = SimulatedCia402(plan, faults, SERVO)
    try:
        sink = Recorder()
        stand = Cia402Lockstep(sim, plan)
        engine = Engine(plan, sink, stand, source=source_info(sim.codec, "nmea2000", virtual=True))
        stand.run(engine, max_stand_s=600.0)
        assert engine.outcome == "paused"
        yield sim, [e for e in sink.of("event") if e[1] == "error"], sink.of("trial_failed")
    finally:
        sim.close()


def test_a_drive_fault_is_one_event_a_failed_trial_and_a_stand_at_rest():
    """(Each fault's `DriveFault`: test_cia402_stand.py.)"""
    faults, kind, cause = DriveFaults(overcurrent_at_s=150.0), "drive fault", "0x2310"
    with _failing(cia402_plan(on_failure="pause"), faults) as (sim, errors, failed):
        assert len(errors) == 1 and errors[0][0] == kind and cause in errors[0][2]
        ((trial, j, reason),) = failed
        assert trial == 1 and j == 2 and reason == errors[0][2]  # (rocking at stand time 150 s)
        assert sim.stand.to_rest()
        assert sim.drive.at_rest and abs(sim.drive.v) < 1.0
        assert sim.drive.status in (sim_drive.FAULT, sim_drive.SWITCH_ON_DISABLED)


def test_a_drive_that_stops_answering_is_one_event_a_failed_trial_and_a_paused_campaign():
    """A drive that falls silent mid-roll (its power lost): one "bus error" event naming it, the
    trial failed with that reason and the campaign paused although the plan goes on after a
    failed trial (nothing to go on from); before, the error left the run with no event."""
    plan = cia402_plan()
    assert plan.on_trial_failure != "pause"
    with _failing(plan, DriveFaults(silent_at_s=150.0)) as (sim, errors, failed):
        assert len(errors) == 1 and errors[0][0] == "bus error"
        assert "stopped answering" in errors[0][2] and "sent no TPDO" in errors[0][2]
        ((trial, j, reason),) = failed
        assert trial == 1 and j == 2 and reason == errors[0][2]  # (rocking at stand time 150 s)
        assert 150.0 <= sim.stand.t_s <= 155.0 + STEP_S  # it stopped there, not at 600 s
