"""`gyrostand simulate`: documented options, standalone logs readable with python-can + the DBC,
live mode on a virtual bus, one-line errors."""

import threading
import uuid
from dataclasses import MISSING, fields
from pathlib import Path

import can
import cantools
import pytest
import typer
from typer.testing import CliRunner

from gyrostand import cmd_simulate
from gyrostand.stand.protocol import DBC_PATH
from gyrostand.stand.simulator import (
    CompassParams,
    FaultParams,
    NoiseParams,
    SimConfig,
    StandParams,
)

runner = CliRunner()
app = typer.Typer()
cmd_simulate.register(app)


@app.callback()
def _root() -> None:
    """Test root: keeps `simulate` a subcommand as in the real CLI."""


def invoke(*args: str) -> object:
    return runner.invoke(app, ["simulate", *args], env={"COLUMNS": "250"})


def test_help_documents_every_parameter() -> None:
    result = invoke("--help")
    assert result.exit_code == 0
    for cls in (SimConfig, CompassParams, NoiseParams, StandParams, FaultParams):
        for f in fields(cls):
            if f.default is MISSING:
                continue
            assert "--" + f.name.lower().replace("_", "-") in result.output, f.name
            assert f.metadata["help"][:40] in result.output, f.name
    for option in ("--interface", "--channel", "--schedule", "--step", "--log"):
        assert option in result.output


SCHEDULE = ["--step", "still 60", "--step", "rock 31 23.5 6.2 300", "--step", "still 60"]


def decode_log(path: Path) -> list[tuple[float, str, dict]]:
    """Every frame of a log, read by python-can and decoded by cantools with the DBC alone."""
    db = cantools.database.load_file(DBC_PATH)
    out = []
    for msg in can.LogReader(str(path)):
        if msg.is_error_frame:
            out.append((msg.timestamp, "ERROR", {}))
            continue
        message = db.get_message_by_frame_id(msg.arbitration_id)
        out.append((msg.timestamp, message.name, message.decode(msg.data)))
    return out


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_standalone_schedule_writes_a_log_that_decodes_with_the_dbc(
    tmp_path: Path, suffix: str
) -> None:
    log = tmp_path / f"run{suffix}"
    result = invoke(*SCHEDULE, "--log", str(log), "--start-epoch", "1700000000", "--seed", "4")
    assert result.exit_code == 0, result.output
    assert "420 s of stand time" in result.output
    frames = decode_log(log)
    heading = [d for _, name, d in frames if name == "GYRO_HEADING"]
    assert len(heading) == 4201  # 0 .. 420 s at 10 Hz
    assert [d["STAND_TIME"] for d in heading[:3]] == [0, 100, 200]
    assert all(0 <= d["HEADING"] < 360 and d["VALID"] == 1 for d in heading)
    commands = [str(d["COMMAND"]) for _, name, d in frames if name == "STAND_COMMAND"]
    assert commands == ["set", "start", "stop"]
    acks = [d for _, name, d in frames if name == "STAND_ACK"]
    assert [(str(a["COMMAND"]), a["ACCEPTED"], a["STAND_TIME"]) for a in acks] == [
        ("set", 1, 60_000),
        ("start", 1, 60_000),
        ("stop", 1, 360_000),
    ]
    rocking = {d["STAND_TIME"]: d["ROCKING"] for _, name, d in frames if name == "STAND_STATUS"}
    assert (rocking[59_500], rocking[60_500], rocking[359_500], rocking[360_500]) == (0, 1, 1, 0)
    motion = [d for _, name, d in frames if name == "STAND_MOTION" and d["AMPLITUDE"] > 0]
    assert {(d["DIRECTION"], d["AMPLITUDE"], d["PERIOD"]) for d in motion} == {(31, 23.5, 6.2)}
    first, last = frames[0][0], frames[-1][0]
    if suffix == ".blf":  # ASC stores times relative to its start
        assert first == pytest.approx(1_700_000_000.0)
    assert last - first == pytest.approx(420.0, abs=1e-3)


def test_schedule_file_and_seeds(tmp_path: Path) -> None:
    schedule = tmp_path / "plan.toml"
    schedule.write_text(
        '[[step]]\naction = "still"\nduration_s = 30\n\n'
        '[[step]]\naction = "rock"\ndirection_deg = 45\namplitude_cm = 20\nperiod_s = 5\n'
        "duration_s = 30\n"
    )
    runs = {}
    for name, seed in (("a", "1"), ("b", "1"), ("c", "2")):
        log = tmp_path / f"{name}.blf"
        args = [
            "--schedule",
            str(schedule),
            "--log",
            str(log),
            "--seed",
            seed,
            "--drop-rate",
            "0.1",
        ]
        assert invoke(*args, "--start-epoch", "0").exit_code == 0
        runs[name] = [(t, n, d) for t, n, d in decode_log(log)]
    assert runs["a"] == runs["b"] and runs["a"] != runs["c"]
    assert sum(n == "GYRO_HEADING" for _, n, _ in runs["a"]) < 601  # some dropped


