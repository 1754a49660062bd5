"""CLI: campaign run/resume/retry/status/list, replay."""

from __future__ import annotations

import functools
import sys
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from gyrostand import cmd_campaign_remove
from gyrostand.cmd_data import DEFAULT_DB, CampaignId, JsonOption, TagOption, open_db, parse_tags
from gyrostand.db.url import DB_ENV, shown_url
from gyrostand.errors import EXIT_FAILED, fail, printable
from gyrostand.stages import Stages
from gyrostand.stand.simconfig import TIMINGS

if TYPE_CHECKING:
    from rich.console import Console

    from gyrostand.acquisition.runner import RunResult
    from gyrostand.acquisition.store import CampaignStore
    from gyrostand.db.queries import CampaignRow
    from gyrostand.plan.model import Plan


@functools.cache
def _out() -> Console:
    """stdout as text, never markup (rich: imported when something is printed)."""
    from rich.console import Console

    return Console(highlight=False, soft_wrap=True, markup=False, emoji=False)


RECENT_EVENTS = 5  # campaign status: the latest warnings and errors shown


def _load(plan_path: Path) -> Plan:
    from gyrostand.plan.model import PlanError, load_plan

    try:
        return load_plan(plan_path)
    except PlanError as exc:
        fail(f"{plan_path}: invalid plan: " + "; ".join(exc.problems))


def checked_plan(
    plan: Plan,
    *,
    interface: str | None,
    channel: str | None,
    db: str | None,
    speedup: float | None,
    seed: int | None,
    timing: str | None = None,
) -> Plan:
    """The plan with the command line's bus and database options, validated as the plan file
    and prepared as the run will use it (one-line errors). The bus options are written into the
    plan's text, which a new campaign stores."""
    from gyrostand.plan.codec import prepare
    from gyrostand.plan.model import PlanError, revised
    from gyrostand.plan.overrides import with_keys

    bus: dict[str, object] = {}
    if timing is not None and timing not in TIMINGS:
        fail(f"--timing must be one of {', '.join(TIMINGS)}, not {timing!r}")
    if timing == "virtual" and speedup is not None:
        fail("--speedup paces the simulated stand in real time: it excludes --timing virtual")
    if interface is not None or channel is not None:
        if speedup is not None or seed is not None:
            fail("--speedup and --seed apply to the simulated stand, not to --interface/--channel")
        bus = {
            "simulated": False,
            "interface": interface,
            "channel": channel,
            "speedup": 1.0,
            "timing": timing or "realtime",
        }
    else:
        if timing is not None:
            bus["timing"] = timing
        if (speedup is not None or seed is not None) and not plan.bus.simulated:
            fail("--speedup and --seed apply only when the plan's bus is simulated")
        if speedup is not None:
            if not speedup > 0:
                fail("--speedup must be > 0")
            bus.update(timing="realtime", speedup=speedup)
        if seed is not None:
            bus["seed"] = seed
    try:
        # the text a new campaign stores gets the bus options: a resume, a re-run and the
        # report see what ran
        text = with_keys(plan.text, {"bus": bus}) if bus else plan.text
        plan = revised(plan, text, bus=bus, campaign={"database": db or plan.database})
        prepare(plan)
    except PlanError as exc:
        fail("invalid plan: " + "; ".join(exc.problems))
    except ValueError as exc:  # a layout with_keys cannot edit (it never guesses)
        fail(f"cannot set the bus options in the plan's text ({exc}): set them in the file")
    return plan


def interactive() -> bool:
    """Whether the operator can answer prompts here (standard input is a terminal)."""
    return sys.stdin is not None and sys.stdin.isatty()


