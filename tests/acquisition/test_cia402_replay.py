"""Replay of a CiA 402 campaign: its raw log holds the drive's CANopen traffic (no stand DBC
frame), and a replay runs gyrostand's master again against the logged drive, so that it derives
the same record as the live run: observations, the measured motion from the drive's actual
position, and a trial failed by the drive's EMCY with the drive's error named. A stopped and
resumed campaign's two logs replay as its two runs, the second on the campaign clock the live
one went on with; the report reads the compass's frames of the logs on that clock."""

from __future__ import annotations

import sqlite3
import threading
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gyrostand.acquisition import cia402_run
from gyrostand.acquisition.cia402_sim import SimulatedCia402
from gyrostand.acquisition.operator import OperatorLink
from gyrostand.acquisition.runner import replay, run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.cli import app
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.devices.cia402_log import RECORD_BUS, RUN, DriveLogError
from gyrostand.devices.sim_drive import EMCY_OVERCURRENT, DriveFaults
from gyrostand.frames.logfile import BatchBLFWriter, read_raw_frames
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import Plan, parse_plan
from gyrostand.report.signal_record import heading_source, headings_in

from .harness import FAST_SIM, dump, files, plan_text
from .test_cia402_campaign import SERVO, STAND

NODE = 2  # the plan's drive
COMPASS = '\n[compass]\nprotocol = "nmea2000"\n'
TRIALS = [(45.0, 24.0, 6.0, "fit"), (135.0, 20.0, 5.0, "fit")]
FAULT_AT_S = 380.0  # drive time: trial 2 rocks (from about 345 s)
STOP_AT_S = 120.0  # stand time: trial 1 rocks (from about 100 s)
ANSWERS = {"k_trial1": "yes", "k_trial2": "yes"}
ANSWERS_1 = {"k_trial1": "yes"}  # trial 2's K prompt left to the operator
# what a run records of itself (prompts and answers, its raw log, how it ended) is not re-derived
RUN_ONLY = "('prompt', 'answer', 'raw log', 'resume', 'interrupted', 'command')"
RECORD = {
    "trial": 'SELECT "index", status, failure_reason, meas_direction_deg, meas_amplitude_cm, '
    "meas_period_s, meas_source FROM trial WHERE campaign_id = {c} ORDER BY id",
    "series": "SELECT j, s.status, settle_started_ms, settle_done_ms, settle_outcome FROM series s "
    "JOIN trial t ON t.id = s.trial_id WHERE campaign_id = {c} ORDER BY s.id",
    "observation": "SELECT k, value_deg, window_start_ms, window_end_ms, frames_used, frames_lost, "
    "flags FROM observation o JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = "
    "s.trial_id WHERE campaign_id = {c} ORDER BY o.id",
    "measured_motion": "SELECT m.source, amplitude_cm, amplitude_se_cm, period_s, period_se_s, "
    "n_samples FROM measured_motion m JOIN series s ON s.id = m.series_id JOIN trial t ON "
    "t.id = s.trial_id WHERE campaign_id = {c} ORDER BY m.id",
    "event": "SELECT stand_time_ms, kind, severity, message FROM event WHERE campaign_id = {c} "
    f"AND kind NOT IN {RUN_ONLY} ORDER BY id",
}


def record(db: Path, campaign: int) -> dict[str, list[tuple]]:
    with sqlite3.connect(db) as conn:
        return {k: conn.execute(q.format(c=campaign)).fetchall() for k, q in RECORD.items()}


def assert_the_logs_headings_make_the_observations(plan: Plan, logs: list[Path]) -> None:
    """The report's reading of the logs (`signal_record.headings_in`: the compass's frames on the
    campaign clock of the RUN and STEP records) finds in each observation window the frames the
    live engine used, with their mean."""
    with sqlite3.connect(plan.database) as conn:
        rows = conn.execute(
            "SELECT o.id, window_start_ms, window_end_ms, frames_used, value_deg FROM observation "
            "o JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id "
            "WHERE campaign_id = 1"
        ).fetchall()
    spans = {r[0]: (r[1], r[2]) for r in rows}
    found = headings_in(logs, codec_for(plan), spans, heading_source(plan))
    for obs, _, _, used, value in rows:
        t, h = found[obs]
        assert len(t) == used and h.mean() == pytest.approx(value, abs=1e-9)


def cia402_plan(tmp_path: Path) -> Plan:
    text = plan_text(
        TRIALS,
        n_obs=2,
        hold_s=30.0,
        database=str(tmp_path / "c.sqlite"),
        raw_dir=str(tmp_path / "raw"),
    )
    return parse_plan(text + FAST_SIM + STAND + COMPASS)


def logs(tmp_path: Path) -> list[Path]:
    """Campaign 1's raw logs."""
    with sqlite3.connect(tmp_path / "c.sqlite") as conn:
        rows = conn.execute("SELECT path FROM raw_log_segment WHERE campaign_id = 1 ORDER BY seq")
        return [Path(p) for (p,) in rows]


