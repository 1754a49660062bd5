"""gyrostand's pytest plugin (the `pytest11` entry point `gyrostand`): the simulated gyrocompass
+ roll stand as fixtures for a lab's own CAN tests (docs/testing.md).

- `gyro_stand`: the stand on a python-can bus, in virtual time, configured by the
  `@pytest.mark.gyro_stand(...)` marker; `gyro_stand_factory` makes more;
- `socketcan_channel` and the `socketcan` marker: skip with the reason where no SocketCAN
  interface exists;
- `gyro_campaign`: runs a gyrostand plan against `gyro_stand` into a temporary database and
  returns the analysed campaign.

Nothing heavy is imported here: a pytest run that uses none of the fixtures pays for a few
option definitions (`bench/bench_plugin_collection.py` measures it)."""

from __future__ import annotations

import os
import socket
import sys
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from gyrostand.simulated_stand import SimulatedStand
    from gyrostand.stand_campaign import CampaignRun

CHANNEL_ENV = "GYROSTAND_SOCKETCAN_CHANNEL"
BUS_ENV = "GYROSTAND_BUS"
DEFAULT_CHANNEL = "vcan0"
_MARKERS = (
    "socketcan: needs a SocketCAN interface (vcan0, or --gyrostand-channel / "
    f"{CHANNEL_ENV}); skipped with the reason where there is none",
    "gyro_stand(**knobs): the simulated stand of the gyro_stand fixture: compass={...}, "
    "noise={...}, faults={...}, stand={...}, seed, timing, speedup, heading_rate_hz, "
    "status_rate_hz, dbc, signals, protocol (gyrostand, nmea2000 or cia406), nmea2000={...}, "
    "cia406={...}",
)


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("gyrostand", "gyrostand's simulated gyrocompass and roll stand")
    group.addoption(
        "--gyrostand-bus",
        choices=("virtual", "socketcan"),
        default=None,
        help=f"bus of the gyro_stand fixture (default: ${BUS_ENV}, else virtual)",
    )
    group.addoption(
        "--gyrostand-channel",
        default=None,
        help=f"SocketCAN channel (default: ${CHANNEL_ENV}, else {DEFAULT_CHANNEL})",
    )
    group.addoption("--gyrostand-dbc", default=None, help="the lab's DBC the stand speaks")
    group.addoption(
        "--gyrostand-signals",
        default=None,
        help="TOML file whose [signals] table maps the lab's DBC, as in a plan",
    )


def pytest_configure(config: pytest.Config) -> None:
    for line in _MARKERS:
        config.addinivalue_line("markers", line)


def channel_name(config: pytest.Config) -> str:
    """The SocketCAN channel asked for: --gyrostand-channel, $GYROSTAND_SOCKETCAN_CHANNEL, vcan0."""
    return config.getoption("gyrostand_channel") or os.environ.get(CHANNEL_ENV) or DEFAULT_CHANNEL


def socketcan_missing(channel: str) -> str | None:
    """Why SocketCAN tests cannot run on `channel` here, or None when they can."""
    if not sys.platform.startswith("linux") or not hasattr(socket, "AF_CAN"):
        return f"SocketCAN needs Linux; this is {sys.platform}"
    if not Path(f"/sys/class/net/{channel}").exists():
        return (
            f"no SocketCAN interface {channel!r} on this machine (create it, e.g. "
            f"`ip link add {channel} type vcan`, or name another with --gyrostand-channel "
            f"or {CHANNEL_ENV})"
        )
    return None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    marked = [item for item in items if item.get_closest_marker("socketcan") is not None]
    if not marked:
        return
    reason = socketcan_missing(channel_name(config))
    if reason is not None:
        for item in marked:
            item.add_marker(pytest.mark.skip(reason=reason))


@pytest.fixture(scope="session")
def socketcan_channel(pytestconfig: pytest.Config) -> str:
    """The SocketCAN channel to test on; the test is skipped with the reason when it is absent."""
    channel = channel_name(pytestconfig)
    reason = socketcan_missing(channel)
    if reason is not None:
        pytest.skip(reason)
    return channel


def _defaults(config: pytest.Config) -> dict[str, Any]:
    """The stand's keyword arguments from the command line and the environment."""
    out: dict[str, Any] = {
        "interface": config.getoption("gyrostand_bus") or os.environ.get(BUS_ENV)
    }
    if config.getoption("gyrostand_dbc"):
        out["dbc"] = config.getoption("gyrostand_dbc")
    if config.getoption("gyrostand_signals"):
        out["signals"] = config.getoption("gyrostand_signals")
    return out


