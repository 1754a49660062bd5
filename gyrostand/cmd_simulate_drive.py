"""CLI: `gyrostand simulate-drive` -- a simulated CiA 402 roll-stand drive (and optionally a
CiA 410 inclinometer on its platform) on a CAN bus, for a CANopen master in another process
(gyrostand's, or the lab's own tools); with `--plan`, the plan's whole simulated stand: the
drive, its inclinometer and the compass on the platform (`acquisition.cia402_sim_stand`), on the
plan's bus. Stand time follows the master's SYNC; while no SYNC comes it follows the wall clock
(docs/instruments.md, "A CiA 402 roll stand")."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from gyrostand.errors import fail

if TYPE_CHECKING:
    from gyrostand.devices.sim_drive import DriveFaults


def simulate_drive(
    interface: str = typer.Option("socketcan", help="python-can interface."),
    channel: str = typer.Option("vcan0", help="CAN channel."),
    node_id: int = typer.Option(2, min=1, max=127, help="The drive's CANopen node id."),
    inclinometer: int = typer.Option(
        0, min=0, max=127, help="Node id of a CiA 410 inclinometer on the platform (0: none)."
    ),
    counts_per_degree: float = typer.Option(
        10_000.0, min=1e-9, help="Drive units per degree of roll (the plan's counts_per_degree)."
    ),
    platform_scale: float = typer.Option(
        1.0, min=1e-9, help="Platform roll / encoder roll: a kinematics error, e.g. 1.03."
    ),
    overcurrent_at_s: float | None = typer.Option(
        None, help="Fault knob: an over-current fault (EMCY 0x2310) at this stand time, s."
    ),
    jam_at_s: float | None = typer.Option(
        None, help="Fault knob: the axis seizes (following-error trip) at this stand time, s."
    ),
    heartbeat_silent_at_s: float | None = typer.Option(
        None, help="Fault knob: the drive's heartbeat stops at this stand time, s."
    ),
    noise_deg: float = typer.Option(0.02, min=0.0, help="Inclinometer noise (sd), deg."),
    bias_deg: float = typer.Option(0.0, help="Inclinometer bias, deg."),
    plan: Path | None = typer.Option(
        None,
        help="A CiA 402 plan: its simulated stand (drive, \\[inclinometer], the compass on the "
        "platform speaking NMEA 2000, \\[bus.simulator]) on its \\[bus]; --interface, --channel, "
        "--node-id, --inclinometer, --counts-per-degree, --noise-deg and --bias-deg are then "
        "the plan's; --platform-scale multiplies its \\[bus.simulator.faults] amplitude_factor.",
    ),
) -> None:
    """Run a simulated CiA 402 drive until Ctrl-C."""
    import threading

    import can
    import canopen

    from gyrostand.devices.sim_drive import DriveFaults, SimDrive, serve
    from gyrostand.devices.sim_inclinometer import SimInclinometer
    from gyrostand.errors import say

    faults = DriveFaults(
        overcurrent_at_s=overcurrent_at_s,
        jam_at_s=jam_at_s,
        heartbeat_silent_at_s=heartbeat_silent_at_s,
        platform_scale=platform_scale,
    )
    if plan is not None:
        _simulate_plan(plan, faults)
        return
    network = canopen.Network()
    try:
        network.connect(interface=interface, channel=channel)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        fail(f"cannot open CAN {interface} {channel}: {exc}", code=1)
    try:
        drive = SimDrive(network, node_id, faults=faults)
        sensor = None
        if inclinometer:
            sensor = SimInclinometer(
                drive, inclinometer, counts_per_degree, bias_deg=bias_deg, noise_deg=noise_deg
            )
        drive.boot()
        if sensor is not None:
            sensor.boot()
        say(f"simulated CiA 402 drive, node {node_id}, on {interface} {channel}; Ctrl-C ends")
        stop = threading.Event()
        try:
            serve(drive, stop)
        except KeyboardInterrupt:
            stop.set()
    finally:
        network.disconnect()


def _simulate_plan(path: Path, faults: DriveFaults) -> None:
    """The plan's simulated CiA 402 stand on the plan's bus until Ctrl-C."""
    import threading

    import can
    import canopen

    from gyrostand.acquisition.cia402_sim_stand import simulated_stand
    from gyrostand.devices.sim_drive import serve
    from gyrostand.errors import say
    from gyrostand.plan.model import PlanError, load_plan

    try:
        plan = load_plan(path)
    except (PlanError, OSError) as exc:
        fail(f"{path}: {exc}")
    if plan.stand.protocol != "cia402" or plan.bus.simulated:
        fail(
            f'{path}: not a CiA 402 stand on a bus ([stand] protocol = "cia402", [bus] '
            "simulated = false)"
        )
    bus = plan.bus
    network = canopen.Network()
    try:
        network.connect(interface=bus.interface, channel=bus.channel)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        fail(f"cannot open CAN {bus.interface} {bus.channel}: {exc}", code=1)
    try:
        stand = simulated_stand(plan, network, faults)
        stand.boot()
        say(
            f"simulated CiA 402 stand of {path.name} (drive node {plan.stand.node_id}) on "
            f"{bus.interface} {bus.channel}; Ctrl-C ends"
        )
        stop = threading.Event()
        try:
            serve(stand.drive, stop)
        except KeyboardInterrupt:
            stop.set()
    finally:
        network.disconnect()


def register(app: typer.Typer) -> None:
    app.command("simulate-drive")(simulate_drive)
