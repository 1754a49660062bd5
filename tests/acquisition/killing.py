"""kill -9 at random moments of a simulated campaign in virtual time, each resume killed in turn,
then a last resume; compared with an uninterrupted run of the same plan (used by
tests/acquisition/test_kill_resume.py and validation/kill_resume.py).

The moments: a run's k-th engine write of its own committed (k drawn at random for each run,
counted from what the database held when the run began, so that a kill finds something new to
lose; k = 0: as soon as it runs, in its start-up or its re-run of what is stored), then a random
wait of up to 20 ms (into the next write or a commit). Counted in the run's own writes, a loaded
machine moves a moment in wall time, never in the campaign: a run killed after two writes of its
own has gone past what the earlier logs hold and logged frames. The runs are forked from this
process (imports done once) and killed with SIGKILL: no cleanup runs in them. The databases are
SQLite files in the folder unless `kill_and_resume` is given two (empty) database URLs, e.g. on
PostgreSQL."""

from __future__ import annotations

import os
import random
import signal
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from sqlalchemy import Connection, Engine, create_engine, inspect, text
from sqlalchemy.exc import DBAPIError

import gyrostand.acquisition.runner  # noqa: F401  (imported once, before the forks)
import gyrostand.cmd_campaign  # noqa: F401
from gyrostand.cli import app
from gyrostand.devices.framing import Received
from gyrostand.devices.serial_replay import serial_log_path
from gyrostand.devices.tagblock import read_tag_log
from gyrostand.frames.logfile import BatchBLFWriter, read_segments
from tests.acquisition.harness import FAST_SIM, plan_text

BOOKKEEPING = ("interrupted", "resume", "raw log")  # events of the runs, not of the campaign
# table: columns compared (no wall-clock column, no id that bookkeeping shifts). Ids are compared
# by rank (`snapshot`): PostgreSQL's sequences do not give back the ids of a killed transaction.
TABLES = {
    "campaign": "id, status, n_obs, engine_writes",
    "trial": 'id, "index", status, failure_reason, meas_direction_deg, meas_amplitude_cm, '
    "meas_period_s",
    "series": "id, trial_id, j, status, settle_started_ms, settle_done_ms, settle_estimate_deg, "
    "settle_outcome",
    "observation": "id, series_id, k, value_deg, window_start_ms, window_end_ms, frames_used, "
    "frames_lost, flags",
    "event": "trial_id, series_id, stand_time_ms, kind, severity, message",
}


def small_containers(path: Path) -> BatchBLFWriter:
    """Raw logs in 4 KiB blocks: a killed run's log then holds most of its frames (patch
    `gyrostand.acquisition.bus.raw_log_writer` with it; the forked runs inherit the patch)."""
    return BatchBLFWriter(path, max_container_size=4096)


def write_plan(folder: Path, database: str, seed: int = 0, compass: str = "", **plan: Any) -> Path:
    """The plan (`compass`: a [compass] table, default gyrostand's frame; `plan`: `plan_text`'s
    keywords)."""
    path = folder / "plan.toml"
    text = plan_text(database=database, raw_dir=str(folder / "raw"), seed=seed, **plan)
    path.write_text(text + FAST_SIM + compass)
    return path


def _reader(url: str) -> Engine:
    """An engine that only reads `url` (a SQLite file is opened read-only: never created)."""
    if url.startswith("sqlite:///"):
        url = f"sqlite:///file:{url.removeprefix('sqlite:///')}?mode=ro&uri=true"
    return create_engine(url)


def _query(url: str, sql: str) -> list[tuple]:
    """Rows of `sql` on the database at `url` ([] when it has no campaign table yet)."""
    engine = _reader(url)
    try:
        with engine.connect() as conn:
            if not inspect(conn).has_table("campaign"):
                return []
            return [tuple(row) for row in conn.execute(text(sql))]
    except DBAPIError:  # no SQLite file yet
        return []
    finally:
        engine.dispose()


