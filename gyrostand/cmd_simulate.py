"""CLI: `gyrostand simulate` -- the simulated gyrocompass + roll stand.

Two modes: live (join a python-can bus, answer stand commands; in virtual time by default, at
`--speedup` x real time with `--timing realtime`) and standalone (play a scripted schedule as
fast as possible into a BLF/ASC log). Every physics, noise, stand and fault parameter is an
option generated from the config dataclasses, whose field help is the single source of its
documentation."""

from __future__ import annotations

import inspect
import time
import typing
from dataclasses import MISSING, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from gyrostand import cmd_simulate_serial
from gyrostand.devices.encoder_knobs import KNOBS as ENCODER_KNOBS
from gyrostand.errors import fail, say
from gyrostand.stand.simconfig import (
    CompassParams,
    FaultParams,
    InclinometerParams,
    NoiseParams,
    SimConfig,
    StandParams,
)

if TYPE_CHECKING:  # the simulator and the bus are imported when the command runs
    import can

    from gyrostand.stand.engine import HeadingTransmitter
    from gyrostand.stand.protocol import Codec


# (SimConfig field or None for its top-level fields, dataclass, help panel)
_GROUPS: tuple[tuple[str | None, type, str], ...] = (
    (None, SimConfig, "Timing"),
    ("compass", CompassParams, "Physics: gyrocompass"),
    ("noise", NoiseParams, "Physics: sensor noise"),
    ("stand", StandParams, "Roll stand limits"),
    ("faults", FaultParams, "Faults"),
    ("inclinometer", InclinometerParams, "CiA 410 inclinometer on the platform"),
)
PREFIXED = {"inclinometer"}  # groups whose options carry the group's name: --inclinometer-...


def _parameter_name(group: str | None, field_name: str) -> str:
    return f"{group}_{field_name}" if group in PREFIXED else field_name


def _option_name(field_name: str) -> str:
    return "--" + field_name.lower().replace("_", "-")


def _config_parameters() -> list[inspect.Parameter]:
    """One keyword parameter (a typer option) per scalar config field."""
    params = []
    for group, cls, panel in _GROUPS:
        hints = typing.get_type_hints(cls)
        for f in fields(cls):
            if f.default is MISSING:  # the nested dataclasses of SimConfig
                continue
            parameter = _parameter_name(group, f.name)
            name = _option_name(parameter)
            switch_off = hints[f.name] is bool and f.default  # --x/--no-x; else a plain flag
            decl = f"{name}/--no-{name[2:]}" if switch_off else name
            option = typer.Option(
                f.default, decl, help=f.metadata["help"], rich_help_panel=panel, show_default=True
            )
            params.append(
                inspect.Parameter(
                    parameter,
                    inspect.Parameter.KEYWORD_ONLY,
                    default=option,
                    annotation=hints[f.name],
                )
            )
    return params


def _config(values: dict[str, Any]) -> SimConfig:
    """Build the SimConfig from the option values; a clear error for a bad combination."""
    nested = {}
    top = {}
    for group, cls, _ in _GROUPS:
        chosen = {
            f.name: values[_parameter_name(group, f.name)]
            for f in fields(cls)
            if f.default is not MISSING
        }
        if group is None:
            top = chosen
        else:
            nested[group] = cls(**chosen)
    try:
        return SimConfig(**nested, **top)
    except ValueError as exc:
        fail(str(exc))