@pytest.fixture
def gyro_stand_factory(pytestconfig: pytest.Config) -> Iterator[Callable[..., SimulatedStand]]:
    """`make(**knobs)`: a simulated gyrocompass + roll stand started on its bus, stopped after
    the test. Knobs: compass, noise, faults, stand, inclinometer (dicts of their fields), seed,
    timing ("virtual" or "realtime"), speedup, heading_rate_hz, status_rate_hz; dbc (path) and
    signals (a [signals] mapping, or a TOML file holding one); protocol, what the compass speaks
    ("gyrostand"; "nmea2000", with nmea2000={model, serial, address, address_change_at_s,
    new_address, not_available_rate}; "cia406", with cia406={node_id, counts_per_revolution,
    zero_counts, direction, heartbeat_ms, sync_id, encoder_silence_at_s, encoder_silence_for_s,
    emcy_at_s}); interface ("virtual" or "socketcan") and channel. The
    command line's --gyrostand-* options are the defaults."""
    closing = ExitStack()  # every stand stopped, even when one fails to stop

    def make(**knobs: Any) -> SimulatedStand:
        from gyrostand.simulated_stand import (
            SimulatedStand,
            StandSetupError,
            StandSpec,
            read_signals,
        )

        given = {**_defaults(pytestconfig), **knobs}
        interface = given.pop("interface", None) or "virtual"
        channel = given.pop("channel", None)
        if interface == "socketcan":
            channel = channel or channel_name(pytestconfig)
            reason = socketcan_missing(channel)
            if reason is not None:
                pytest.skip(reason)
        dbc = given.pop("dbc", None)
        signals = given.pop("signals", None) or {}
        protocol = given.pop("protocol", "gyrostand")
        n2k = given.pop("nmea2000", None) or {}
        encoder = given.pop("cia406", None) or {}
        try:
            if isinstance(signals, str | Path):
                signals = read_signals(Path(signals))
            spec = StandSpec(
                simulator=given,
                dbc=Path(dbc).resolve() if dbc else None,
                signals=signals,
                interface=interface,
                channel=channel,
                protocol=protocol,
                nmea2000=n2k,
                cia406=encoder,
            )
            stand = SimulatedStand(spec)
        except StandSetupError as exc:
            reason = str(exc)
        else:
            closing.callback(stand.close)
            return stand
        pytest.fail(reason, pytrace=False)

    with closing:
        yield make


@pytest.fixture
def gyro_stand(
    request: pytest.FixtureRequest, gyro_stand_factory: Callable[..., SimulatedStand]
) -> SimulatedStand:
    """The simulated gyrocompass + roll stand, as `@pytest.mark.gyro_stand(**knobs)` sets it
    (`gyro_stand_factory`'s knobs; none: gyrostand's defaults, seed 0, virtual time)."""
    marker = request.node.get_closest_marker("gyro_stand")
    return gyro_stand_factory(**(marker.kwargs if marker else {}))


@pytest.fixture
def gyro_serial_compass() -> Iterator[Callable[..., str]]:
    """`start(**knobs)`: the simulated compass speaking IEC 61162 (NMEA 0183) on a
    pseudo-terminal pair in real time, as `gyrostand simulate --protocol iec61162` does; returns
    the port's path to open (pyserial, or the code under test). Knobs: baud, talker, sentences
    (e.g. ("THS", "ROT")), rate_hz, seed, and the line faults checksum_error_rate,
    garbage_rate, not_valid_rate, line_silence_at_s, line_silence_for_s, sender_baud. Stopped
    after the test."""
    import threading

    from gyrostand.devices.serial_config import LineFaults
    from gyrostand.devices.serial_sim import (
        PtyLine,
        SerialCompass,
        SerialCompassConfig,
        SerialSimError,
        write_realtime,
    )
    from gyrostand.stand.simconfig import SimConfig

    closing = ExitStack()

    def start(**knobs: Any) -> str:
        fault_names = {f.name for f in fields(LineFaults)}
        faults = LineFaults(**{k: knobs.pop(k) for k in list(knobs) if k in fault_names})
        try:
            config = SerialCompassConfig(**knobs, faults=faults)
            config.check()
        except (SerialSimError, TypeError) as exc:
            pytest.fail(f"gyro_serial_compass: {exc}", pytrace=False)
        compass = SerialCompass(config)
        engine = compass.stand(SimConfig(seed=config.seed, heading_rate_hz=config.rate_hz))
        line = PtyLine(config.baud)
        stop = threading.Event()
        writer = threading.Thread(
            target=write_realtime,
            args=(compass.line(engine), line.write, config.baud),
            kwargs={"stop": stop.is_set},
            daemon=True,
        )
        writer.start()

        def close() -> None:
            stop.set()
            writer.join()
            line.close()

        closing.callback(close)
        return line.path

    with closing:
        yield start


@pytest.fixture
def gyro_campaign(
    gyro_stand: SimulatedStand, tmp_path: Path
) -> Callable[[str | Path], CampaignRun]:
    """`run(plan_path)`: the plan's campaign acquired from `gyro_stand` into a SQLite file in
    the test's temporary folder, analysed; a `CampaignRun` (campaign id, outcome, counts,
    database, `analysis`)."""

    def run(plan: str | Path) -> CampaignRun:
        from gyrostand.stand_campaign import CampaignNotRun, run_plan

        folder = tmp_path / f"campaign-{len(list(tmp_path.glob('campaign-*'))) + 1}"
        folder.mkdir()
        try:
            return run_plan(gyro_stand, Path(plan), folder)
        except CampaignNotRun as exc:
            reason = str(exc)
        pytest.fail(reason, pytrace=False)

    return run
