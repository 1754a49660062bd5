"""`campaign run` with `[compass] protocol = "iec61162"`, as a user runs it: on the simulated
stand the compass's sentences go through a pseudo-terminal pair and pyserial, timed by the
simulation (virtual time); the serial raw log beside the CAN log, recorded with its hash; a
replay of both logs gives the live run's observations; a port that does not open is one line
before anything is written."""

from __future__ import annotations

import hashlib
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.devices.tagblock import read_tag_log
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import parse_plan
from gyrostand.report.signal_record import heading_source, headings_in
from tests.acquisition.harness import FAST_SIM, plan_text

runner = CliRunner()
TRIALS = [(45.0, 24.0, 6.0, "fit"), (135.0, 20.0, 5.0, "fit"), (315.0, 16.0, 8.0, "fit")]
HOLD_S = 20.0  # settled when within the band for 20 s (a short campaign)
SERIAL = '\n[compass]\nprotocol = "iec61162"\n'
OBSERVATIONS = """SELECT t."index", s.j, o.k, o.value_deg, o.window_start_ms, o.window_end_ms,
    o.frames_used, o.frames_lost, o.flags
    FROM observation o JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id
    WHERE t.campaign_id = ? ORDER BY t."index", s.j, o.k"""


def write_plan(folder: Path, extra: str = SERIAL, **kwargs: object) -> Path:
    plan = folder / "plan.toml"
    text = plan_text(
        trials=TRIALS,
        n_obs=2,
        hold_s=HOLD_S,
        database=str(folder / "db.sqlite"),
        raw_dir=str(folder / "raw"),
    )
    plan.write_text(text + FAST_SIM + extra)
    return plan


def run(plan: Path) -> None:
    result = runner.invoke(app, ["campaign", "run", str(plan), "--quiet"])
    assert result.exit_code == 0, result.output


def observations(db: Path, campaign: int = 1) -> list[tuple]:
    with sqlite3.connect(db) as conn:
        return conn.execute(OBSERVATIONS, (campaign,)).fetchall()


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    plan = write_plan(tmp_path_factory.mktemp("serial"))
    run(plan)
    return plan


def test_the_campaign_completes_on_the_serial_source(campaign: Path) -> None:
    db = campaign.with_name("db.sqlite")
    with sqlite3.connect(db) as conn:
        row = conn.execute(
            "SELECT status, heading_source, heading_resolution_deg, heading_time_base FROM campaign"
        ).fetchone()
    assert row[:3] == ("completed", "iec61162", 0.01)  # THS: two decimals
    assert "virtual time" in row[3]
    got = observations(db)
    assert len(got) == 3 * 2 * 2  # 3 trials, j = 1, 2, N = 2
    assert all(o[7] == 0 and "stuck" not in o[8] for o in got)  # nothing lost, not stuck
    # the 2 Hz compass's THS samples in each window, one for every 0.5 s of it
    assert all(o[6] == (o[5] - o[4]) // 500 for o in got)


def test_the_serial_log_is_recorded_with_its_hash(campaign: Path) -> None:
    (log,) = (campaign.parent / "raw").glob("*.nmea")
    pieces = list(read_tag_log(log))
    assert pieces[0].data.startswith(b"$HETHS,") and pieces[1].data.startswith(b"$HEROT,")
    with sqlite3.connect(campaign.with_name("db.sqlite")) as conn:
        (message,) = conn.execute(
            "SELECT message FROM event WHERE kind = 'raw log' AND message LIKE 'serial%'"
        ).fetchone()
        segment = conn.execute("SELECT serial_lines, serial_sha256 FROM raw_log_segment").fetchall()
    sha = hashlib.sha256(log.read_bytes()).hexdigest()
    assert message == f"serial sentences in {log} ({len(pieces)} lines, sha256 {sha})"
    assert segment == [(len(pieces), sha)]


def test_replay_of_both_logs_gives_the_live_observations(campaign: Path, tmp_path: Path) -> None:
    (blf,) = (campaign.parent / "raw").glob("*.blf")
    db = tmp_path / "replay.sqlite"
    args = ["replay", str(blf), "--plan", str(campaign), "--db", str(db)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert observations(db) == observations(campaign.with_name("db.sqlite"))
    with sqlite3.connect(db) as conn, sqlite3.connect(campaign.with_name("db.sqlite")) as live:
        query = "SELECT frames, sha256, serial_lines, serial_sha256 FROM raw_log_segment"
        assert conn.execute(query).fetchall() == live.execute(query).fetchall()


def test_replay_without_the_serial_log_is_one_line(campaign: Path, tmp_path: Path) -> None:
    (blf,) = (campaign.parent / "raw").glob("*.blf")
    alone = tmp_path / blf.name
    alone.write_bytes(blf.read_bytes())
    db = tmp_path / "replay.sqlite"
    result = runner.invoke(app, ["replay", str(alone), "--plan", str(campaign), "--db", str(db)])
    assert result.exit_code != 0
    assert "no serial log beside" in result.output and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_a_port_that_does_not_open_is_one_line_before_anything_is_written(
    tmp_path: Path,
) -> None:
    port = tmp_path / "ttyUSB9"
    text = plan_text(trials=TRIALS, database=str(tmp_path / "db.sqlite"), raw_dir=str(tmp_path))
    real_bus = 'simulated = false\ninterface = "virtual"\nchannel = "gyro-serial-test"'
    plan = tmp_path / "plan.toml"
    plan.write_text(
        text.replace("simulated = true\nseed = 1", real_bus) + SERIAL + f'port = "{port}"\n'
    )
    result = runner.invoke(app, ["campaign", "run", str(plan), "--quiet"])
    assert result.exit_code == 1, result.output
    assert result.output.strip() == (
        f"gyrostand: error: serial port {port}: cannot open it (No such file or directory)"
    )
    assert not (tmp_path / "db.sqlite").exists()


def test_the_report_reads_the_headings_from_the_serial_log(campaign: Path) -> None:
    """The report's heading traces and reading record (`report.signal_record.headings_in`) take
    the headings from the serial log: every THS sentence in trial 1's still series, at its
    reception time (virtual time: the stand time of its sample)."""
    plan = parse_plan(campaign.read_text())
    (blf,) = (campaign.parent / "raw").glob("*.blf")
    windows = [o for o in observations(campaign.with_name("db.sqlite")) if o[:2] == (1, 1)]
    span = (min(o[4] for o in windows), max(o[5] for o in windows))
    t, h = headings_in([blf], codec_for(plan), {1: span}, heading_source(plan))[1]
    ths = [
        (round(p.time_s * 1000), float(p.data.split(b",")[1]))
        for p in read_tag_log(blf.with_suffix(".nmea"))
        if p.data.startswith(b"$HETHS") and span[0] <= p.time_s * 1000 < span[1]
    ]
    assert len(ths) == (span[1] - span[0]) // 500  # one every 0.5 s (2 Hz)
    assert list(zip(t.tolist(), h.tolist(), strict=True)) == ths