_RUN_PARAMETERS = [
    inspect.Parameter(
        "interface",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=str | None,
        default=typer.Option(
            None, help="python-can interface to join (virtual, socketcan, pcan, ...)"
        ),
    ),
    inspect.Parameter(
        "channel",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=str | None,
        default=typer.Option(None, help="python-can channel, e.g. vcan0"),
    ),
    inspect.Parameter(
        "duration_s",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=float | None,
        default=typer.Option(None, help="live mode: stop after this many wall seconds"),
    ),
    inspect.Parameter(
        "schedule",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=Path | None,
        default=typer.Option(
            None,
            help="standalone mode: TOML file, an array of 'step' tables with action (still or "
            "rock), duration_s and, to rock, direction_deg, amplitude_cm, period_s",
        ),
    ),
    inspect.Parameter(
        "step",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=list[str] | None,
        default=typer.Option(
            None,
            help="standalone mode step (repeatable, after --schedule's): "
            "'still DURATION_S' or 'rock K_DEG A_CM TAU_S DURATION_S'",
        ),
    ),
    inspect.Parameter(
        "log",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=Path | None,
        default=typer.Option(
            None, help="python-can log (.blf or .asc) of every frame sent; required standalone"
        ),
    ),
    inspect.Parameter(
        "dbc",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=Path | None,
        default=typer.Option(
            None, help="a lab's DBC file to speak instead of gyrostand's (with --signals)"
        ),
    ),
    inspect.Parameter(
        "signals",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=Path | None,
        default=typer.Option(
            None,
            help="TOML file with the \\[signals] map of the DBC's messages (a plan file will do; "
            "docs/protocol.md)",
        ),
    ),
    inspect.Parameter(
        "protocol",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=str,
        default=typer.Option(
            "gyrostand",
            help="what the compass speaks: gyrostand (the DBC's heading frame), nmea2000 "
            "(PGN 127250/127251/127257, address claim, product information), cia406 (a CiA 406 "
            "encoder on the compass card: position 0x6004 in TPDO1, heartbeat, EMCY) or "
            "iec61162 (HDT/THS/ROT sentences on a serial port: the Serial compass options); "
            "docs/instruments.md",
            rich_help_panel="Compass protocol",
        ),
    ),
    *(
        inspect.Parameter(
            name,
            inspect.Parameter.KEYWORD_ONLY,
            annotation=kind,
            default=typer.Option(default, help=text, rich_help_panel="Compass protocol"),
        )
        for name, kind, default, text in (
            ("model", str, "simulated compass", "nmea2000: model in the product information"),
            ("serial", str, "SIM-1", "nmea2000: serial number in the product information"),
            ("address", int, 35, "nmea2000: source address claimed at start (0-251)"),
            (
                "address_change_at_s",
                float | None,
                None,
                "nmea2000 fault: claim --new-address at this stand time",
            ),
            ("new_address", int, 36, "nmea2000: the address claimed by --address-change-at-s"),
            (
                "not_available_rate",
                float,
                0.0,
                "nmea2000 fault: probability that a heading is sent as not available",
            ),
            *((name, *knob) for name, knob in ENCODER_KNOBS.items()),
        )
    ),
    inspect.Parameter(
        "start_epoch",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=float | None,
        default=typer.Option(None, help="Unix time of stand time 0 in the log (default: now)"),
    ),
]
_RUN_NAMES = [p.name for p in _RUN_PARAMETERS]


_HELP = (
    "Run the simulated gyrocompass + roll stand.\n\n"
    "Live: --interface virtual|socketcan|... --channel ... joins that bus, answers stand "
    "commands and publishes heading and status until --duration-s or Ctrl-C: in virtual time "
    "(the default) as far as the controller's SIM_SYNC frames allow, for `gyrostand campaign "
    "run --timing virtual --interface ... --channel ...`; with --timing realtime at --speedup x "
    "real time.\n\n"
    "Standalone: --schedule FILE.toml and/or --step ... plays the schedule with no partner on "
    "the bus, as fast as possible, into --log FILE.blf|.asc (and onto the bus when --interface "
    "is given)."
)


def simulate(**options: Any) -> None:
    """Run the simulated gyrocompass + roll stand (options: see _HELP and the config fields)."""
    run = {name: options.pop(name) for name in _RUN_NAMES}
    line = {name: options.pop(name) for name in cmd_simulate_serial.NAMES}
    config = _config(options)
    codec = _codec(run["dbc"], run["signals"])
    if run["protocol"] == "iec61162":
        cmd_simulate_serial.simulate_serial(config, run, line, codec)
        return
    transmitter = _transmitter(run, config.seed)
    standalone = run["schedule"] is not None or run["step"]
    if not standalone and run["interface"] is None:
        fail("give --interface/--channel to join a bus, or --schedule/--step to play a schedule")
    bus = _open_bus(run["interface"], run["channel"]) if run["interface"] else None
    try:
        if standalone:
            _standalone(config, run, bus, codec, transmitter)
        else:
            assert bus is not None
            _live(config, run, bus, codec, transmitter)
    finally:
        if bus is not None:
            bus.shutdown()


def _codec(dbc: Path | None, signals: Path | None) -> Codec | None:
    """The lab's DBC and signal map as the stand's codec, the one a plan with them uses
    (`Codec.of`); None: gyrostand's own DBC."""
    from gyrostand.simulated_stand import StandSetupError, read_signals
    from gyrostand.stand.protocol import Codec, ProtocolError

    if dbc is None and signals is None:
        return None
    try:
        table = read_signals(signals) if signals is not None else {}
        return Codec.of(None if dbc is None else str(dbc), table)
    except (StandSetupError, ProtocolError) as exc:
        fail(str(exc))