def checked_answers(plan: Plan, given: Sequence[str], new: bool = True) -> dict[str, str]:
    """`--answer ID=VALUE` checked against the plan's prompts; for a `new` campaign, a prompt
    before the campaign left out is asked on the terminal, or is one error line when there is
    none (a resumed campaign's were answered when it started)."""
    from gyrostand.plan.switching import all_prompts

    prompts = {p.id: p for p in all_prompts(plan)}
    answers: dict[str, str] = {}
    for item in given:
        key, sep, value = item.partition("=")
        if not sep:
            fail(f"--answer {item!r}: give ID=VALUE")
        if key not in prompts:
            known = ", ".join(prompts) or "none"
            fail(f"--answer {key}: the plan has no such prompt (its prompts: {known})")
        try:
            answers[key] = prompts[key].answer(value)
        except ValueError as exc:
            fail(f"--answer {exc}")
    for prompt in plan.prompts_before("campaign") if new else ():
        while prompt.id not in answers:
            if not interactive():
                fail(
                    f"the plan asks before the campaign: {prompt.text} "
                    f"(give --answer {prompt.id}=...)"
                )
            try:
                answers[prompt.id] = prompt.answer(typer.prompt(prompt.text, err=True))
            except ValueError as exc:
                typer.echo(str(exc), err=True)
    return answers


def preflight(plan: Plan) -> None:
    """Before anything is written (a campaign row, an event): the raw log folder takes a file,
    a real bus opens (and the compass's own bus, if it has one), and an NMEA 2000 compass on its
    bus is the plan's instrument (one-line errors, exit code 1: the environment refuses)."""
    import can

    from gyrostand.acquisition.bus import check_raw_log_dir, open_bus
    from gyrostand.devices.n2k_identify import IdentificationError, identify

    real = [] if plan.bus.simulated else [plan.bus, plan.compass][: 1 + plan.compass.own_bus]
    for bus in real:  # (the compass is on the last)
        what = "the compass's CAN bus" if bus is plan.compass else "the CAN bus"
        try:
            opened = open_bus(bus)
        except (can.CanError, OSError, ValueError) as exc:
            fail(
                f"cannot open {what} (interface {bus.interface!r}, channel {bus.channel!r}): {exc}",
                code=EXIT_FAILED,
            )
        try:
            if plan.compass.protocol == "nmea2000" and bus is real[-1]:
                _, name, instrument, _ = plan.heading_source
                identify(opened, None if name is None else int(name, 16), instrument)
        except IdentificationError as exc:
            fail(str(exc), code=EXIT_FAILED)
        except (can.CanError, OSError) as exc:
            fail(f"cannot send on the CAN bus (channel {bus.channel!r}): {exc}", code=EXIT_FAILED)
        finally:
            opened.shutdown()
    from gyrostand.acquisition.serial_input import check_serial
    from gyrostand.devices.serial_config import SerialSimError
    from gyrostand.devices.serial_port import SerialPortError

    try:
        check_serial(plan)
    except SerialPortError as exc:
        fail(str(exc), code=EXIT_FAILED)
    except SerialSimError as exc:
        fail(f"[compass] the simulated serial compass: {exc}")
    try:
        check_raw_log_dir(plan)
    except OSError as exc:
        fail(
            f"cannot write raw CAN logs in {plan.raw_log_dir}: {exc.strerror or exc}",
            code=EXIT_FAILED,
        )


@contextmanager
def signals_deferred() -> Iterator[threading.Event]:
    """Ctrl-C (SIGINT) and SIGTERM from here on set the event instead of raising in the middle
    of opening the database or the bus: the command checks it before it writes the campaign,
    and the acquisition loop stops on it (the stand told to stop, the campaign "stopped" with
    an event). The runner's own handlers while it acquires set the same event."""
    from gyrostand.acquisition.runner import _stop_on_signals

    stop = threading.Event()
    with _stop_on_signals(stop):
        yield stop


def not_interrupted(stop: threading.Event, before: str) -> None:
    """Leave before `before` when a signal came: nothing is written yet."""
    if stop.is_set():
        fail(f"interrupted before {before}: nothing written", code=EXIT_FAILED)


