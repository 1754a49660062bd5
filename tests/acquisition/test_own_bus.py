"""A compass on a CAN bus of its own (`[compass] interface`, `channel`): on the simulated stand
the simulated NMEA 2000 compass sits on a second in-process virtual bus. The campaign reads both
buses into one stream (virtual time: in an order that depends on the simulation alone), the raw
log records each frame's bus (BLF channel 1: the stand's, 2: the compass's), the replay of the
log gives the live observations, and a compass bus without headings fails the trial naming it."""

from __future__ import annotations

import hashlib
import math
import sqlite3
from pathlib import Path

import can
import numpy as np
import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.devices.nmea2000 import split_id
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import parse_plan
from gyrostand.report.signal_record import heading_source, headings_in
from tests.acquisition.harness import FAST_SIM, plan_text

runner = CliRunner()
TRIALS = [(45.0, 24.0, 6.0, "fit"), (135.0, 20.0, 5.0, "fit"), (315.0, 16.0, 8.0, "fit")]
OWN_BUS = '\n[compass]\nprotocol = "nmea2000"\ninterface = "virtual"\nchannel = "compass"\n'
OBSERVATIONS = """SELECT t."index", s.j, o.k, o.value_deg, o.window_start_ms, o.window_end_ms,
    o.frames_used, o.frames_lost, o.flags
    FROM observation o JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id
    WHERE t.campaign_id = ? ORDER BY t."index", s.j, o.k"""


def write_plan(folder: Path, compass: str = OWN_BUS, extra: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    plan = folder / "plan.toml"
    text = plan_text(
        trials=TRIALS,
        n_obs=2,
        hold_s=20.0,
        database=str(folder / "db.sqlite"),
        raw_dir=str(folder / "raw"),
    )
    plan.write_text(text + FAST_SIM + extra + compass)
    return plan


def run(plan: Path) -> Path:
    """Run the plan's campaign; its raw log."""
    result = runner.invoke(app, ["campaign", "run", str(plan), "--quiet"])
    assert result.exit_code == 0, result.output
    (blf,) = (plan.parent / "raw").glob("*.blf")
    return blf


def query(db: Path, sql: str, *args: object) -> list[tuple]:
    with sqlite3.connect(db) as conn:
        return conn.execute(sql, args).fetchall()


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    plan = write_plan(tmp_path_factory.mktemp("own-bus"))
    run(plan)
    return plan


def test_the_campaign_completes_with_the_compass_on_its_own_bus(campaign: Path) -> None:
    db = campaign.with_name("db.sqlite")
    assert query(db, "SELECT status, heading_source FROM campaign") == [("completed", "nmea2000")]
    assert query(db, "SELECT count(*), sum(frames_lost) FROM observation") == [(3 * 2 * 2, 0)]


def test_the_raw_log_records_each_frames_bus(campaign: Path) -> None:
    """Read with python-can's own BLF reader: the compass's NMEA 2000 frames (29-bit) on the
    second channel and nothing else there; the stand's frames (11-bit) on the first."""
    (blf,) = (campaign.parent / "raw").glob("*.blf")
    with can.BLFReader(blf) as reader:
        frames = [(m.channel, m.is_extended_id, m.arbitration_id) for m in reader]
    on = {0: [f for f in frames if f[0] == 0], 1: [f for f in frames if f[0] == 1]}
    assert len(on[0]) + len(on[1]) == len(frames)
    assert on[1] and all(extended for _, extended, _ in on[1])
    assert on[0] and not any(extended for _, extended, _ in on[0])
    pgns = set(split_id(np.array([i for _, _, i in on[1]]))[0].tolist())
    assert {127250, 60928, 126996, 59904} <= pgns  # headings, claim, product, our request


def test_replay_gives_the_live_observations(campaign: Path, tmp_path: Path) -> None:
    (blf,) = (campaign.parent / "raw").glob("*.blf")
    db = tmp_path / "replay.sqlite"
    result = runner.invoke(app, ["replay", str(blf), "--plan", str(campaign), "--db", str(db)])
    assert result.exit_code == 0, result.output
    live = campaign.with_name("db.sqlite")
    assert query(db, OBSERVATIONS, 1) == query(live, OBSERVATIONS, 1)


def test_the_run_is_byte_reproducible(campaign: Path, tmp_path: Path) -> None:
    """Two notifier threads, one stream: the same raw log however the threads ran."""
    (blf,) = (campaign.parent / "raw").glob("*.blf")
    again = run(write_plan(tmp_path / "again"))
    digest = [hashlib.sha256(p.read_bytes()).hexdigest() for p in (blf, again)]
    assert digest[0] == digest[1]


def test_a_compass_bus_without_headings_fails_the_trial_naming_it(tmp_path: Path) -> None:
    """Every heading the simulated compass samples is dropped: its bus carries only its
    answers to the campaign's requests (address claim, product information)."""
    plan = write_plan(tmp_path, extra="[bus.simulator.faults]\ndrop_rate = 1.0\n")
    result = runner.invoke(app, ["campaign", "run", str(plan), "--quiet"])
    assert result.exit_code == 1, result.output
    failed = "SELECT failure_reason FROM trial WHERE status = 'failed'"
    reasons = [r for (r,) in query(tmp_path / "db.sqlite", failed)]
    why = "the compass's bus (virtual compass) silent: no heading frame for 6 s of stand time"
    assert reasons == [why] * len(TRIALS)


def test_plan_check_names_the_compass_bus(tmp_path: Path) -> None:
    result = runner.invoke(app, ["plan", "check", str(write_plan(tmp_path))])
    assert result.exit_code == 0, result.output
    assert "compass on nmea2000 on its own bus (virtual compass)" in result.stdout


def test_the_report_reads_the_headings_from_the_compass_bus(campaign: Path) -> None:
    """The report's heading traces (`report.signal_record.headings_in`) take the compass's
    headings from the second BLF channel: every PGN 127250 there inside trial 1's still series,
    at its reception time (virtual time: its sample's stand time), 1e-4 rad each."""
    plan = parse_plan(campaign.read_text())
    (blf,) = (campaign.parent / "raw").glob("*.blf")
    windows = [
        o for o in query(campaign.with_name("db.sqlite"), OBSERVATIONS, 1) if o[:2] == (1, 1)
    ]
    span = (min(o[4] for o in windows), max(o[5] for o in windows))
    t, h = headings_in([blf], codec_for(plan), {1: span}, heading_source(plan))[1]
    with can.BLFReader(blf) as reader:
        frames = [
            (round(m.timestamp * 1000), bytes(m.data))
            for m in reader
            if m.channel == 1 and int(split_id(np.array([m.arbitration_id]))[0][0]) == 127250
        ]
    inside = [(ms, data) for ms, data in frames if span[0] <= ms < span[1]]
    heading_deg = [math.degrees(int.from_bytes(d[1:3], "little") * 1e-4) for _, d in inside]
    assert len(inside) == (span[1] - span[0]) // 500  # one every 0.5 s (2 Hz)
    assert t.tolist() == [ms for ms, _ in inside]
    assert h.tolist() == pytest.approx(heading_deg, abs=1e-9)
