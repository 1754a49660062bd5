"""The simulated gyrocompass + roll stand on a python-can bus, as a test hands it to a user's own
software: a node on python-can's `virtual` bus (in this process) or on a SocketCAN channel,
speaking gyrostand's DBC or a lab's (its DBC and the `[signals]` map a plan uses), in virtual time
by default: its clock moves only when the test says so (`advance`), so a test gets the same
frames at any machine load. `gyrostand.pytest_plugin` builds it from fixture parameters."""

from __future__ import annotations

import threading
import tomllib
import uuid
import warnings
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import can
from can.interfaces.virtual import VirtualBus, channels_lock
from pydantic import BaseModel, ValidationError

from gyrostand.acquisition.bus import SimulatorBus
from gyrostand.devices.nmea2000 import Product
from gyrostand.devices.sim_cia406 import simulated_encoder
from gyrostand.devices.sim_nmea2000 import Nmea2000Compass, Nmea2000Device, Nmea2000Faults
from gyrostand.stand.engine import HeadingTransmitter, ReceivedCommand
from gyrostand.stand.protocol import Codec, ProtocolError
from gyrostand.stand.simconfig import (
    FaultParams,
    SimConfig,
    SimConfigError,
    renamed_knobs,
    simulator_config,
    simulator_tables,
)
from gyrostand.stand.simulator import Simulator
from gyrostand.stand.virtual_time import clock_message, encode_sync, sync_message

INTERFACES = ("virtual", "socketcan")
N2K_KNOBS: dict[str, Any] = {  # the simulated NMEA 2000 compass (`devices.sim_nmea2000`)
    "model": "simulated compass",
    "serial": "SIM-1",
    "address": 35,
    "address_change_at_s": None,
    "new_address": 36,
    "not_available_rate": 0.0,
}
_TABLES = ("compass", "noise", "faults", "stand")


class StandSetupError(ValueError):
    """Parameters the simulated stand cannot take; the text is one line naming each problem."""


@dataclass(frozen=True)
class StandSpec:
    """What to simulate and where: the `[bus.simulator]` tables of a plan as keyword arguments
    (`compass`, `noise`, `faults`, `stand`, and `seed`, `timing`, `speedup`,
    `heading_rate_hz`, `status_rate_hz`), the DBC and `[signals]` map, the bus."""

    simulator: Mapping[str, Any] = field(default_factory=dict)
    dbc: Path | None = None
    signals: Mapping[str, str] = field(default_factory=dict)
    interface: str = "virtual"
    channel: str | None = None
    protocol: str = "gyrostand"  # what the compass speaks: "gyrostand", "nmea2000", "cia406"
    nmea2000: Mapping[str, Any] = field(default_factory=dict)  # its `N2K_KNOBS`
    cia406: Mapping[str, Any] = field(default_factory=dict)  # `devices.encoder_knobs.KNOBS`

    def config(self) -> SimConfig:
        """The SimConfig (StandSetupError naming every unknown or inconsistent knob)."""
        tables = simulator_tables()
        for table, old, new in renamed_knobs(self.simulator):
            warnings.warn(
                f"simulated stand: {table}.{old} is spelled {new} now (the old spelling is "
                "still read)",
                DeprecationWarning,
                stacklevel=2,
            )
        try:
            return simulator_config(tables.model_validate(dict(self.simulator)))
        except ValidationError as exc:
            problems = [
                f"{'.'.join(map(str, e['loc']))}: {e['msg']}"
                + (_known_knobs(tables, e["loc"]) if e["type"] == "extra_forbidden" else "")
                for e in exc.errors(include_url=False)
            ]
            raise StandSetupError("simulated stand: " + "; ".join(problems)) from None
        except SimConfigError as exc:
            problems = [f"{path}: {text}" for path, text in exc.problems]
            raise StandSetupError("simulated stand: " + "; ".join(problems)) from None

    def transmitter(self) -> HeadingTransmitter | None:
        """The compass's own protocol (None: the DBC's heading frame); StandSetupError naming
        an unknown protocol or knob."""
        if self.protocol == "gyrostand" and not (self.nmea2000 or self.cia406):
            return None
        if self.protocol == "cia406" and not self.nmea2000:
            try:
                return simulated_encoder(self.cia406)
            except ValueError as exc:
                raise StandSetupError(f"simulated stand: {exc}") from None
        if self.protocol != "nmea2000" or self.cia406:
            raise StandSetupError(
                f"simulated stand: protocol {self.protocol!r} is not one of gyrostand, nmea2000, "
                "cia406, or has the knobs of another"
            )
        unknown = sorted(set(self.nmea2000) - set(N2K_KNOBS))
        if unknown:
            raise StandSetupError(f"simulated stand: unknown nmea2000 knob(s) {', '.join(unknown)}")
        k = {**N2K_KNOBS, **self.nmea2000}
        device = Nmea2000Device(Product(k["model"], k["serial"], "1.0"), address=k["address"])
        faults = Nmea2000Faults(k["address_change_at_s"], k["new_address"], k["not_available_rate"])
        return Nmea2000Compass(device, faults, int(self.simulator.get("seed", 0)))

    def codec(self) -> Codec:
        try:
            return Codec.of(self.dbc, self.signals)
        except ProtocolError as exc:
            raise StandSetupError(f"simulated stand: {exc}") from None