def print_outcome(result: RunResult, db: str, *, resumable: bool = True) -> None:
    """The outcome on stdout; exit code 1 unless the campaign completed (failed: it cannot be
    analysed; with how to continue it and to retry its failed trials when it can be continued)."""
    shown = printable(shown_url(db))
    _out().print(
        f"campaign {result.campaign_id} {result.outcome}: {result.trials_completed} trials "
        f"completed, {result.trials_failed} failed, {result.observations} observations in "
        f"{shown}"
    )
    if result.raw_log is not None:
        _out().print(f"raw frames: {printable(result.raw_log)} (sha256 {result.raw_log_sha256})")
        from gyrostand.devices.serial_replay import serial_log_path

        if (sentences := serial_log_path(result.raw_log)).is_file():  # a serial compass's
            _out().print(f"serial sentences: {printable(sentences)}")
    if result.trials_failed and resumable:
        _out().print(
            f"retry the failed trials with: gyrostand campaign resume {result.campaign_id} "
            f"--retry-failed --db {shown}"
        )
    if result.outcome == "failed":  # every trial attempted, too few completed to analyse
        fail(
            f"campaign {result.campaign_id} failed: it cannot be analysed "
            f"({result.trials_completed} trials completed, {result.trials_failed} failed)",
            code=EXIT_FAILED,
        )
    if result.outcome != "completed":
        if resumable:
            _out().print(
                f"continue with: gyrostand campaign resume {result.campaign_id} --db {shown}"
            )
        raise typer.Exit(EXIT_FAILED)


def run_campaign(
    plan: Plan,
    store: CampaignStore,
    quiet: bool,
    stop: threading.Event,
    db: str,
    start: str = "new",
    answers: Mapping[str, str] | None = None,
) -> RunResult:
    """Acquire into a stored campaign (`start`: see `run_live`); one outcome whatever happens:
    the result (completed, paused, stopped), or one line naming the failure with the campaign
    marked and an event, as far as the database still takes writes."""
    import can
    from sqlalchemy.exc import OperationalError

    from gyrostand.acquisition.runner import RawLogFailed, result, run_live
    from gyrostand.acquisition.store import ReRunMismatch
    from gyrostand.campaign_procedures import run_procedures_of
    from gyrostand.db.session import unusable
    from gyrostand.devices.serial_port import SerialPortError

    def mark(kind: str, severity: str, message: str, status: str) -> None:
        """An event saying why, and the campaign's status (as far as the database lets us)."""
        try:
            store.run_event(kind, severity, message)
            store.set_status(status)
        except OperationalError:  # still refused: the campaign stays "running" (interrupted)
            pass

    try:
        if stop.is_set():  # a signal while the campaign was being stored: nothing acquired
            mark("interrupted", "warning", "stopped by signal before acquiring", "stopped")
            return result(store, "stopped", None, None)
        terminal = sys.stdin if interactive() else None
        if not run_procedures_of(plan, store, quiet, stop, answers, terminal):
            why = "stopped during the standard's procedures (the stages done are kept)"
            mark("interrupted", "warning", why, "stopped")
            return result(store, "stopped", None, None)
        # (the analysis is recorded by the first `analyze` or `report`, not here: computing it
        # at the end of every run cost ~45 s of the SocketCAN suite's emulated campaign)
        return run_live(
            plan, store, start=start, quiet=quiet, stop=stop, answers=answers, terminal=terminal
        )
    except ReRunMismatch as exc:
        mark("resume", "error", str(exc), "stopped")
        fail(f"campaign {store.campaign_id}: {exc}", code=EXIT_FAILED)
    except RawLogFailed as exc:
        fail(
            f"campaign {store.campaign_id} stopped: {exc}; what was committed is kept: resume "
            f"it (gyrostand campaign resume {store.campaign_id} --db {db}) once the disk has room",
            code=EXIT_FAILED,
        )
    except KeyboardInterrupt:  # python's own handler (ours cannot be set outside the main thread)
        mark("interrupted", "warning", "interrupted before acquiring (Ctrl-C)", "stopped")
        return result(store, "stopped", None, None)
    except SerialPortError as exc:
        mark("serial port", "error", str(exc), "paused")
        fail(f"campaign {store.campaign_id}: {exc}", code=EXIT_FAILED)
    except (can.CanError, OSError, ValueError) as exc:
        mark("bus error", "error", f"could not use the bus: {exc}", "paused")
        fail(f"campaign {store.campaign_id} could not use the bus: {exc}", code=EXIT_FAILED)
    except OperationalError as exc:
        problem = unusable(exc, shown_url(db))
        mark("database", "error", f"the database refused a write: {exc.orig}", "stopped")
        fail(
            f"campaign {store.campaign_id} stopped: {problem}; what was committed is kept: "
            f"resume it (gyrostand campaign resume {store.campaign_id} --db {shown_url(db)}) "
            "once the database takes writes",
            code=EXIT_FAILED,
        )