def forked(args: list[str], kill_when: Callable[[], bool] = lambda: False) -> int | None:
    """Run the CLI in a forked child, SIGKILL it once `kill_when()` (polled) holds; its exit
    code, or None when it was killed."""
    pid = os.fork()
    if pid == 0:  # the child: no output, no cleanup, its own exit code
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        sys.stdout = sys.stderr = open(os.devnull, "w")  # noqa: SIM115
        code = 1
        try:
            app(args, prog_name="gyrostand")
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        finally:
            os._exit(code)
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        if kill_when():
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return None
        time.sleep(0.005)


class Writes:
    """The campaign's committed engine writes, read on one connection (-1: no campaign yet)."""

    def __init__(self, url: str) -> None:
        self.engine = _reader(url)
        self._conn: Connection | None = None

    def __call__(self) -> int:
        try:
            if self._conn is None:
                self._conn = self.engine.connect()
            row = self._conn.execute(text("SELECT engine_writes FROM campaign")).first()
            self._conn.rollback()  # the next poll sees the writes committed since
        except DBAPIError:
            self.close()
            return -1
        return -1 if row is None else row[0]

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        self.engine.dispose()


def snapshot(url: str) -> dict[str, list[tuple]]:
    """The compared rows of every table (empty before the campaign exists)."""
    rows = {
        name: _query(url, f"SELECT {columns} FROM {name} ORDER BY id")
        for name, columns in TABLES.items()
    }
    rank = {name: {row[0]: i for i, row in enumerate(rows[name], 1)} for name in TABLES}
    refers = {  # table: (column, table it refers to), the id first
        "campaign": [(0, "campaign")],
        "trial": [(0, "trial")],
        "series": [(0, "series"), (1, "trial")],
        "observation": [(0, "observation"), (1, "series")],
        "event": [(0, "trial"), (1, "series")],
    }
    for name, columns in refers.items():
        for i, row in enumerate(rows[name]):
            cells = list(row)
            for column, table in columns:
                cells[column] = rank[table].get(cells[column])
            rows[name][i] = tuple(cells)
    rows["event"] = [e for e in rows["event"] if e[3] not in BOOKKEEPING]
    return rows


def campaign_id(url: str) -> str:
    """The id of the one campaign (not always 1 on PostgreSQL: a run killed while storing the
    campaign used up id 1)."""
    return str(_query(url, "SELECT id FROM campaign")[0][0])


@dataclass(frozen=True)
class Segment:
    path: Path
    start: str
    first_frame: int
    frames: int | None
    ending: str | None


def segments(url: str) -> list[Segment]:
    rows = _query(
        url, "SELECT path, start, first_frame, frames, ending FROM raw_log_segment ORDER BY seq"
    )
    return [Segment(Path(path), *rest) for path, *rest in rows]


def frames(paths: list[Path]) -> tuple[np.ndarray, ...]:
    """Identifier, length and payload of every frame of the logs read in order (BLF timestamps
    count from each file's start; the stand time is in the frames' payload)."""
    parts = list(read_segments(paths))
    return tuple(
        np.concatenate([getattr(p, name) for p in parts])
        for name in ("arbitration_id", "is_error", "dlc", "data")
    )


@dataclass(frozen=True)
class KillRun:
    kills: int
    problems: tuple[str, ...]  # every way the killed-and-resumed campaign differs
    segments: tuple[Segment, ...]
    advanced: tuple[int, ...]  # the segments of runs killed after two writes of their own
    seconds: float