def test_replay_of_a_trial_failed_by_the_drives_emcy_equals_the_live_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    faults = DriveFaults(overcurrent_at_s=FAULT_AT_S)
    monkeypatch.setattr(
        cia402_run, "SimulatedCia402", partial(SimulatedCia402, servo=SERVO, drive_faults=faults)
    )
    plan = cia402_plan(tmp_path)
    sessions = open_database(sqlite_url(tmp_path / "c.sqlite"))
    live = run_live(plan, CampaignStore.create(sessions, plan), quiet=True, answers=ANSWERS)
    assert live.outcome == "completed"
    (log,) = logs(tmp_path)

    # the log: the drive's CANopen traffic, the compass's NMEA 2000, the master's records
    ids: set[int] = set()
    records = 0
    first = next(read_raw_frames(log))
    assert first.channel[0] == RECORD_BUS and first.data[0, 0] == RUN  # the run's clock: 0
    for raw in read_raw_frames(log):
        standard = ~raw.is_extended & (raw.channel != RECORD_BUS)
        ids.update(raw.arbitration_id[standard].tolist())
        records += int((raw.channel == RECORD_BUS).sum())
        emcy = raw.data[standard & (raw.arbitration_id == 0x80 + NODE)]
        if len(emcy):
            assert int.from_bytes(bytes(emcy[0, :2]), "little") == EMCY_OVERCURRENT
    # NMT, SYNC, EMCY, TPDO1, RPDO1, SDO, the drive's and gyrostand's heartbeats; nothing else
    assert ids == {0x000, 0x080, 0x082, 0x182, 0x202, 0x582, 0x602, 0x702, 0x77F}
    assert records > 70  # a RUN, then a STEP every 5 s of stand time (about 390 s)

    assert_the_logs_headings_make_the_observations(plan, [log])

    result = replay(plan, sessions, [log])
    assert result.outcome == live.outcome
    replayed, recorded = record(tmp_path / "c.sqlite", 2), record(tmp_path / "c.sqlite", 1)
    assert replayed == recorded
    trials = recorded["trial"]
    assert [t[1] for t in trials] == ["completed", "failed"]
    assert trials[1][2] == "CiA 402 drive: drive fault, error code 0x2310: EMCY 0x2310 (Current)"
    assert trials[0][6] == "drive position" and len(recorded["measured_motion"]) == 1
    assert len(recorded["observation"]) == 2 * 2 + 2  # trial 2: its still series

    # the log cut in two mid-roll (a killed run's log and its continuation): the same run
    frames = list(read_raw_frames(log, chunk=1000))
    cut = len(frames) // 2
    assert cut > 0
    for name, part in (("a.blf", frames[:cut]), ("b.blf", frames[cut:])):
        writer = BatchBLFWriter(tmp_path / name)
        for raw in part:
            writer.write_frames(raw)
        writer.stop()
    replay(plan, sessions, [tmp_path / "a.blf", tmp_path / "b.blf"])
    assert record(tmp_path / "c.sqlite", 3) == recorded


def stopped_and_resumed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Plan, list]:
    """Campaign 1, stopped at STOP_AT_S and resumed; its plan and its two raw logs."""
    monkeypatch.setattr(cia402_run, "SimulatedCia402", partial(SimulatedCia402, servo=SERVO))
    plan = cia402_plan(tmp_path)
    stop = threading.Event()
    advance = SimulatedCia402.advance_to

    def advance_then_stop(self: SimulatedCia402, t_s: float) -> list:
        if t_s >= STOP_AT_S:  # (the signal handler's `stop`, at a stand time)
            stop.set()
        return advance(self, t_s)

    sessions = open_database(sqlite_url(plan.database))
    with monkeypatch.context() as m:
        m.setattr(SimulatedCia402, "advance_to", advance_then_stop)
        store = CampaignStore.create(sessions, plan)
        first = run_live(plan, store, quiet=True, stop=stop, answers=ANSWERS)
    assert first.outcome == "stopped"
    resumed = CliRunner().invoke(
        app,
        ["campaign", "resume", "1", "--db", str(plan.database), "--quiet"]
        + [f"--answer={k}={v}" for k, v in ANSWERS.items()],
    )
    assert resumed.exit_code == 0, resumed.output
    segments = logs(tmp_path)
    assert len(segments) == 2
    return plan, segments


def test_a_stopped_and_resumed_campaign_replays_as_its_two_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plan, segments = stopped_and_resumed(tmp_path, monkeypatch)
    db = tmp_path / "c.sqlite"
    assert_the_logs_headings_make_the_observations(plan, segments)

    outcome = replay(plan, open_database(sqlite_url(db)), segments)
    assert outcome.outcome == "completed"
    replayed, recorded = record(db, 2), record(db, 1)
    assert replayed["observation"] == recorded["observation"]
    assert replayed == recorded
    # the second run's windows are on the campaign clock after the stop
    starts = [o[2] for o in recorded["observation"]]
    assert starts == sorted(starts) and starts[2] > STOP_AT_S * 1000


