"""Fixtures for the database tests: a fresh SQLite file per test, a minimal valid campaign, and
stands running campaigns at once."""

import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import pytest
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.models import Campaign, Instrument, Series, Trial
from gyrostand.db.session import open_database, sqlite_url
from tests.acquisition.harness import FAST_SIM, plan_text

TRIALS = [(45.0, 24.0, 6.0, "fit"), (315.0, 20.0, 5.0, "fit"), (30.0, 20.0, 6.0, "fit")]
"""Three fit trials: enough for a fit, quick on the simulated stand (N = 3)."""


@pytest.fixture
def db_path(tmp_path: Path) -> Path:
    return tmp_path / "lab" / "gyrostand.sqlite"


@pytest.fixture
def sessions(db_path: Path) -> sessionmaker[Session]:
    return open_database(sqlite_url(db_path))


def make_campaign(session: Session, n_trials: int = 1) -> Campaign:
    """A planned campaign with `n_trials` pending trials, each with its two pending series."""
    instrument = Instrument(model="Kurs-4", serial="0001", constants_json={"lp_gcm2s2": 6.57e6})
    campaign = Campaign(
        instrument=instrument,
        plan_toml="",
        plan_hash="0" * 64,
        operator="test",
        latitude_deg=46.5,
        n_obs=5,
        software_version="test",
    )
    for i in range(1, n_trials + 1):
        trial = Trial(
            index=i, role="fit", cmd_direction_deg=332, cmd_amplitude_cm=24, cmd_period_s=8
        )
        trial.series = [Series(j=1), Series(j=2)]
        campaign.trials.append(trial)
    session.add(campaign)
    session.flush()
    return campaign


def run_stands_at_once(folder: Path, databases: Sequence[str]) -> list[str]:
    """`gyrostand campaign run` of the quick plan into each database, all at once, each in a
    process of its own (stand n: label stand=Sn, seed n); returns their stderr, each run having
    succeeded."""
    runs = []
    for n, database in enumerate(databases, 1):
        plan = folder / f"s{n}.toml"
        plan.write_text(
            plan_text(TRIALS, database=database, raw_dir=str(folder / f"raw{n}"), seed=n) + FAST_SIM
        )
        runs.append(
            subprocess.Popen(
                [sys.executable, "-m", "gyrostand", "campaign", "run", str(plan), "--quiet"]
                + ["--tag", f"stand=S{n}"],
                cwd=folder,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    errors = []
    for run in runs:
        _, err = run.communicate(timeout=600)
        assert run.returncode == 0, err
        errors.append(err)
    return errors