def test_refused_step_is_reported_as_a_warning(tmp_path: Path) -> None:
    result = invoke("--step", "rock 31 80 6 10", "--log", str(tmp_path / "x.blf"))
    assert result.exit_code == 0
    assert "stand refused 'set': amplitude out of stand limits" in result.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--step", "rok 1 2 3 4", "--log", "{tmp}/x.blf"], "bad step 'rok 1 2 3 4'"),
        (["--step", "still 10", "--log", "{tmp}/x.txt"], "needs --log FILE ending in .blf or .asc"),
        (["--step", "still 10"], "needs --log FILE"),
        (["--step", "still 10", "--log", "{tmp}/no/x.blf"], "does not exist"),
        (["--schedule", "{tmp}/absent.toml", "--log", "{tmp}/x.blf"], "cannot read schedule"),
        ([], "give --interface/--channel to join a bus"),
        (["--interface", "nonexistent", "--channel", "x"], "cannot open CAN bus"),
        (
            [
                "--step",
                "still 1",
                "--log",
                "{tmp}/x.blf",
                "--timing",
                "realtime",
                "--speedup",
                "-1",
            ],
            "speedup must be",
        ),
        (["--step", "still 1", "--log", "{tmp}/x.blf", "--speedup", "5"], "only with timing"),
        (["--step", "still 1", "--log", "{tmp}/x.blf", "--timing", "fast"], "timing must be"),
        (["--step", "still 1", "--log", "{tmp}/x.blf", "--drop-rate", "2"], "drop_rate must be"),
        (["--step", "still 1", "--log", "{tmp}/x.blf", "--protocol", "n2k"], "not one of"),
        (
            ["--step", "still 1", "--log", "{tmp}/x.blf", "--protocol", "nmea2000", "--address"]
            + ["252"],
            "--address: 252 is not a source address (0-251)",
        ),
        (
            ["--step", "still 1", "--log", "{tmp}/x.blf", "--protocol", "nmea2000"]
            + ["--not-available-rate", "1.5"],
            "--not-available-rate: 1.5 is not a probability in [0, 1]",
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, args: list[str], message: str) -> None:
    result = invoke(*[a.replace("{tmp}", str(tmp_path)) for a in args])
    assert result.exit_code == 2
    assert message in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "x.blf").exists()


def test_live_mode_on_a_virtual_bus(tmp_path: Path) -> None:
    channel = f"gyrostand-cli-{uuid.uuid4()}"
    received: list[can.Message] = []
    with can.Bus(interface="virtual", channel=channel) as bus:
        collect = threading.Thread(
            target=lambda: received.extend(iter(lambda: bus.recv(timeout=1.0), None))
        )
        collect.start()
        log = tmp_path / "live.asc"
        args = ["--interface", "virtual", "--channel", channel, "--duration-s", "0.4"]
        result = invoke(*args, "--timing", "realtime", "--speedup", "100", "--log", str(log))
        collect.join()
    assert result.exit_code == 0, result.output
    heading = [m for m in received if m.arbitration_id == 0x100]
    assert len(heading) > 50  # ~40 s of stand time at 10 Hz
    assert len(list(can.LogReader(str(log)))) == len(received)


def test_a_labs_dbc_on_the_bus(tmp_path: Path) -> None:
    """--dbc/--signals: the stand speaks the lab's messages (docs/examples/lab.dbc, its map), as
    a plan with them would; the frames decode with that codec and none is gyrostand's."""
    from gyrostand.simulated_stand import read_signals
    from gyrostand.stand.protocol import Codec, HeadingFrame

    examples = Path(__file__).resolve().parents[2] / "docs" / "examples"
    dbc, signals = examples / "lab.dbc", examples / "lab-signals.toml"
    log = tmp_path / "lab.asc"
    lab = ["--dbc", str(dbc), "--signals", str(signals)]
    result = invoke("--step", "still 10", "--log", str(log), "--start-epoch", "0", *lab)
    assert result.exit_code == 0, result.output
    codec = Codec.of(str(dbc), read_signals(signals))
    frames = list(can.LogReader(str(log)))
    headings = [f for f in map(codec.decode, frames) if isinstance(f, HeadingFrame)]
    assert len(headings) == 101  # 10 s at 10 Hz, stand times 0 to 10 s
    assert not any(m.arbitration_id == 0x100 for m in frames)  # gyrostand's heading message
    bad = invoke("--step", "still 1", "--log", str(log), "--signals", str(tmp_path / "no.toml"))
    assert bad.exit_code == 2 and "no.toml" in bad.output and "Traceback" not in bad.output


def test_standalone_nmea2000_compass(tmp_path: Path) -> None:
    """The compass speaks NMEA 2000 beside the stand's DBC frames: read back by the heading
    source, the headings equal those of the gyrostand frame within the PGN's resolution, at the
    same stand times (its frames' timestamps, Unix time, put on the stand clock)."""
    import numpy as np

    from gyrostand.devices.decoder import frame_decoder
    from gyrostand.frames.batch import BatchDecoder
    from gyrostand.frames.logfile import read_raw_frames
    from gyrostand.stand.protocol import Codec

    logs = {}
    for protocol, epoch in (("gyrostand", "0"), ("nmea2000", "1795000000.25")):
        logs[protocol] = tmp_path / f"{protocol}.blf"
        args = ["--step", "still 30", "--log", str(logs[protocol]), "--protocol", protocol]
        result = invoke(*args, "--address-change-at-s", "10", "--start-epoch", epoch)
        assert result.exit_code == 0, result.output
    (raw,) = read_raw_frames(logs["gyrostand"])
    plain = BatchDecoder(Codec()).decode(raw).headings
    (raw,) = read_raw_frames(logs["nmea2000"])
    decoder = frame_decoder(Codec(), "nmea2000", None, ("simulated compass", "SIM-1"))
    batch = decoder.decode(raw)
    n2k = batch.headings
    assert len(plain) == 301 and len(n2k) == 300  # the first: before the stand's first status
    assert np.array_equal(n2k.t_ms, plain.t_ms[1:])
    assert np.abs(n2k.heading_deg - plain.heading_deg[1:]).max() <= np.degrees(1e-4) / 2 + 1e-9
    events = [frame.message for _, frame in batch.others if hasattr(frame, "message")]
    assert any("claimed address 36 (was 35)" in e for e in events)
