"""`gyrostand simulate --protocol cia406`: the encoder's TPDOs carry the same compass readings as
gyrostand's heading frame (same seed), at the encoder's resolution and mounting; its heartbeat
and an EMCY on the bus; a bad knob is one line."""

from __future__ import annotations

import struct
from pathlib import Path

import can
import numpy as np
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.stand.protocol import Codec

runner = CliRunner()


def simulate(log: Path, *args: str) -> list[can.Message]:
    result = runner.invoke(app, ["simulate", "--step", "still 1", "--log", str(log), *args])
    assert result.exit_code == 0, result.output
    return list(can.LogReader(str(log)))


def test_the_tpdos_carry_the_compass_readings(tmp_path: Path) -> None:
    plain = simulate(tmp_path / "plain.asc")
    codec = Codec()
    heading = codec.database.get_message_by_name("GYRO_HEADING")
    reference = {
        round(m.timestamp, 3): heading.decode(bytes(m.data))["HEADING"]
        for m in plain
        if m.arbitration_id == heading.frame_id
    }
    frames = simulate(
        tmp_path / "encoder.asc",
        *("--protocol", "cia406", "--node-id", "9", "--counts-per-revolution", "8192"),
        *("--zero-counts", "100", "--direction", "counterclockwise", "--emcy-at-s", "0.5"),
    )
    tpdo = [m for m in frames if m.arbitration_id == 0x189]
    assert len(tpdo) == len(reference) == 11
    counts = np.array([struct.unpack("<I", bytes(m.data))[0] for m in tpdo])
    got = ((100 - counts) % 8192) * 360.0 / 8192  # counter-clockwise from 100 counts
    want = np.array([reference[round(m.timestamp, 3)] for m in tpdo])
    wrapped = (got - want + 180.0) % 360.0 - 180.0
    assert np.abs(wrapped).max() <= 360.0 / 8192 / 2 + 1e-3  # (+ the DBC's 0.001 deg)
    beats = [(m.timestamp, m.data[0]) for m in frames if m.arbitration_id == 0x709]
    assert beats == [(0.0, 0), (0.0, 5), (1.0, 5)]  # boot-up, OPERATIONAL every 1000 ms
    (emcy,) = [m for m in frames if m.arbitration_id == 0x89]
    assert emcy.timestamp == 0.5 and bytes(emcy.data)[:3] == b"\x00\x10\x01"


def test_a_bad_knob_is_one_line(tmp_path: Path) -> None:
    args = ["simulate", "--step", "still 1", "--log", str(tmp_path / "x.asc")]
    result = runner.invoke(app, [*args, "--protocol", "cia406", "--node-id", "0"])
    assert result.exit_code != 0 and not (tmp_path / "x.asc").exists()
    assert result.output.strip().splitlines() == [
        "gyrostand: error: --protocol cia406: node_id 0 is not a CANopen node id (1-127)"
    ]