@dataclass(frozen=True)
class BusOptions:
    """The command line's bus options of `campaign run`, `resume` and `retry`."""

    interface: str | None
    channel: str | None
    speedup: float | None
    seed: int | None
    timing: str | None

    def checked(self, plan: Plan, db: str | None) -> Plan:
        """`checked_plan` with these options."""
        return checked_plan(
            plan,
            interface=self.interface,
            channel=self.channel,
            db=db,
            speedup=self.speedup,
            seed=self.seed,
            timing=self.timing,
        )


def new_campaign(
    plan: Path | Plan,
    db: str | None,
    bus: BusOptions,
    quiet: bool,
    labels: Mapping[str, str] | None = None,
    answers: Sequence[str] = (),
) -> tuple[RunResult, str]:
    """`campaign run PLAN`: a new campaign of the plan file (or parsed plan) with the command
    line's options and `labels`, acquired (`run_campaign`) with the operator's `answers`
    (ID=VALUE) to the plan's prompts; its outcome and the database it went to.
    Everything is checked before anything is written (one-line errors: `_load`, `checked_plan`,
    `preflight`)."""
    from gyrostand.acquisition.operator import record_answers
    from gyrostand.acquisition.store import CampaignStore

    with signals_deferred() as stop:
        checked = bus.checked(_load(plan) if isinstance(plan, Path) else plan, db)
        given = checked_answers(checked, answers)
        preflight(checked)
        sessions = open_db(checked.database, must_exist=False)
        not_interrupted(stop, "the campaign was stored")
        store = CampaignStore.create(sessions, checked, labels=labels)
        record_answers(store, checked.prompts_before("campaign"), given)
        database = checked.database
        return run_campaign(checked, store, quiet, stop, database, answers=given), database


