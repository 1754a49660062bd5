"""Two stands, one SQLite file: two `campaign run` processes at once both complete, nothing lost
or duplicated, nothing "database is locked"."""

import subprocess
import sys
from pathlib import Path

from sqlalchemy import create_engine, text

from tests.acquisition.harness import FAST_SIM, plan_text

TRIALS = [(45.0, 24.0, 6.0, "fit"), (315.0, 20.0, 5.0, "fit"), (30.0, 20.0, 6.0, "fit")]


def test_two_campaigns_into_one_sqlite_file_at_once(tmp_path: Path) -> None:
    db = tmp_path / "lab.sqlite"
    runs = []
    for stand in (1, 2):
        plan = tmp_path / f"stand{stand}.toml"
        plan.write_text(
            plan_text(TRIALS, database=str(db), raw_dir=str(tmp_path / f"raw{stand}"), seed=stand)
            + FAST_SIM
        )
        runs.append(
            subprocess.Popen(
                [sys.executable, "-m", "gyrostand", "campaign", "run", str(plan), "--quiet"],
                cwd=tmp_path,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    for run in runs:
        out, err = run.communicate(timeout=600)
        assert run.returncode == 0, err
        assert "locked" not in err
    engine = create_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        campaigns = conn.execute(text("SELECT id, status FROM campaign ORDER BY id")).all()
        counts = conn.execute(
            text(
                "SELECT t.campaign_id, count(*), count(DISTINCT s.id || '-' || o.k)"
                " FROM observation o JOIN series s ON s.id = o.series_id"
                " JOIN trial t ON t.id = s.trial_id GROUP BY t.campaign_id ORDER BY 1"
            )
        ).all()
    engine.dispose()
    assert [tuple(c) for c in campaigns] == [(1, "completed"), (2, "completed")]
    # 3 trials x 2 series x N = 3 observations each, none duplicated
    assert [tuple(c) for c in counts] == [(1, 18, 18), (2, 18, 18)]
