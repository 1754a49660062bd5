"""CLI: campaign remove -- take campaigns out of a database (a simulated fleet, a trial run),
after a confirmation (`--yes` for scripts), keeping a record of each removal (db.removal)."""

from __future__ import annotations

import getpass
import sys
from pathlib import Path
from typing import Annotated

import typer

from gyrostand.cmd_data import DEFAULT_DB, MAX_CAMPAIGN_ID, DbOption, open_db
from gyrostand.db.url import shown_url
from gyrostand.errors import EXIT_FAILED, fail, printable


def _login() -> str:
    """Who runs the command: the operating system's login name ('' when there is none)."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no name for the uid (a container)
        return ""


def _interactive() -> bool:
    """Whether someone at a terminal can answer the confirmation."""
    return sys.stdin is not None and sys.stdin.isatty()


def register(campaign_app: typer.Typer) -> None:
    """Add `campaign remove` to the campaign command group."""

    @campaign_app.command("remove")
    def campaign_remove(
        campaign_ids: Annotated[
            list[int],
            typer.Argument(
                help="The campaigns' ids.", min=1, max=MAX_CAMPAIGN_ID, metavar="CAMPAIGN..."
            ),
        ],
        db: DbOption = DEFAULT_DB,
        yes: Annotated[
            bool, typer.Option("--yes", help="Remove without asking (for scripts).")
        ] = False,
        reason: Annotated[
            str | None, typer.Option("--reason", help="Why, for the removal record.")
        ] = None,
        by: Annotated[
            str | None,
            typer.Option("--by", help="Who removes them (default: your login name)."),
        ] = None,
        delete_raw_logs: Annotated[
            bool,
            typer.Option(
                "--delete-raw-logs",
                help="Delete their raw CAN logs (with the serial logs beside, the standard's "
                "procedures' logs, and a killed run's progress file) that no campaign left refers "
                "to (default: the files are kept where they are, named in the removal record).",
            ),
        ] = False,
    ) -> None:
        """Remove campaigns from a database, keeping a record of each removal.

        Their trials, observations, events, analyses and sign-offs go, in one transaction; a
        removal record stays with each one's content SHA-256, what it was (instrument, status,
        labels, origin, raw logs), who removed it, when and why. Asks first, on a terminal;
        elsewhere give --yes."""
        from gyrostand import SOFTWARE_VERSION
        from gyrostand.acquisition.procedures import procedures_logs_of
        from gyrostand.db.models import Campaign
        from gyrostand.db.queries import live_file_of
        from gyrostand.db.removal import RemovalRefused, remove_campaigns
        from gyrostand.devices.serial_replay import serial_log_path

        remover = (by if by is not None else _login()).strip()
        if not remover:
            fail("--by: say who removes the campaigns (no login name to default to)")
        if reason is not None and not reason.strip():
            fail("--reason: the reason is empty")
        sessions = open_db(db, must_exist=True)
        with sessions() as session:
            found = {c: session.get(Campaign, c) for c in dict.fromkeys(campaign_ids)}
            missing = [str(c) for c, campaign in found.items() if campaign is None]
            if missing:
                fail(f"no campaign {', '.join(missing)} in {shown_url(db)}; nothing removed")
            listed = [
                f"campaign {c.id}: {c.instrument.model} {c.instrument.serial}, {c.status}, "
                f"{c.source}, created {c.created_at:%Y-%m-%d %H:%M}, raw logs: {len(c.raw_logs)}"
                for c in found.values()
                if c is not None
            ]
        if not yes:
            if not _interactive():
                fail("campaign remove asks before removing: confirm with --yes")
            for line in listed:
                typer.echo(printable(line), err=True)
            question = f"Remove {len(listed)} campaign(s) from {shown_url(db)}?"
            if not typer.confirm(question, err=True):
                fail("nothing removed", EXIT_FAILED)
        try:
            removed = remove_campaigns(
                sessions,
                list(found),
                removed_by=remover,
                reason=None if reason is None else reason.strip(),
                delete_raw_logs=delete_raw_logs,
                software_version=SOFTWARE_VERSION,
                # the serial and the procedures' logs beside, the progress file a killed run left
                files_of=lambda log: (
                    Path(log),
                    serial_log_path(log),
                    *procedures_logs_of(log),
                    live_file_of(log),
                ),
            )
        except RemovalRefused as error:
            fail(str(error))
        for r in removed:
            logs = "no raw logs"
            if r.raw_logs:
                logs = "raw logs " + ("deleted" if delete_raw_logs else "kept: ")
                logs += "" if delete_raw_logs else ", ".join(r.raw_logs)
            typer.echo(
                printable(
                    f"removed campaign {r.campaign_id} (content SHA-256 {r.content_sha256[:16]}, "
                    f"removal record {r.removal_id}); {logs}"
                )
            )
