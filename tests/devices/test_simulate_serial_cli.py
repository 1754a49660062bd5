"""`gyrostand simulate --protocol iec61162`: the TAG-block log of a schedule (reproducible, the
stand's headings), live sentences on a pseudo-terminal it opens, one-line errors."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from gyrostand import cmd_simulate
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.tagblock import read_tag_log
from tests.devices.serial_reading import HANG_GUARD_S, ReceptionClock, read_headings

app = typer.Typer()
cmd_simulate.register(app)


@app.callback()
def _root() -> None:
    """Test root: keeps `simulate` a subcommand as in the real CLI."""


def invoke(*args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(app, ["simulate", "--protocol", "iec61162", *args])


def test_schedule_into_a_tag_block_log_is_reproducible(tmp_path: Path) -> None:
    args = ["--step", "still 20", "--step", "rock 45 20 8 30", "--start-epoch", "1700000000"]
    a, b = tmp_path / "a.nmea", tmp_path / "b.nmea"
    for log in (a, b):
        result = invoke(*args, "--sentences", "THS", "--log", str(log))
        assert result.exit_code == 0, result.output
    assert a.read_bytes() == b.read_bytes()
    assert "501 lines (sentences and junk), 50 s of stand time" in result.output
    epoch = ReceptionClock(1_700_000_000_000)  # --start-epoch
    out = Iec61162Source(4800).decode_pieces(list(read_tag_log(a)), epoch)
    assert out.invalid == () and len(out.headings) == 501
    assert out.headings.t_ms.tolist() == list(range(0, 50_001, 100))
    # the stand's headings: at rest, the simulated compass's true heading plus its noise
    assert abs(out.headings.heading_deg[:200].mean() - 120.0) < 0.05


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--step", "still 1", "--log", "x.blf"], "needs --log FILE.nmea"),
        (["--step", "still 1", "--log", "x.nmea", "--heading-rate-hz", "50"], "2000 bytes/s"),
        (["--step", "still 1", "--log", "x.nmea", "--sentences", "GGA"], "some of HDT, THS"),
        (["--port", "/dev/ttyGYRO404", "--duration-s", "1"], "/dev/ttyGYRO404: cannot open"),
        (["--interface", "virtual", "--channel", "x"], "no --interface"),
        (["--step", "still 1", "--log", "x.nmea", "--garbage-rate", "2"], "garbage_rate 2 is not"),
        (["--step", "still 1", "--log", "x.nmea", "--baud", "0"], "baud 0 is not a baud rate"),
    ],
)
def test_bad_input_is_one_line(args: list[str], message: str, tmp_path: Path) -> None:
    os.chdir(tmp_path)
    result = invoke(*args)
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gyrostand: error: ") and message in lines[0]


def test_live_on_a_pseudo_terminal_it_opens() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "gyrostand", "simulate", "--protocol", "iec61162"]
        + ["--duration-s", "600", "--sentences", "HDT,ROT"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        path = proc.stdout.readline().strip()  # the path, alone on its line
        assert path.startswith("/dev/pts/")
        headings, _ = read_headings(path, 4800, 5)
        assert len(headings) >= 5 and all(abs(h - 120.0) < 1.0 for h in headings)
    finally:
        proc.terminate()
        proc.wait(HANG_GUARD_S)
