"""`gyrostand simulate --protocol iec61162`: the simulated compass on a serial line.

Live: HDT/THS/ROT sentences in real time onto --port (a serial port, or a pseudo-terminal a
tool made), or onto a pseudo-terminal pair it opens and names. Standalone (--schedule/--step):
the schedule played in stand time as fast as the machine allows into a TAG-block log (.nmea),
byte-reproducible for a seed."""

from __future__ import annotations

import functools
import inspect
import time
import typing
from collections.abc import Callable
from dataclasses import fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from gyrostand.devices.serial_config import LineFaults, SerialCompassConfig, SerialSimError
from gyrostand.errors import fail
from gyrostand.stand.simconfig import SimConfig

if TYPE_CHECKING:  # the simulation, the line and the log are imported when the command runs
    from rich.console import Console

    from gyrostand.stand.protocol import Codec

PANEL = "Serial compass (--protocol iec61162)"


@functools.cache
def _out() -> Console:
    from rich.console import Console

    return Console(stderr=True, highlight=False, markup=False, emoji=False)


def _options() -> list[inspect.Parameter]:
    """One option per field of the serial compass and its line faults (their help texts)."""
    params = []
    for cls in (SerialCompassConfig, LineFaults):
        hints = typing.get_type_hints(cls)
        for f in fields(cls):
            if "help" not in f.metadata:
                continue
            default: Any = f.default
            annotation = hints[f.name]
            if f.name == "sentences":
                default, annotation = ",".join(f.default), str  # type: ignore[arg-type]
            option = typer.Option(
                default,
                "--" + f.name.replace("_", "-"),
                help=f.metadata["help"],
                rich_help_panel=PANEL,
            )
            params.append(
                inspect.Parameter(
                    f.name, inspect.Parameter.KEYWORD_ONLY, default=option, annotation=annotation
                )
            )
    params.append(
        inspect.Parameter(
            "port",
            inspect.Parameter.KEYWORD_ONLY,
            annotation=str | None,
            default=typer.Option(
                None,
                help="serial port to send on (default: a pseudo-terminal pair, its path printed)",
                rich_help_panel=PANEL,
            ),
        )
    )
    return params


OPTIONS = _options()
NAMES = [p.name for p in OPTIONS]


def serial_config(config: SimConfig, values: dict[str, Any]) -> SerialCompassConfig:
    """The serial compass of the option values: its rate is the stand's heading rate."""
    faults = LineFaults(**{f.name: values[f.name] for f in fields(LineFaults)})
    serial = SerialCompassConfig(
        rate_hz=config.heading_rate_hz,
        baud=values["baud"],
        talker=values["talker"],
        sentences=tuple(s.strip().upper() for s in values["sentences"].split(",") if s.strip()),
        faults=faults,
        seed=config.seed,
    )
    try:
        serial.check()
    except SerialSimError as exc:
        fail(str(exc))
    return serial


def simulate_serial(
    config: SimConfig, run: dict[str, Any], values: dict[str, Any], codec: Codec | None
) -> None:
    serial = serial_config(config, values)
    if run["interface"] is not None:
        fail("--protocol iec61162 sends on a serial port: no --interface (the stand's CAN bus)")
    if run["schedule"] is not None or run["step"]:
        _standalone(config, serial, run, codec)
    else:
        _live(config, serial, values["port"], run["duration_s"], codec)


def _standalone(
    config: SimConfig, serial: SerialCompassConfig, run: dict[str, Any], codec: Codec | None
) -> None:
    from gyrostand.devices.framing import Framer, byte_time_s
    from gyrostand.devices.serial_sim import SerialCompass
    from gyrostand.devices.tagblock import SUFFIX, TagBlockWriter
    from gyrostand.stand.schedule import ScheduleError, Step, load_schedule, play

    log: Path | None = run["log"]
    if log is None or log.suffix.lower() != SUFFIX:
        fail(f"standalone mode with --protocol iec61162 needs --log FILE{SUFFIX}")
    try:
        steps = load_schedule(run["schedule"]) if run["schedule"] else []
        steps += [Step.parse(text) for text in run["step"] or []]
    except ScheduleError as exc:
        fail(str(exc))
    if not log.parent.is_dir():
        fail(f"folder {log.parent} does not exist")
    wall0 = time.perf_counter()
    epoch = time.time() if run["start_epoch"] is None else run["start_epoch"]
    compass = SerialCompass(serial)
    engine = compass.stand(replace(config, timing="virtual"), codec)
    framer = Framer(serial.baud)
    byte_s = byte_time_s(serial.baud)
    log.unlink(missing_ok=True)
    lines = 0
    with TagBlockWriter(log) as writer:
        for _ in play(engine, steps):  # (the stand's own frames stay on its bus)
            for t, data in compass.take():  # each read when its last byte is in
                writer.write(framer.feed(epoch + t + len(data) * byte_s, data))
        writer.write(framer.close())
        lines = writer.lines
    _out().print(
        f"{lines} lines (sentences and junk), {engine.stand_time_s:g} s of stand time in "
        f"{time.perf_counter() - wall0:.2f} s -> {log}"
    )


def _live(
    config: SimConfig,
    serial: SerialCompassConfig,
    port: str | None,
    duration_s: float | None,
    codec: Codec | None,
) -> None:
    from gyrostand.devices.serial_sim import PtyLine, SerialCompass, write_realtime

    write: Callable[[bytes], object]
    if port is None:
        line = PtyLine(serial.baud)
        write, close, where = line.write, line.close, line.path
        print(line.path, flush=True)  # the path to connect to, alone on stdout
    else:
        from gyrostand.devices.serial_port import SerialPortError, open_port

        try:
            device = open_port(port, serial.baud)
        except SerialPortError as exc:
            fail(str(exc))
        write, close, where = device.write, device.close, port
    compass = SerialCompass(serial)
    engine = compass.stand(config, codec)
    what = "+".join(serial.sentences)
    _out().print(
        f"serial compass on {where} at {serial.baud} baud: {what} at "
        f"{serial.rate_hz:g} Hz in real time (Ctrl-C to stop)"
    )

    written = 0
    try:
        written = write_realtime(compass.line(engine, duration_s), write, serial.baud)
    except KeyboardInterrupt:
        pass
    except OSError as exc:
        fail(f"serial port {where}: write failed ({exc.strerror or exc})", code=1)
    finally:
        close()
    _out().print(f"sent {written} bytes, stand time {engine.stand_time_s:.1f} s")
