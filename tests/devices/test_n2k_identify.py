"""Identification on a real bus: gyrostand's ISO Requests (PGN 59904 from the null address)
read by the reference codec; the simulated compass answering them as a device does, in virtual
time at its stand time, deterministically; the check of its product information against the
plan before anything is stored."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import can
import pytest
from nmea2000 import NMEA2000Decoder
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.devices.n2k_identify import Identification, IdentificationError, identify
from gyrostand.devices.nmea2000 import (
    ADDRESS_CLAIM,
    PRODUCT_INFORMATION,
    Product,
    ReferenceDecoder,
    ReferenceEncoder,
    can_id,
    iso_name,
    iso_requests,
    requested_pgn,
)
from gyrostand.devices.sim_nmea2000 import Nmea2000Compass, Nmea2000Device
from gyrostand.stand.simulator import Simulator
from tests.acquisition.harness import plan_text, quick_config

PRODUCT = Product("test compass", "T-1", "1.0")
DEVICE = Nmea2000Device(PRODUCT, address=35)


def test_the_requests_as_the_reference_reads_them() -> None:
    decoder = NMEA2000Decoder()
    asked = []
    for msg in iso_requests():
        decoded = decoder.decode(msg)
        assert decoded is not None and decoded.PGN == 59904
        assert (decoded.source, decoded.destination) == (254, 255)  # null address, to all
        assert len(msg.data) == 3
        asked.append(int(decoded.get_field_by_id("pgn").raw_value))
    assert asked == [ADDRESS_CLAIM, PRODUCT_INFORMATION]


def test_a_request_is_for_its_destination_or_all() -> None:
    to_36 = can.Message(arbitration_id=can_id(59904, 254, 6, 36), data=b"\x00\xee\x00")
    assert requested_pgn(to_36, 36) == ADDRESS_CLAIM
    assert requested_pgn(to_36, 35) is None
    (to_all, _) = iso_requests()
    assert requested_pgn(to_all, 35) == requested_pgn(to_all, 36) == ADDRESS_CLAIM
    heading = can.Message(arbitration_id=can_id(127250, 35, 2), data=bytes(8))
    assert requested_pgn(heading, 35) is None


def test_the_compass_answers_as_a_device_does() -> None:
    compass = Nmea2000Compass(DEVICE)
    claim_request, product_request = iso_requests()
    other = can.Message(arbitration_id=can_id(59904, 254, 6), data=(127250).to_bytes(3, "little"))
    assert compass.answers(claim_request) and compass.answers(product_request)
    assert not compass.answers(other)
    decoder = ReferenceDecoder()
    (claim,) = compass.answer(claim_request, 12.5)
    assert claim.arbitration_id & 0xFF == 35 and claim.timestamp == 12.5
    assert decoder.decode(claim) == DEVICE.name
    frames = compass.answer(product_request, 12.5)
    assert len(frames) > 1  # fast-packet
    assert [decoder.decode(f) for f in frames][-1] == PRODUCT


@pytest.mark.parametrize(("unique", "address"), [(1, 36), (99999, 35)], ids=["loses", "wins"])
def test_a_claim_of_its_address_is_arbitrated_by_name(unique: int, address: int) -> None:
    """ISO 11783-5: the lower NAME keeps the address; the compass (NAME unique number 4242)
    claims its new address (36) when it loses, claims its own again when it wins."""
    compass = Nmea2000Compass(DEVICE)
    intruder = ReferenceEncoder().address_claim(iso_name(unique), 35, 1.0)[0]
    assert compass.answers(intruder)
    (claim,) = compass.answer(intruder, 2.0)
    assert claim.arbitration_id & 0xFF == address and compass.address == address
    assert ReferenceDecoder().decode(claim) == DEVICE.name
    assert not compass.answers(ReferenceEncoder().address_claim(iso_name(1), 41, 3.0)[0])


@pytest.fixture
def channel() -> str:
    return f"identify-{uuid.uuid4().hex}-bus"


def simulated(channel: str, timing: str = "virtual") -> Simulator:
    """The simulated stand, its compass speaking NMEA 2000; in virtual time, until a SIM_SYNC
    lets it run, its stand time stays 0."""
    return Simulator(
        can.Bus(interface="virtual", channel=channel),
        replace(quick_config(), timing=timing),
        recorder=can.BufferedReader(),  # what it sends, at stand time (python-can's virtual
        start_epoch_s=0.0,  # bus stamps frames with their reception time)
        transmitter=Nmea2000Compass(DEVICE),
    )


@pytest.fixture
def compass_on(channel: str) -> Iterator[Simulator]:
    simulator = simulated(channel)
    with simulator:
        yield simulator
    simulator.bus.shutdown()


def answers(channel: str) -> list[tuple[int, bytes, float]]:
    """The frames on the bus after the requests to a new simulated stand, with the stand time
    it sent them at."""
    simulator = simulated(channel)
    with simulator, can.Bus(interface="virtual", channel=channel) as bus:
        for msg in iso_requests():
            bus.send(msg)
        got = []
        while (msg := bus.recv(timeout=0.3)) is not None:
            sent = simulator._recorder.get_message(0)  # type: ignore[union-attr]
            assert sent is not None and sent.data == msg.data
            got.append((msg.arbitration_id, bytes(msg.data), sent.timestamp))
    simulator.bus.shutdown()
    return got


def test_in_virtual_time_it_answers_at_its_stand_time_deterministically(channel: str) -> None:
    first, again = answers(channel), answers(channel + "2")
    assert first == again  # the same frames, at the same stand time
    requests = [(m.arbitration_id, bytes(m.data)) for m in iso_requests()]
    assert [f[:2] for f in first if f[0] & 0xFF == 254] == requests  # echoed into the stream
    assert {f[2] for f in first} == {0.0}  # stand time 0: it has not run
    decoder = ReferenceDecoder()
    msgs = [can.Message(arbitration_id=i, data=d, is_extended_id=True) for i, d, _ in first]
    assert [x for x in map(decoder.decode, msgs) if x is not None] == [DEVICE.name, PRODUCT]


@pytest.mark.usefixtures("compass_on")
def test_identify_finds_the_plans_compass(channel: str) -> None:
    with can.Bus(interface="virtual", channel=channel) as bus:
        identify(bus, None, ("test compass", "T-1"))
        identify(bus, DEVICE.name, ("test compass", "T-1"))


@pytest.mark.usefixtures("compass_on")
def test_a_named_compass_with_another_product_is_one_line_at_once(channel: str) -> None:
    with (
        can.Bus(interface="virtual", channel=channel) as bus,
        pytest.raises(IdentificationError) as caught,
    ):
        identify(bus, DEVICE.name, ("test compass", "T-2"), timeout_wall_s=30.0)
    assert str(caught.value) == (
        f"the compass (NAME 0x{DEVICE.name:016X}, address 35) is model 'test compass', "
        "serial 'T-1', not the plan's [instrument] (model 'test compass', serial 'T-2')"
    )


@pytest.mark.usefixtures("compass_on")
def test_no_device_with_the_plans_product_names_what_answered(channel: str) -> None:
    with (
        can.Bus(interface="virtual", channel=channel) as bus,
        pytest.raises(IdentificationError) as caught,
    ):
        identify(bus, None, ("test compass", "T-2"), timeout_wall_s=0.5)
    assert str(caught.value) == (
        "none of the NMEA 2000 devices that answered within 0.5 s is the plan's [instrument] "
        f"(model 'test compass', serial 'T-2'): address 35 (NAME 0x{DEVICE.name:016X}) is "
        "model 'test compass', serial 'T-1'"
    )


def test_a_silent_bus_is_one_line(channel: str) -> None:
    with (
        can.Bus(interface="virtual", channel=channel) as bus,
        pytest.raises(IdentificationError, match="^no NMEA 2000 device answered the request"),
    ):
        identify(bus, None, ("test compass", "T-1"), timeout_wall_s=0.2)


def test_an_address_change_moves_the_device() -> None:
    heard = Identification(None, ("test compass", "T-1"))
    compass = Nmea2000Compass(DEVICE)
    claim_request, product_request = iso_requests()
    for msg in compass.answer(claim_request, 0.0):
        heard.feed(msg)
    compass.address = 36
    for msg in [*compass.answer(claim_request, 1.0), *compass.answer(product_request, 1.0)]:
        heard.feed(msg)
    assert list(heard.devices) == [36] and heard.verdict() == ""


def test_campaign_run_with_another_compass_is_one_line_and_stores_nothing(
    tmp_path: Path, channel: str
) -> None:
    """The plan's instrument is serial T-2; the compass on the bus (running: in real time, as
    a compass timed by reception needs) answers T-1."""
    db = tmp_path / "db.sqlite"
    plan = tmp_path / "plan.toml"
    bus = f'simulated = false\ninterface = "virtual"\nchannel = "{channel}"\ntiming = "realtime"'
    text = plan_text(database=str(db), raw_dir=str(tmp_path / "raw"))
    text = text.replace("simulated = true", bus).replace('serial = "T-1"', 'serial = "T-2"')
    plan.write_text(text + '\n[compass]\nprotocol = "nmea2000"\n')
    with simulated(channel, "realtime") as simulator:
        result = CliRunner().invoke(app, ["campaign", "run", str(plan), "--quiet"])
    simulator.bus.shutdown()
    assert result.exit_code == 1, result.output
    assert result.stderr.count("\n") == 1
    assert result.stderr.startswith(
        "gyrostand: error: none of the NMEA 2000 devices that answered within 2 s is the plan's "
        "[instrument] (model 'test compass', serial 'T-2'): address 35 (NAME 0x"
    )
    assert result.stderr.endswith(") is model 'test compass', serial 'T-1'\n")
    assert not db.exists()  # nothing stored
