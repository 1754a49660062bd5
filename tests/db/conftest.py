"""Fixtures for the database tests: a fresh SQLite file per test, and a minimal valid campaign."""

from pathlib import Path

import pytest
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.models import Campaign, Instrument, Series, Trial
from gyrostand.db.session import open_database, sqlite_url


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
