"""The plan's CAN codec (its DBC: the shipped one unless the plan names a lab DBC; its signal
map), its simulated stand, and `prepare`: what is checked before the bus or the database is
touched (`campaign run`, `plan check`)."""

from __future__ import annotations

from gyrostand.plan.model import BusPlan, Plan, PlanError
from gyrostand.stand.protocol import Codec, ProtocolError
from gyrostand.stand.simconfig import SimConfig, simulator_config


def codec_for(plan: Plan) -> Codec:
    """The plan's DBC and signal map as a codec (PlanError naming the problem)."""
    try:
        return Codec.of(plan.dbc_path, plan.signals)
    except ProtocolError as exc:
        raise PlanError([str(exc)]) from None


def sim_config(bus: BusPlan) -> SimConfig:
    """The simulated stand for a plan: its `[bus.simulator]` overrides (validated with the plan)
    on the defaults, with the plan's speedup, seed and timing."""
    return simulator_config(bus.simulator, speedup=bus.speedup, seed=bus.seed, timing=bus.timing)


def _serial_problems(plan: Plan) -> list[str]:
    """A serial compass: a real one needs its port; the simulated stand's is simulated too (on
    a pseudo-terminal pair of its own, in virtual time: timed by the simulation; its line is
    checked by `acquisition.serial_input.check_serial`)."""
    if not plan.bus.simulated:
        if plan.compass.port is None:
            return ['[compass] port: missing (the compass\'s serial port, e.g. "/dev/ttyUSB0")']
        return []
    if plan.bus.timing != "virtual":
        return [
            '[compass] protocol: "iec61162" on the simulated stand needs [bus] timing = '
            '"virtual" (its simulated compass is timed by the simulation)'
        ]
    return []


def prepare(plan: Plan) -> None:
    """Everything that can be checked before the bus or the database is touched (PlanError),
    including that the stand command of every trial can be encoded (its DBC ranges)."""
    codec = codec_for(plan)
    problems = []
    for t in plan.trials:
        try:
            codec.encode_command_set(t.direction_deg, t.amplitude_cm, t.period_s)
        except ProtocolError as exc:
            problems.append(f"[[trials]] {t.index}: the stand command cannot carry it: {exc}")
    if plan.stand.protocol == "cia402":
        problems.append(
            '[stand] protocol: "cia402" stands are not runnable yet (the acquisition commands a '
            '"gyrostand" stand controller only)'
        )
    compass = plan.compass
    if compass.protocol == "cia406":
        problems.append(
            '[compass] protocol: "cia406" is not runnable yet (gyrostand, dbc, nmea2000 and '
            "iec61162 are)"
        )
    elif compass.protocol == "iec61162":
        problems += _serial_problems(plan)
    elif compass.own_bus:
        problems.append(
            "[compass] interface: a compass on a CAN bus of its own is not runnable yet (put it "
            "on the stand's bus: leave interface and channel out)"
        )
    if problems:
        raise PlanError(problems)
    if plan.bus.simulated:
        sim_config(plan.bus)