def kill_and_resume(
    folder: Path,
    kills: int,
    seed: int,
    urls: tuple[str, str] | None = None,
    compass: str = "",
    answers: tuple[str, ...] = (),
    plan: Mapping[str, Any] = MappingProxyType({}),
) -> KillRun:
    """An uninterrupted run and one killed `kills` times (then resumed to its end) of the same
    plan (simulator seed `seed`, [compass] table `compass`, the plan's prompts answered by
    `answers`, ID=VALUE; `plan`: `plan_text`'s keywords) under `folder`, into the databases
    `urls` (reference, killed; default: SQLite files in `folder`); what differs."""
    answered = [f"--answer={a}" for a in answers]
    t0 = time.monotonic()
    reference, killed = folder / "reference", folder / "killed"
    reference.mkdir()
    killed.mkdir()
    ref_db, db = urls or tuple(f"sqlite:///{d / 'db.sqlite'}" for d in (reference, killed))
    problems: list[str] = []
    reference_plan = write_plan(reference, ref_db, seed, compass, **plan)
    if forked(["campaign", "run", str(reference_plan), "--quiet", *answered]) != 0:
        return KillRun(0, ("the uninterrupted run failed",), (), (), time.monotonic() - t0)
    expected = snapshot(ref_db)
    rng = random.Random(seed)
    most = max(1, (expected["campaign"][0][3] - 1) // kills)  # the kills come before the end
    steps = [rng.randrange(0, most + 1) for _ in range(kills)]
    killed_plan = write_plan(killed, db, seed, compass, **plan)
    writes_now = Writes(db)
    before = snapshot(db)
    done = 0
    advanced: list[int] = []
    for step in steps:
        args = ["campaign", "resume", campaign_id(db), "--db", db] if before["campaign"] else []
        args = args or ["campaign", "run", str(killed_plan)]
        delay = rng.uniform(0.0, 0.02)
        moment = (before["campaign"][0][3] if before["campaign"] else 0) + step

        def due(moment: int = moment, delay: float = delay) -> bool:
            if writes_now() < moment:
                return False
            time.sleep(delay)
            return True

        code = forked([*args, "--quiet", *answered], due)
        writes_now.close()
        now = snapshot(db)
        if now["observation"][: len(before["observation"])] != before["observation"]:
            problems.append(f"kill {done + 1}: committed observations lost or changed")
        if now["observation"] != expected["observation"][: len(now["observation"])]:
            problems.append(f"kill {done + 1}: observations not the uninterrupted run's")
        before = now
        if code is not None:
            if code != 0:
                problems.append(f"{' '.join(args[:2])} ended with exit code {code}")
            break  # finished before the kill came
        if step >= 2:  # its segment is the last one: it committed writes
            advanced.append(len(segments(db)) - 1)
        done += 1
    if forked(["campaign", "resume", campaign_id(db), "--db", db, "--quiet", *answered]) != 0:
        problems.append("the last resume failed")
    final = snapshot(db)
    problems += [f"table {name} differs" for name in TABLES if final[name] != expected[name]]
    logs = segments(db)
    readable = [s.path for s in logs if s.frames]  # a run killed early may have logged nothing
    if [s.start for s in logs] != ["new"] + ["continued"] * (len(logs) - 1):
        problems.append(f"segment starts {[s.start for s in logs]}")
    if [s.ending for s in logs] != ["killed"] * (len(logs) - 1) + ["closed"]:
        problems.append(f"segment endings {[s.ending for s in logs]}")
    if [s.first_frame for s in logs] != list(np.cumsum([0] + [s.frames for s in logs[:-1]])):
        problems.append("segments do not continue one another")
    got, want = frames(readable), frames([s.path for s in segments(ref_db)])
    if any(a.shape != b.shape or not np.array_equal(a, b) for a, b in zip(got, want, strict=True)):
        problems.append("the segments read in order differ from the uninterrupted raw log")
    if serial_pieces(logs) != serial_pieces(segments(ref_db)):
        problems.append("the serial logs read in order differ from the uninterrupted one")
    return KillRun(done, tuple(problems), tuple(logs), tuple(advanced), time.monotonic() - t0)


def serial_pieces(logs: list[Segment]) -> list[Received]:
    """The pieces of the serial logs beside the CAN logs (a serial compass's), in order."""
    paths = [serial_log_path(s.path) for s in logs]
    return [p for path in paths if path.is_file() for p in read_tag_log(path)]