def continue_campaign(
    campaign_id: int,
    db: str,
    bus: BusOptions,
    quiet: bool,
    *,
    retry: tuple[int, ...] | Literal["failed"] | None,
    answers: Sequence[str] = (),
) -> None:
    """Resume a stand campaign, first retrying the trials `retry` names ("failed": every
    failed one): everything is checked before anything is written; then the new attempts are
    added under the campaign's lease, which the acquisition keeps."""
    from gyrostand.acquisition.retry import RetryRefused, retry_trials
    from gyrostand.acquisition.runner import resume_start, resume_store
    from gyrostand.db.lease import CampaignBusy
    from gyrostand.db.queries import (
        CampaignNotFound,
        NotOnTheStand,
        stand_campaign,
        trial_progress,
    )
    from gyrostand.plan.model import PlanError, parse_plan

    with signals_deferred() as stop:
        sessions = open_db(db, must_exist=True)
        try:
            with sessions() as session:  # everything is checked before anything is written
                text = stand_campaign(session, campaign_id).plan_toml
            stored = parse_plan(text)
        except (CampaignNotFound, NotOnTheStand) as exc:
            fail(str(exc))
        except PlanError as exc:
            fail(f"campaign {campaign_id}: stored plan invalid: " + "; ".join(exc.problems))
        checked = bus.checked(stored, db)
        given = checked_answers(checked, answers, new=False)
        preflight(checked)
        not_interrupted(stop, f"campaign {campaign_id} was taken over")
        try:
            if retry is not None:
                retried = retry_trials(sessions, campaign_id, None if retry == "failed" else retry)
                for r in retried:
                    _out().print(
                        printable(
                            f"trial {r.index}: attempt {r.attempt} (attempt {r.attempt - 1} "
                            f"failed: {r.reason})"
                        )
                    )
            _, store = resume_store(sessions, campaign_id)
        except (CampaignNotFound, NotOnTheStand, RetryRefused) as exc:
            fail(str(exc))
        except CampaignBusy as exc:
            fail(str(exc), code=EXIT_FAILED)
        start = resume_start(store, stored, checked)
        with sessions() as session:
            trials = trial_progress(session, campaign_id)
        # the one resume rule: nothing left. A re-run (a simulation killed at every run) goes on
        # all the same: it finishes the trials acquired but not marked (with the stand's motion)
        # and derives again the raw log's frames the killed run had not written out
        if all(t.acquired for t in trials) and start != "continued":
            store.complete_acquired()
            store.set_status("completed")
            _out().print(f"campaign {campaign_id}: nothing left to acquire")
            return
        outcome = run_campaign(checked, store, quiet, stop, db, start, answers=given)
    print_outcome(outcome, db)


Interface = Annotated[
    str | None,
    typer.Option(help="python-can interface (e.g. socketcan); default: the plan's bus."),
]
Channel = Annotated[str | None, typer.Option(help="python-can channel (e.g. can0).")]
Speedup = Annotated[
    float | None,
    typer.Option(
        help="Simulated stand in real time at this many stand s per wall s "
        "(default: the plan's timing; virtual time runs as fast as the CPU allows)."
    ),
]
Seed = Annotated[int | None, typer.Option(help="Simulated stand: random seed.")]
Timing = Annotated[
    str | None,
    typer.Option(
        help="virtual: the stand is simulated in virtual time (in process, or `gyrostand "
        "simulate` on --interface/--channel); realtime: a real stand, or the simulated one "
        "paced by the wall clock. Default: the plan's (realtime with --interface)."
    ),
]
Quiet = Annotated[bool, typer.Option("--quiet", help="No live progress display.")]
Answers = Annotated[
    list[str] | None,
    typer.Option(
        "--answer",
        help="ID=VALUE: the answer to the plan's prompt ID (repeatable; yes to confirm). "
        "Prompts before the campaign not answered are asked on a terminal; prompts before a "
        "trial there or at the station.",
    ),
]


def list_item(row: CampaignRow) -> dict[str, object]:
    """One campaign of `campaign list --json` (times ISO 8601, UTC)."""
    finished = None if row.finished_at is None else row.finished_at.isoformat()
    return {
        "id": row.campaign_id,
        "model": row.model,
        "serial": row.serial,
        "status": row.status,
        "source": row.source,
        "operator": row.operator,
        "started_at": row.started_at.isoformat(),
        "finished_at": finished,
        "labels": row.labels,
        "observations": row.observations,
        "verdict": row.verdict,
        "merged_from": None if row.origin is None else {"from": row.origin[0], "id": row.origin[1]},
    }


