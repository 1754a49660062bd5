"""The processes the station starts: `gyrostand campaign run|resume|retry` (the acquisition,
never inside the web server) and `gyrostand report`. A stop goes through the database
(`station.operator.request_stop`), whoever started the acquisition."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from gyrostand.db.url import DB_ENV

GYROSTAND = (sys.executable, "-m", "gyrostand")
ERROR = "gyrostand: error: "  # `gyrostand.errors.fail`'s prefix
START_WAIT_S = 60.0
"""How long a new campaign may take to appear in the database (imports, bus, raw log folder)."""


class ProcessRefused(RuntimeError):
    """A command the station started ended with an error before doing its work (its one line)."""


@dataclass
class Acquisition:
    """A `gyrostand campaign ...` or `gyrostand report` process of this server, and its
    stderr."""

    process: subprocess.Popen[bytes]
    stderr: IO[bytes]
    what: str

    @property
    def running(self) -> bool:
        return self.process.poll() is None

    def lines(self) -> list[str]:
        """What the process wrote on stderr so far, by line."""
        self.stderr.seek(0)
        return self.stderr.read().decode(errors="replace").strip().splitlines()

    def error(self) -> str | None:
        """The process's last error line ("gyrostand: error: " left out), once it has ended with
        a non-zero exit code; None when it wrote none (a stopped or paused run: its outcome is
        in the database)."""
        code = self.process.poll()
        if code is None or code == 0:
            return None
        errors = [line for line in self.lines() if line.startswith(ERROR)]
        return errors[-1].removeprefix(ERROR) if errors else None


@dataclass
class Processes:
    """The acquisitions this server started, by campaign id (at most one live per campaign:
    the campaign's lease refuses a second one anyway)."""

    db: str
    command: Sequence[str] = GYROSTAND
    acquisitions: dict[int, Acquisition] = field(default_factory=dict)
    reports: dict[int, Report] = field(default_factory=dict)

    @property
    def environment(self) -> dict[str, str]:
        """The commands' environment: the database in GYROSTAND_DB, not in their arguments
        (a password in the URL would show in `ps`, which lists every process's arguments)."""
        return {**os.environ, DB_ENV: self.db}

    def _spawn(self, args: Sequence[str], what: str, quiet: bool = True) -> Acquisition:
        stderr = tempfile.TemporaryFile()  # noqa: SIM115 (kept with the process, read at its end)
        process = subprocess.Popen(
            [*self.command, *args, *(["--quiet"] if quiet else [])],
            env=self.environment,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=stderr,
            start_new_session=True,  # a Ctrl-C on the server is not a stop of the campaign
        )
        return Acquisition(process, stderr, what)

    def running(self, campaign_id: int) -> bool:
        acquisition = self.acquisitions.get(campaign_id)
        return acquisition is not None and acquisition.running

    def error(self, campaign_id: int) -> str | None:
        acquisition = self.acquisitions.get(campaign_id)
        return None if acquisition is None else acquisition.error()

    async def start(
        self, plan: Path, newest_campaign: Callable[[], int | None], answers: Mapping[str, str]
    ) -> int:
        """Run a new campaign of `plan` with the `answers` to its prompts; its id once it is in
        the database (ProcessRefused with the command's error line when it ends first).
        `newest_campaign()`: the id of the newest campaign stored with this plan text (None:
        none)."""
        before = newest_campaign()
        given = [a for key, value in answers.items() for a in ("--answer", f"{key}={value}")]
        acquisition = self._spawn(["campaign", "run", str(plan), *given], "campaign run")
        deadline = time.monotonic() + START_WAIT_S
        while time.monotonic() < deadline:
            campaign_id = newest_campaign()
            if campaign_id is not None and campaign_id != before:
                self.acquisitions[campaign_id] = acquisition
                return campaign_id
            if not acquisition.running:
                raise ProcessRefused(acquisition.error() or "campaign run stored no campaign")
            await asyncio.sleep(0.05)
        acquisition.process.terminate()
        raise ProcessRefused(f"no campaign stored after {START_WAIT_S:.0f} s: stopped the run")

    def resume(self, campaign_id: int, retry: Sequence[int] = ()) -> None:
        """`campaign resume ID`, or `campaign retry ID --trial I ...` when `retry` names trials."""
        if self.running(campaign_id):
            raise ProcessRefused(f"campaign {campaign_id} is being acquired by this station")
        if retry:
            trials = [a for index in retry for a in ("--trial", str(index))]
            args = ["campaign", "retry", str(campaign_id), *trials]
        else:
            args = ["campaign", "resume", str(campaign_id)]
        self.acquisitions[campaign_id] = self._spawn(args, args[1])

    def report(self, campaign_id: int, out: Path, formats: str) -> None:
        """Start `gyrostand report ID --out OUT --format FORMATS` (its progress: `reports`)."""
        if self.report_running(campaign_id):
            raise ProcessRefused(f"a report of campaign {campaign_id} is being written")
        args = ["report", str(campaign_id), "--out", str(out), "--format", formats]
        self.reports[campaign_id] = Report(self._spawn(args, "report", quiet=False), formats)

    def report_running(self, campaign_id: int) -> bool:
        job = self.reports.get(campaign_id)
        return job is not None and job.process.running


@dataclass(frozen=True)
class Report:
    """A report being written (or written) by this server, with the formats asked for."""

    process: Acquisition
    formats: str

    def progress(self) -> dict[str, object]:
        """For the page: running, the formats, its latest stage line, its error line."""
        lines = [line.removeprefix("report: ") for line in self.process.lines()]
        return {
            "running": self.process.running,
            "formats": self.formats,
            "stage": lines[-1] if lines else "starting",
            "error": self.process.error(),
        }
