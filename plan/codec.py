"""The plan's CAN codec (its DBC: the shipped one unless the plan names a lab DBC; its signal
map), its simulated stand, and `prepare`: what is checked before the bus or the database is
touched (`campaign run`, `plan check`)."""

from __future__ import annotations

import dataclasses
from importlib.resources import files
from pathlib import Path

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


def stand_config(plan: Plan) -> SimConfig:
    """The plan's simulated stand (`sim_config`) carrying the plan's [inclinometer] as it is
    mounted: node id, axis, scale, and the stand's arm (its noise, bias, rate and faults are
    [bus.simulator.inclinometer]'s)."""
    config = sim_config(plan.bus)
    mounted = plan.inclinometer
    if mounted is None or mounted.protocol != "cia410":
        return config
    assert plan.stand.arm_length_cm is not None  # (the plan requires it with an inclinometer)
    inclinometer = dataclasses.replace(
        config.inclinometer,
        node_id=mounted.node_id,
        axis=mounted.axis,
        step_deg=mounted.scale,
        arm_length_cm=plan.stand.arm_length_cm,
    )
    return dataclasses.replace(config, inclinometer=inclinometer)


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
        problems += _cia402_problems(plan)
    compass = plan.compass
    if compass.protocol == "iec61162":
        problems += _serial_problems(plan)
    inclinometer = plan.inclinometer
    if plan.bus.simulated and inclinometer is not None and inclinometer.protocol != "cia410":
        problems.append(
            '[inclinometer] protocol: the simulated stand carries a "cia410" inclinometer only'
        )
    try:
        problems += _encoder_ids_taken(plan, codec)
    except PlanError as exc:
        problems += exc.problems
    if problems:
        raise PlanError(problems)
    if plan.bus.simulated:
        stand_config(plan)


def _encoder_ids_taken(plan: Plan, codec: Codec) -> list[str]:
    """A CiA 406 encoder on the stand's bus: its COB-IDs (TPDO, EMCY, heartbeat) must not be
    frames of the stand's DBC (PlanError for an EDS gyrostand cannot use)."""
    encoder = plan.compass.encoder()
    if encoder is None or plan.compass.own_bus:
        return []
    problems = []
    for what, cob_id in zip(("TPDO", "EMCY", "heartbeat"), encoder.ids, strict=True):
        try:
            taken = codec.database.get_message_by_frame_id(cob_id)
        except KeyError:
            continue
        problems.append(
            f"[compass] node_id: the encoder's {what} 0x{cob_id:03X} is the stand's frame "
            f"{taken.name} (DBC): give the encoder another node id"
        )
    return problems


def drive_eds(plan: Plan) -> Path:
    """The drive's EDS file: the plan's [stand] eds, or by its name the simulated drive's
    (sim-drive.eds, shipped with gyrostand). ValueError (one line) when there is none."""
    name = plan.stand.eds
    assert name is not None  # (the plan requires it with protocol = "cia402")
    path = Path(name)
    if path.is_file():
        return path
    # the simulated drive's EDS, shipped as gyrostand's resource (devices.sim_drive.SIM_DRIVE_EDS;
    # a resource, not an import: the plan layer imports no device)
    shipped = Path(str(files("gyrostand.devices") / "data" / "sim-drive.eds"))
    if path.name == shipped.name and len(path.parts) == 1:
        return shipped
    raise ValueError(f"[stand] eds: no file {name} (the drive's EDS, from its maker)")


def _cia402_problems(plan: Plan) -> list[str]:
    """What a CiA 402 stand cannot run with yet, or at all."""
    problems = []
    if plan.bus.simulated and plan.bus.timing != "virtual":
        problems.append(
            "[bus] timing: the simulated CiA 402 stand runs in virtual time only (timing = "
            '"virtual"); a real drive (simulated = false) runs in real time'
        )
    if not plan.bus.simulated:
        if plan.compass.own_bus:
            problems.append(
                "[compass] interface: a CiA 402 stand's compass on a bus of its own is not "
                "runnable yet (put it on the stand's bus)"
            )
        try:
            drive_eds(plan)
        except ValueError as exc:
            problems.append(str(exc))
    if plan.compass.protocol != "nmea2000":
        problems.append(
            '[compass] protocol: a "cia402" stand has no clock to put in a heading frame: its '
            'compass must be timed by reception (protocol = "nmea2000")'
        )
    return problems
