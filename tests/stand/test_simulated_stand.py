"""The plugin's stand on its bus against the same simulation run directly: in virtual time the
frames on the bus are the StandEngine's frame for frame, and commands and injected faults take
effect at the stand time the test reached."""

import can
import pytest

from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec
from tests.stand.frames import config, headings

KNOBS = {"seed": 4, "noise": {"white_sigma_deg": 0.02}}


def received(bus: can.BusABC) -> list[can.Message]:
    return list(iter(lambda: bus.recv(timeout=0), None))


def payloads(frames: list[can.Message]) -> list[tuple[int, bytes]]:
    return [(m.arbitration_id, bytes(m.data)) for m in frames]


@pytest.mark.gyro_stand(**KNOBS)
def test_frames_on_the_bus_are_the_simulation_step_by_step(gyro_stand) -> None:
    bus = gyro_stand.open_bus()
    for _ in range(3):  # steps of 7.3 s: the clock stops exactly where the test says
        gyro_stand.advance(7.3)
    assert gyro_stand.stand_time_s == pytest.approx(21.9)
    on_bus = [m for m in received(bus) if m.arbitration_id < 0x7F0]  # virtual time's apart
    direct = StandEngine(config(**KNOBS)).advance_to(21.9)
    assert payloads(on_bus) == payloads(direct)
    t_s, _, _ = headings(on_bus)
    assert len(t_s) == 220 and t_s[-1] == pytest.approx(21.9)  # 10 Hz, 0 to 21.9 s


@pytest.mark.gyro_stand(**KNOBS)
def test_commands_take_effect_at_the_stand_time_reached(gyro_stand) -> None:
    bus, codec = gyro_stand.open_bus(), Codec()
    gyro_stand.advance(12.0)
    bus.send(codec.encode_command("set", 45.0, 30.0, 5.0))
    bus.send(codec.encode_command("start"))
    bus.send(codec.encode_command("set", 45.0, 99.0, 5.0))  # beyond the stand's 50 cm
    gyro_stand.advance(3.0)
    assert [(c.stand_time_s, c.command.command, c.answer) for c in gyro_stand.commands] == [
        (12.0, "set", "accepted"),
        (12.0, "start", "accepted"),
        (12.0, "set", "busy: stop rocking first"),
    ]
    engine = StandEngine(config(**KNOBS))  # the same commands at 12 s, run directly
    engine.advance_to(12.0)
    for msg in (codec.encode_command("set", 45.0, 30.0, 5.0), codec.encode_command("start")):
        engine.receive(msg)
    expected = [m for m in engine.advance_to(15.0) if m.arbitration_id == 0x100]
    on_bus = [m for m in received(bus) if m.arbitration_id == 0x100]
    assert payloads(on_bus[-30:]) == payloads(expected)


@pytest.mark.gyro_stand(**KNOBS)
def test_injected_faults_start_at_the_stand_time_reached(gyro_stand) -> None:
    gyro_stand.advance(5.0)
    gyro_stand.inject_fault(drop_rate=1.0, compass_fault_bits=4)
    gyro_stand.advance(5.0)
    assert gyro_stand.frames_of("heading") == 51  # 0 to 5 s; none after
    assert gyro_stand.frames_of("compass_rotor") == 21  # GYRO_STATUS keeps coming at 2 Hz
    assert gyro_stand.config.faults.compass_fault_bits == 4