def register(app: typer.Typer) -> None:
    """Add the campaign run/resume/retry/status/list, replay command(s) to the CLI."""

    campaign_app = typer.Typer(
        help="Run, resume, retry, inspect and list campaigns.", no_args_is_help=True
    )
    app.add_typer(campaign_app, name="campaign")
    cmd_campaign_remove.register(campaign_app)

    @campaign_app.command("run")
    def campaign_run(
        plan: Annotated[Path, typer.Argument(help="Campaign plan (TOML).")],
        interface: Interface = None,
        channel: Channel = None,
        db: Annotated[
            str | None,
            typer.Option(envvar=DB_ENV, help="Database (file or URL); default: the plan's."),
        ] = None,
        speedup: Speedup = None,
        seed: Seed = None,
        timing: Timing = None,
        tag: TagOption = None,
        answer: Answers = None,
        quiet: Quiet = False,
    ) -> None:
        """Run a campaign plan on the stand (the simulated stand when the plan says so)."""
        bus = BusOptions(interface, channel, speedup, seed, timing)
        outcome, database = new_campaign(
            plan, db, bus, quiet, parse_tags(tag), answers=answer or ()
        )
        print_outcome(outcome, database)

    @campaign_app.command("resume")
    def campaign_resume(
        campaign_id: CampaignId,
        db: Annotated[
            str, typer.Option(envvar=DB_ENV, help="Database (file or URL).")
        ] = DEFAULT_DB,
        interface: Interface = None,
        channel: Channel = None,
        speedup: Speedup = None,
        seed: Seed = None,
        timing: Timing = None,
        retry_failed: Annotated[
            bool,
            typer.Option(
                "--retry-failed", help="First retry every failed trial (see campaign retry)."
            ),
        ] = False,
        answer: Answers = None,
        quiet: Quiet = False,
    ) -> None:
        """Continue a campaign from its first incomplete series (re-settling first). A
        simulated campaign in virtual time that was killed is re-run from its start instead,
        skipping what the database holds: it ends as the uninterrupted run would have."""
        bus = BusOptions(interface, channel, speedup, seed, timing)
        retry = "failed" if retry_failed else None
        continue_campaign(campaign_id, db, bus, quiet, retry=retry, answers=answer or ())

    @campaign_app.command("retry")
    def campaign_retry(
        campaign_id: CampaignId,
        trial: Annotated[
            list[int],
            typer.Option("--trial", help="Index of a failed trial to retry (repeatable)."),
        ],
        db: Annotated[
            str, typer.Option(envvar=DB_ENV, help="Database (file or URL).")
        ] = DEFAULT_DB,
        interface: Interface = None,
        channel: Channel = None,
        speedup: Speedup = None,
        seed: Seed = None,
        timing: Timing = None,
        answer: Answers = None,
        quiet: Quiet = False,
    ) -> None:
        """Re-run failed trials as new attempts (the failed ones are kept), then resume."""
        bus = BusOptions(interface, channel, speedup, seed, timing)
        continue_campaign(campaign_id, db, bus, quiet, retry=tuple(trial), answers=answer or ())

    @campaign_app.command("status")
    def campaign_status(
        campaign_id: CampaignId,
        db: Annotated[
            str, typer.Option(envvar=DB_ENV, help="Database (file or URL).")
        ] = DEFAULT_DB,
    ) -> None:
        """Show where a campaign stands."""
        from sqlalchemy import select

        from gyrostand.db.lease import held_elsewhere
        from gyrostand.db.models import Event
        from gyrostand.db.queries import CampaignNotFound, campaign_summary

        sessions = open_db(db, must_exist=True)
        with sessions() as session:
            try:
                s = campaign_summary(session, campaign_id)
            except CampaignNotFound as exc:
                fail(str(exc))
            recent = session.execute(
                select(Event.severity, Event.kind, Event.message)
                .where(Event.campaign_id == campaign_id, Event.severity != "info")
                .order_by(Event.id.desc())
                .limit(RECENT_EVENTS)
            ).all()
        status = printable(s.status)
        if s.status == "running" and not held_elsewhere(sessions, campaign_id):
            status = "interrupted (left running by a process that is gone; resume continues it)"
        elif s.status == "failed":
            status = "failed (too few trials completed to analyse it; resume --retry-failed)"
        # every stored string goes through printable() and is printed as text (markup off)
        _out().print(
            f"campaign {s.campaign_id} ({printable(s.source)}): {status}, "
            f"{printable(s.instrument)}, operator {printable(s.operator)}, N={s.n_obs}"
        )
        from rich.table import Table
        from rich.text import Text

        table = Table("trial", "role", "status", "j=1", "j=2", "failure")
        for t in s.trials:
            table.add_row(
                *(
                    Text(printable(cell))
                    for cell in (
                        t.index,
                        t.role,
                        t.status,
                        f"{t.observations_by_j.get(1, 0)}/{s.n_obs}",
                        f"{t.observations_by_j.get(2, 0)}/{s.n_obs}",
                        t.failure_reason or "",
                    )
                )
            )
        _out().print(table)
        for t in s.trials:
            if t.earlier:
                before = "; ".join(
                    f"attempt {e.attempt} {e.status}: {e.failure_reason or ''}" for e in t.earlier
                )
                _out().print(
                    printable(f"trial {t.index}: attempt {t.attempt} {t.status} ({before})")
                )
        events = ", ".join(f"{n} {printable(sev)}" for sev, n in s.events_by_severity.items())
        _out().print(f"observations: {s.observations_stored}; events: {events}")
        for severity, kind, message in reversed(recent):
            _out().print(f"  {printable(severity)} ({printable(kind)}): {printable(message)}")
        if s.resume is not None and s.source == "stand":
            _out().print(
                f"next: trial {s.resume.trial_index}, series j={s.resume.j}, "
                f"observation {s.resume.next_k}"
            )

    @campaign_app.command("list")
    def campaign_list(
        model: Annotated[str | None, typer.Option(help="Instrument model.")] = None,
        serial: Annotated[str | None, typer.Option(help="Instrument serial number.")] = None,
        stand: Annotated[
            str | None, typer.Option(help="The stand (the campaigns' label stand=...).")
        ] = None,
        status: Annotated[
            str | None,
            typer.Option(help="planned, running, paused, completed, failed or stopped."),
        ] = None,
        since: Annotated[
            datetime | None,
            typer.Option(formats=["%Y-%m-%d"], help="Started on or after this day (UTC)."),
        ] = None,
        until: Annotated[
            datetime | None,
            typer.Option(formats=["%Y-%m-%d"], help="Started on or before this day (UTC)."),
        ] = None,
        tag: Annotated[
            list[str] | None,
            typer.Option("--tag", help="Only campaigns with this label, key=value (repeatable)."),
        ] = None,
        text: Annotated[
            str | None,
            typer.Option(
                help="Only campaigns whose operator, model or serial contains this (any case)."
            ),
        ] = None,
        as_json: JsonOption = False,
        db: Annotated[
            str, typer.Option(envvar=DB_ENV, help="Database (file or URL).")
        ] = DEFAULT_DB,
    ) -> None:
        """List the campaigns of a database, with filters."""
        import json

        from gyrostand.db.models import CAMPAIGN_STATUSES
        from gyrostand.db.queries import CampaignFilter, campaign_list

        if status is not None and status not in CAMPAIGN_STATUSES:
            fail(f"--status must be one of {', '.join(CAMPAIGN_STATUSES)}, not {status!r}")
        labels = parse_tags(tag)
        if stand is not None:
            if labels.get("stand", stand) != stand:
                fail("--stand and --tag stand=... name different stands")
            labels["stand"] = stand
        day = timedelta(days=1)
        where = CampaignFilter(
            model=model,
            serial=serial,
            status=status,
            labels=tuple(sorted(labels.items())),
            since=None if since is None else since.replace(tzinfo=UTC),
            until=None if until is None else until.replace(tzinfo=UTC) + day,
            text=text,
        )
        if where.since is not None and where.until is not None and where.until <= where.since:
            fail("--until is before --since")
        with open_db(db, must_exist=True)() as session:
            rows = campaign_list(session, where)
        if as_json:
            typer.echo(json.dumps({"campaigns": [list_item(r) for r in rows]}, indent=2))
            return
        lines = [
            (
                "id",
                "model",
                "serial",
                "status",
                "source",
                "started (UTC)",
                "obs",
                "verdict",
                "labels",
            )
        ]
        lines += [
            (
                str(r.campaign_id),
                printable(r.model),
                printable(r.serial),
                r.status,
                r.source
                if r.origin is None
                else f"{r.source}, merged from {r.origin[0]} #{r.origin[1]}",
                r.started_at.strftime("%Y-%m-%d %H:%M"),
                str(r.observations),
                r.verdict,
                printable(" ".join(f"{k}={v}" for k, v in r.labels.items())),
            )
            for r in rows
        ]
        widths = [max(len(line[i]) for line in lines) for i in range(len(lines[0]))]
        for line in lines:  # one campaign a line, whatever the terminal's width (for grep)
            typer.echo("  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip())
        typer.echo(f"{len(rows)} campaign{'' if len(rows) == 1 else 's'}")

    @app.command("replay")
    def replay_command(
        logs: Annotated[
            list[Path],
            typer.Argument(
                help="Raw CAN log of a campaign (.blf or .asc); several: its segments in "
                "order (a resumed campaign's), read as one stream.",
                show_default=False,
            ),
        ],
        plan: Annotated[Path, typer.Option("--plan", help="The campaign's plan (TOML).")],
        db: Annotated[
            str | None,
            typer.Option(envvar=DB_ENV, help="Database (file or URL); default: the plan's."),
        ] = None,
    ) -> None:
        """Re-derive observations offline from raw CAN logs into a new campaign. The logs are
        read whole before the database is opened: a log that cannot be replayed leaves it as
        it was. A replayed campaign cannot be resumed on the stand."""
        import can

        from gyrostand.acquisition.runner import ReplayLogError, check_replay_log, replay
        from gyrostand.campaign_procedures import replay_procedures_log

        checked = checked_plan(
            _load(plan), interface=None, channel=None, db=db, speedup=None, seed=None
        )
        readable = []
        for log in logs:
            if not log.is_file():
                fail(f"no log file at {log}")
            try:
                readable.append(check_replay_log(log))
            except ReplayLogError as exc:
                fail(f"cannot replay {exc}")
        if checked.compass.protocol == "iec61162":  # its serial logs, before any progress line
            from gyrostand.devices.serial_replay import check_serial_logs
            from gyrostand.frames.logfile import LogFileError

            try:
                check_serial_logs(logs, checked.bus.timing == "virtual")
            except LogFileError as exc:
                fail(f"cannot replay {exc}")
        if checked.stand.protocol == "cia402":  # its drive's traffic, from a run's start
            from gyrostand.acquisition.cia402_replay import check_first_log
            from gyrostand.devices.cia402_log import DriveLogError

            try:
                check_first_log(checked, readable[0].path)
            except DriveLogError as exc:
                fail(f"cannot replay {exc}")
        try:  # the standard's procedures: from their log beside the first, before the database
            procedures = replay_procedures_log(checked, logs[0])
        except ReplayLogError as exc:
            fail(f"cannot replay {exc}")
        with Stages("replay") as stage:
            sessions = open_db(checked.database, must_exist=False)
            stage(f"logs read; re-deriving the observations into {shown_url(checked.database)}")
            try:
                result = replay(checked, sessions, logs, readable, procedures)
            except (ReplayLogError, ValueError, OSError, can.CanError) as exc:  # changed since
                fail(f"replay of {printable(logs[-1])} failed: {exc}", code=EXIT_FAILED)
            rederived = ", the standard's procedures re-derived" if procedures else ""
            stage.done(
                f"campaign {result.campaign_id}: {result.observations} observations{rederived}"
            )
        print_outcome(result, checked.database, resumable=False)