def _transmitter(run: dict[str, Any], seed: int) -> HeadingTransmitter | None:
    """The compass's own protocol (None: the DBC's heading frame)."""
    from gyrostand.devices.nmea2000 import Product
    from gyrostand.devices.sim_nmea2000 import Nmea2000Compass, Nmea2000Device, Nmea2000Faults

    if run["protocol"] == "gyrostand":
        return None
    if run["protocol"] == "cia406":
        from gyrostand.devices.sim_cia406 import simulated_encoder

        try:
            return simulated_encoder({name: run[name] for name in ENCODER_KNOBS})
        except ValueError as exc:
            fail(f"--protocol cia406: {exc}")
    if run["protocol"] != "nmea2000":
        fail(f"--protocol: {run['protocol']!r} is not one of gyrostand, nmea2000, cia406, iec61162")
    for key in ("address", "new_address"):
        if not 0 <= run[key] <= 251:
            fail(f"--{key.replace('_', '-')}: {run[key]} is not a source address (0-251)")
    if not 0.0 <= run["not_available_rate"] <= 1.0:
        fail(f"--not-available-rate: {run['not_available_rate']} is not a probability in [0, 1]")
    device = Nmea2000Device(Product(run["model"], run["serial"], "1.0"), address=run["address"])
    faults = Nmea2000Faults(
        run["address_change_at_s"], run["new_address"], run["not_available_rate"]
    )
    return Nmea2000Compass(device, faults, seed)


def _open_bus(interface: str, channel: str | None) -> can.BusABC:
    import can

    try:
        return can.Bus(interface=interface, channel=channel)
    except (can.CanError, ValueError, ImportError, OSError, NotImplementedError) as exc:
        fail(f"cannot open CAN bus (interface {interface!r}, channel {channel!r}): {exc}")


def _standalone(
    config: SimConfig,
    run: dict[str, Any],
    bus: can.BusABC | None,
    codec: Codec | None,
    transmitter: HeadingTransmitter | None,
) -> None:
    from gyrostand.stand.schedule import (
        LOG_SUFFIXES,
        ScheduleError,
        Step,
        load_schedule,
        run_schedule,
    )

    log: Path | None = run["log"]
    if log is None or log.suffix.lower() not in LOG_SUFFIXES:
        fail(f"standalone mode needs --log FILE ending in {' or '.join(LOG_SUFFIXES)}")
    try:
        steps = load_schedule(run["schedule"]) if run["schedule"] else []
        steps += [Step.parse(text) for text in run["step"] or []]
        if not log.parent.is_dir():
            raise ScheduleError(f"folder {log.parent} does not exist")
        result = run_schedule(
            config,
            steps,
            log,
            start_epoch_s=run["start_epoch"],
            bus=bus,
            codec=codec,
            transmitter=transmitter,
        )
    except ScheduleError as exc:
        fail(str(exc))
    for ack in result.refusals:
        say(f"warning: stand refused {ack.command!r}: {ack.reason}")
    say(
        f"{result.frames} frames, {result.stand_duration_s:g} s of stand time in "
        f"{result.wall_s:.2f} s -> {log}"
    )


def _live(
    config: SimConfig,
    run: dict[str, Any],
    bus: can.BusABC,
    codec: Codec | None,
    transmitter: HeadingTransmitter | None,
) -> None:
    import can

    from gyrostand.stand.schedule import LOG_SUFFIXES
    from gyrostand.stand.simulator import Simulator

    log: Path | None = run["log"]
    if log is not None and log.suffix.lower() not in LOG_SUFFIXES:
        fail(f"--log must end in {' or '.join(LOG_SUFFIXES)}")
    recorder = can.Logger(str(log)) if log is not None else None
    simulator = Simulator(
        bus,
        config,
        codec=codec,
        recorder=recorder,
        start_epoch_s=run["start_epoch"],
        transmitter=transmitter,
    )
    pace = "in virtual time" if config.timing == "virtual" else f"at {config.speedup:g}x"
    say(f"simulating on {run['interface']}:{run['channel']} {pace} (Ctrl-C to stop)")
    deadline = None if run["duration_s"] is None else time.monotonic() + run["duration_s"]
    simulator.start()
    try:
        while deadline is None or time.monotonic() < deadline:
            time.sleep(
                0.05 if deadline is None else max(0.0, min(0.05, deadline - time.monotonic()))
            )
            if simulator.error is not None:
                break
    except KeyboardInterrupt:
        pass
    finally:
        try:
            simulator.stop()
        except can.CanError as exc:
            fail(f"CAN bus failed: {exc}", code=1)
        finally:
            if recorder is not None:
                recorder.stop()
    say(
        f"sent {simulator.frames_sent} frames ({simulator.frames_failed} failed, "
        f"{simulator.receive_errors} receive errors), "
        f"stand time {simulator.stand_time_s:.1f} s"
    )


simulate.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
    _RUN_PARAMETERS + _config_parameters() + cmd_simulate_serial.OPTIONS
)


def register(app: typer.Typer) -> None:
    """Add the simulate command to the CLI."""
    app.command(help=_HELP)(simulate)
