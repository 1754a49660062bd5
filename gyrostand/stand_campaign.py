"""A gyrostand campaign plan run against a `SimulatedStand` as `campaign run --interface ...
--channel ...` runs it against a stand on a bus: acquisition into a SQLite file of a given
folder, then the analysis `analyze` gives (Potemkin 1982)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import typer

from gyrostand.analysis.campaign import CampaignAnalysis
from gyrostand.cmd_campaign import BusOptions, new_campaign
from gyrostand.cmd_data import open_db
from gyrostand.db.lease import take_lease
from gyrostand.plan.model import Plan, PlanError, load_plan, revised
from gyrostand.report.stored import analyze_stored
from gyrostand.simulated_stand import SimulatedStand


class CampaignNotRun(RuntimeError):
    """gyrostand refused the plan or the bus (its one-line reason went to stderr)."""


@dataclass(frozen=True)
class CampaignRun:
    """A campaign acquired from the simulated stand, and its analysis (None when the plan is
    `acquisition_only`)."""

    campaign_id: int
    outcome: str  # completed | failed (cannot be analysed) | paused | stopped
    trials_completed: int
    trials_failed: int
    observations: int
    database: Path
    analysis: CampaignAnalysis | None


def run_plan(stand: SimulatedStand, plan: Path | Plan, folder: Path) -> CampaignRun:
    """Run `plan` (a plan file or a parsed plan) on the stand's bus in the stand's timing, with
    its database and raw logs in `folder`. A plan naming no DBC and no `[signals]` speaks the
    stand's."""
    try:
        parsed = load_plan(plan) if isinstance(plan, Path) else plan
        tables: dict[str, dict[str, object]] = {"campaign": {"raw_log_dir": str(folder / "raw")}}
        if not parsed.dbc_path and not parsed.signals:
            if stand.spec.dbc is not None:
                tables["protocol"] = {"dbc_path": str(stand.spec.dbc)}
            tables["signals"] = dict(stand.spec.signals)
        parsed = revised(parsed, **tables)
    except PlanError as exc:
        raise CampaignNotRun(f"{plan}: invalid plan: " + "; ".join(exc.problems)) from None
    database = folder / "campaign.sqlite"
    bus = BusOptions(stand.interface, stand.channel, None, None, stand.config.timing)
    try:
        result, _ = new_campaign(parsed, str(database), bus, quiet=True)
    except typer.Exit as exc:
        raise CampaignNotRun(
            f"the campaign did not run (exit code {exc.exit_code}; the reason is on stderr)"
        ) from None
    sessions = open_db(str(database), must_exist=True)
    try:
        take_lease(sessions, result.campaign_id).release()  # as the command's exit does
        analysis = None
        if not parsed.campaign.acquisition_only:
            analysis = analyze_stored(sessions, result.campaign_id).analysis
    finally:
        sessions.kw["bind"].dispose()
    return CampaignRun(
        campaign_id=result.campaign_id,
        outcome=result.outcome,
        trials_completed=result.trials_completed,
        trials_failed=result.trials_failed,
        observations=result.observations,
        database=database,
        analysis=analysis,
    )