def test_a_set_point_changed_in_the_second_run_leaves_the_database_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The replay of the first run is written (its own transaction) when the second one's log
    turns out not to be what the master sends: one line, exit code 1, and the database as it
    was (no campaign marked failed, no events, segments or lease file of it)."""
    plan, (first, second) = stopped_and_resumed(tmp_path, monkeypatch)
    frames = list(read_raw_frames(second))
    rpdo = [
        (i, r)
        for i, raw in enumerate(frames)
        for r in np.flatnonzero(raw.arbitration_id == 0x200 + NODE)
    ]
    i, row = rpdo[len(rpdo) // 2]  # a set-point in the middle of the second run: another target
    frames[i].data[row, 2] ^= 0x01
    tampered = tmp_path / "tampered.blf"
    writer = BatchBLFWriter(tampered)
    for raw in frames:
        writer.write_frames(raw)
    writer.stop()
    path = tmp_path / "plan.toml"
    path.write_text(plan.text)
    before, listed = dump(plan.database), files(tmp_path)
    result = CliRunner().invoke(app, ["replay", str(first), str(tampered), "--plan", str(path)])
    assert dump(plan.database) == before and files(tmp_path) == listed
    assert result.exit_code == 1
    (error,) = [line for line in result.stderr.splitlines() if "error" in line]
    assert error.startswith(f"gyrostand: error: replay of {tampered} failed: at stand time ")
    assert "the master sends 0x202" in error and "Traceback" not in result.output


def test_a_log_of_another_drive_is_refused_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A log whose drive answered otherwise (here: one TPDO's position changed) is not what
    the master's commands give: the replay stops there, naming the frame."""
    monkeypatch.setattr(cia402_run, "SimulatedCia402", partial(SimulatedCia402, servo=SERVO))
    plan = cia402_plan(tmp_path)
    sessions = open_database(sqlite_url(tmp_path / "c.sqlite"))
    stop = threading.Event()
    advance = SimulatedCia402.advance_to

    def advance_then_stop(self: SimulatedCia402, t_s: float) -> list:
        if t_s >= 20.0:
            stop.set()
        return advance(self, t_s)

    monkeypatch.setattr(SimulatedCia402, "advance_to", advance_then_stop)
    run_live(plan, CampaignStore.create(sessions, plan), quiet=True, stop=stop, answers=ANSWERS)
    (log,) = logs(tmp_path)
    tampered = tmp_path / "tampered.blf"
    writer = BatchBLFWriter(tampered)
    done = False
    for raw in read_raw_frames(log):
        rpdo = raw.arbitration_id == 0x200 + NODE
        if not done and rpdo.any():  # the first set-point: another controlword
            raw.data[int(rpdo.argmax()), 0] ^= 0x01
            done = True
        writer.write_frames(raw)
    writer.stop()
    with pytest.raises(DriveLogError, match=r"the master sends 0x202 .* where the raw log holds"):
        replay(plan, sessions, [tampered])

    # without its RUN record (a later segment alone, a log of before): refused, nothing written
    headless = tmp_path / "headless.blf"
    writer = BatchBLFWriter(headless)
    for raw in read_raw_frames(log):
        writer.write_frames(raw.tail(1) if raw.start == 0 else raw)
    writer.stop()
    with sqlite3.connect(tmp_path / "c.sqlite") as conn:
        before = conn.execute("SELECT count(*) FROM campaign").fetchall()
    with pytest.raises(DriveLogError, match="no RUN record first"):
        replay(plan, sessions, [headless])
    with sqlite3.connect(tmp_path / "c.sqlite") as conn:
        assert conn.execute("SELECT count(*) FROM campaign").fetchall() == before


def test_a_campaign_stopped_at_a_k_prompt_replays_as_live_and_so_does_its_resume(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The operator declines to turn the compass for trial 2 (stops the campaign at its K
    prompt: a confirm prompt has no other answer than yes); later the campaign is resumed and
    the prompt answered. The first run's log replays to the stopped campaign, trial 2 not
    begun; both logs to the completed one."""
    monkeypatch.setattr(cia402_run, "SimulatedCia402", partial(SimulatedCia402, servo=SERVO))
    plan = cia402_plan(tmp_path)
    db = tmp_path / "c.sqlite"
    sessions = open_database(sqlite_url(db))
    stop = threading.Event()
    with monkeypatch.context() as m:  # the prompt said on the terminal: the operator stops
        m.setattr(OperatorLink, "_say", lambda self, line: self.stop.set())
        first = run_live(
            plan, CampaignStore.create(sessions, plan), quiet=True, stop=stop, answers=ANSWERS_1
        )
    assert first.outcome == "stopped"
    stopped = record(db, 1)
    assert [t[1] for t in stopped["trial"]] == ["completed", "pending"]
    (log,) = logs(tmp_path)
    assert replay(plan, sessions, [log]).outcome == "stopped"
    assert record(db, 2) == stopped

    resumed = CliRunner().invoke(
        app,
        ["campaign", "resume", "1", "--db", str(db), "--quiet"]
        + [f"--answer={k}={v}" for k, v in ANSWERS.items()],
    )
    assert resumed.exit_code == 0, resumed.output
    completed = record(db, 1)
    assert [t[1] for t in completed["trial"]] == ["completed", "completed"]
    assert replay(plan, sessions, logs(tmp_path)).outcome == "completed"
    assert record(db, 3) == completed