def read_signals(path: Path) -> dict[str, str]:
    """The `[signals]` table of a TOML file (a plan, or a file holding only that table)."""
    try:
        table = tomllib.loads(path.read_text()).get("signals")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise StandSetupError(f"signal map {path}: {exc}") from None
    if not isinstance(table, dict):
        raise StandSetupError(f"signal map {path}: no [signals] table")
    return table


class SendOnlyBus(VirtualBus):
    """A node of python-can's virtual bus that only sends: it keeps no queue of the frames the
    others send (the stand's clock messages would pile up in it)."""

    def __init__(self, channel: str) -> None:
        super().__init__(channel=channel)
        with channels_lock:
            self.channel.remove(self.queue)

    def shutdown(self) -> None:
        with channels_lock:  # back in place for VirtualBus.shutdown to take out
            self.channel.append(self.queue)
        super().shutdown()


class _Counts(can.Listener):
    """Frames the stand sent, by arbitration ID (error frames apart)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.by_id: Counter[int | None] = Counter()

    def on_message_received(self, msg: can.Message) -> None:
        with self._lock:
            self.by_id[None if msg.is_error_frame else msg.arbitration_id] += 1

    def snapshot(self) -> Counter[int | None]:
        with self._lock:
            return Counter(self.by_id)


class SimulatedStand:
    """The simulated gyrocompass + roll stand running on its bus (`interface`, `channel`) until
    `close()`. `open_bus()` gives the test's own nodes on the same bus."""

    def __init__(self, spec: StandSpec, *, sim_bus: can.BusABC | None = None) -> None:
        """`sim_bus`: the stand's own node, instead of one on `spec`'s bus (tests of how the
        stand meets a failing bus)."""
        if spec.interface not in INTERFACES:
            raise StandSetupError(
                f"simulated stand: interface {spec.interface!r} is not one of "
                f"{', '.join(INTERFACES)}"
            )
        self.spec = spec
        self.config = spec.config()
        self.codec = spec.codec()
        self.interface = spec.interface
        # a virtual channel name not ending in digits: log writers would take those for a number
        self.channel = spec.channel or f"gyrostand-{uuid.uuid4().hex}-sim"
        self._buses: list[can.BusABC] = []
        self._counts = _Counts()
        virtual = self.interface == "virtual"
        if sim_bus is None:
            sim_bus = SimulatorBus(channel=self.channel) if virtual else self._open()
        self._buses.append(sim_bus)
        try:
            # the test's clock: sends SIM_SYNC, receives nothing
            self._control = (
                SendOnlyBus(self.channel)
                if virtual
                else self._open(
                    can_filters=[{"can_id": sync_message().frame_id, "can_mask": 0x7FF}]
                )
            )
            self._buses.append(self._control)
            self.simulator = Simulator(
                sim_bus,
                self.config,
                codec=self.codec,
                recorder=self._counts,
                start_epoch_s=0.0,
                transmitter=spec.transmitter(),
            )
            self.simulator.start()
        except BaseException:
            self._shutdown()
            raise

    def _open(self, **kwargs: Any) -> can.BusABC:
        return can.Bus(interface=self.interface, channel=self.channel, **kwargs)

    def open_bus(self, **kwargs: Any) -> can.BusABC:
        """Another node on the stand's bus (python-can keyword arguments: `can_filters`, ...),
        shut down with the stand."""
        bus = self._open(**kwargs)
        self._buses.append(bus)
        return bus

    @property
    def stand_time_s(self) -> float:
        """How far the stand has run (its frames up to here are on the bus)."""
        return self.simulator.stand_time_s

    def advance(self, seconds: float, timeout_s: float = 120.0) -> None:
        """Let the stand run `seconds` of stand time further and return once its frames are on
        the bus. In virtual time the stand stops there until the next call, and commands sent
        in between take effect at exactly this stand time; in real time it runs on by itself
        and this waits for it. `timeout_s` of wall time bounds a hang."""
        if not seconds >= 0:
            raise ValueError(f"advance needs seconds >= 0, got {seconds}")
        now_ms = round(self.stand_time_s * 1000)
        target_ms = now_ms + round(seconds * 1000)
        if self.config.timing == "virtual":
            self._control.send(encode_sync(now_ms, target_ms - now_ms))
        self.simulator.wait_until(target_ms / 1000, timeout_s + seconds / self.config.speedup)

    @property
    def commands(self) -> list[ReceivedCommand]:
        """Every command the stand received, in order, with its stand time and answer."""
        return list(self.simulator.engine.received)

    def frames_per_message(self) -> dict[str, int]:
        """How many frames the stand sent, by DBC message name ("error frame" for error frames,
        SIM_CLOCK for virtual time's clock; an ID of no DBC message as 0xNNN)."""
        names = {m.frame_id: m.name for m in self.codec.database.messages}
        names[clock_message().frame_id] = clock_message().name
        return {
            "error frame" if key is None else names.get(key, f"0x{key:X}"): n
            for key, n in sorted(self._counts.snapshot().items(), key=lambda kv: kv[0] or -1)
        }

    def frames_of(self, key: str) -> int:
        """How many frames the stand sent of the message carrying the signal-map entry `key`
        ("heading", "status_time", "ack_command", ...: the `[signals]` keys), whatever the
        DBC calls it."""
        layout = self.codec.layout([key])
        if not layout:
            raise StandSetupError(f"frames_of: no signal-map entry {key!r} in this stand's map")
        ((message, _),) = layout
        return self._counts.snapshot()[message.frame_id]

    def inject_fault(self, **knobs: Any) -> FaultParams:
        """Change fault knobs (`FaultParams` fields) from the current stand time on: in virtual
        time exactly at `stand_time_s`. Windows (`silence_at_s`, `stuck_at_s`) are stand times;
        omitted, they open now. The new knobs (StandSetupError for unknown or bad ones)."""
        known = {f.name for f in fields(FaultParams)}
        unknown = sorted(set(knobs) - known)
        if unknown:
            raise StandSetupError(f"inject_fault: unknown fault knob(s) {', '.join(unknown)}")
        now = self.stand_time_s
        for window in ("silence", "stuck"):
            if f"{window}_for_s" in knobs and f"{window}_at_s" not in knobs:
                knobs[f"{window}_at_s"] = now
        try:
            config = replace(self.config, faults=replace(self.config.faults, **knobs))
        except SimConfigError as exc:
            raise StandSetupError(f"inject_fault: {exc}") from None
        self.config = config
        self.simulator.inject_faults(config.faults)
        return config.faults

    def close(self) -> None:
        """Stop the stand (re-raising what made it fail) and shut every bus."""
        try:
            self.simulator.stop()
        finally:
            self._shutdown()

    def _shutdown(self) -> None:
        for bus in reversed(self._buses):
            bus.shutdown()
        self._buses.clear()

    def __enter__(self) -> SimulatedStand:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _known_knobs(tables: type[BaseModel], loc: tuple[Any, ...]) -> str:
    """For an unknown knob at `loc`: the one meant when only its case differs (LP_gcm2s2 for
    lp_gcm2s2), and the valid names."""
    model: Any = tables
    for key in loc[:-1]:
        table = model.model_fields.get(key) if isinstance(key, str) else None
        if table is None or not isinstance(table.annotation, type):
            return ""
        model = table.annotation
    names = list(model.model_fields)
    meant = [n for n in names if n.lower() == str(loc[-1]).lower()]
    hint = f" (did you mean {meant[0]}?)" if meant else ""
    return f"{hint}; valid: {', '.join(names)}"
