"""`gyrostand import` and `gyrostand export`: exit codes, one-line errors, database untouched."""

import re
import sqlite3
import time
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.models import Campaign
from gyrostand.db.session import open_database, sqlite_url
from tests.db.test_io import PAPER_CSV, dump, observation_rows

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


def gyrostand(*args: str | Path) -> tuple[int, str, str]:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture
def paper(tmp_path: Path) -> Path:
    path = tmp_path / "paper.csv"
    path.write_text(PAPER_CSV)
    return path


def campaign(db: Path, campaign_id: int) -> Campaign:
    with open_database(sqlite_url(db))() as session:
        return session.get_one(Campaign, campaign_id)


def test_import_without_plan_says_which_constants_it_used(paper: Path, db_path: Path) -> None:
    code, out, err = gyrostand("import", paper, "--db", db_path, "--operator", "V. Potemkin")
    assert code == 0
    assert out == f"imported {paper} (trials form, 6 trials, N = 5) as campaign 1\n"
    assert (
        err.startswith("no --plan: used the example instrument and site of Potemkin (1982)")
        and err.count("\n") == 1
    )
    stored = campaign(db_path, 1)
    assert (stored.operator, stored.latitude_deg, stored.source) == ("V. Potemkin", 46.5, "import")


def test_import_with_plan_stores_it(paper: Path, db_path: Path) -> None:
    plan = ROOT / "examples" / "paper.toml"
    code, out, err = gyrostand("import", paper, "--plan", plan, "--db", db_path)
    assert (code, err) == (0, "")
    assert out.endswith("as campaign 1\n")
    stored = campaign(db_path, 1)
    assert stored.plan_toml == plan.read_text()
    assert stored.operator == "stand operator"  # the plan's [campaign] operator


def test_plan_with_missing_keys_is_refused(paper: Path, db_path: Path, tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text('[instrument]\nmodel = "x"\nserial = "1"\nh1_gcm2s = 1.55e8\n[site]\n')
    code, out, err = gyrostand("import", paper, "--plan", plan, "--db", db_path)
    assert code == 2 and out == ""
    assert err == (
        f"gyrostand: error: {plan}: invalid plan: [instrument] lp_gcm2s2: missing; "
        "[site] latitude_deg: missing\n"
    )
    plan.write_text("[instrument\n")
    code, _, err = gyrostand("import", paper, "--plan", plan, "--db", db_path)
    assert code == 2 and err.startswith(f"gyrostand: error: {plan}: invalid plan: TOML syntax")
    plan.write_text(
        (ROOT / "examples" / "paper.toml")
        .read_text()
        .replace("latitude_deg = 46.5", "latitude_deg = -91.0", 1)
    )
    code, _, err = gyrostand("import", paper, "--plan", plan, "--db", db_path)
    assert code == 2 and "[site] latitude_deg: must be > -90" in err
    assert not db_path.exists()


def test_bad_import_file_one_clear_error_and_database_untouched(
    paper: Path, db_path: Path, tmp_path: Path
) -> None:
    assert gyrostand("import", paper, "--db", db_path)[0] == 0
    before = dump(db_path)
    bad = tmp_path / "bad.csv"
    bad.write_text(PAPER_CSV.replace("3,fit,316", "3,fit,316.5x"))
    code, out, err = gyrostand("import", bad, "--db", db_path)
    assert (code, out) == (2, "")
    assert (
        err == f"gyrostand: error: {bad}: line 5: direction_deg '316.5x' is not a finite number\n"
    )
    assert dump(db_path) == before


def test_export_then_import_round_trip(db_path: Path, tmp_path: Path) -> None:
    observation_rows().to_csv(tmp_path / "obs.csv", index=False)
    assert gyrostand("import", tmp_path / "obs.csv", "--db", db_path)[0] == 0
    out = tmp_path / "export" / "c1.csv"
    code, printed, _ = gyrostand("export", "1", "--format", "csv", "--out", out, "--db", db_path)
    assert code == 0
    assert printed.splitlines() == [
        f"wrote {out}: 24 observations",
        f"wrote {out.with_name('c1.series.csv')}: 6 series",
        f"wrote {out.with_name('c1.trials.csv')}: 3 trials",
    ]
    code, printed, _ = gyrostand("import", out, "--db", db_path)
    assert code == 0 and re.search(r"as campaign 2$", printed.strip())
    out2 = tmp_path / "export" / "c2.csv"
    assert gyrostand("export", "2", "--out", out2, "--db", db_path)[0] == 0
    assert out2.read_bytes() == out.read_bytes()
    exported = pd.read_csv(out)
    assert exported.value_deg.tolist() == observation_rows().value_deg.tolist()


def test_export_xlsx_default_path(
    db_path: Path, paper: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert gyrostand("import", paper, "--db", db_path)[0] == 0
    monkeypatch.chdir(tmp_path)
    code, printed, _ = gyrostand("export", "1", "-f", "xlsx", "--db", db_path)
    assert code == 0 and "runs/export/campaign-1.xlsx [trials]: 6 trials" in printed
    trials = pd.read_excel(tmp_path / "runs/export/campaign-1.xlsx", sheet_name="trials")
    assert trials.delta_mean_deg.tolist() == [-0.117, 0.21, -0.466, -0.401, 0.32, -0.11]


def test_export_errors(db_path: Path, paper: Path, tmp_path: Path) -> None:
    code, _, err = gyrostand("export", "1", "--db", tmp_path / "none.sqlite")
    assert (code, err) == (2, f"gyrostand: error: no database at {tmp_path / 'none.sqlite'}\n")
    assert not (tmp_path / "none.sqlite").exists()
    assert gyrostand("import", paper, "--db", db_path)[0] == 0
    code, _, err = gyrostand("export", "9", "--db", db_path)
    assert (code, err) == (2, "gyrostand: error: no campaign 9 in the database\n")
    assert gyrostand("export", "1", "--format", "pdf", "--db", db_path)[0] == 2


def test_database_newer_than_the_code_is_a_clean_error(paper: Path, db_path: Path) -> None:
    assert gyrostand("import", paper, "--db", db_path)[0] == 0
    with sqlite3.connect(db_path) as conn:
        conn.execute("UPDATE alembic_version SET version_num = 'ffff'")
    code, _, err = gyrostand("import", paper, "--db", db_path)
    assert code == 2
    assert err.startswith("gyrostand: error: sqlite:///") and "newer than this gyrostand" in err
    assert err.count("\n") == 1


def test_locked_database_is_a_clean_error_and_nothing_is_written(
    paper: Path, db_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert gyrostand("import", paper, "--db", db_path)[0] == 0
    before = dump(db_path)
    monkeypatch.setattr("gyrostand.db.session.BUSY_TIMEOUT_MS", 50)
    other_writer = sqlite3.connect(db_path, isolation_level=None)
    other_writer.execute("BEGIN IMMEDIATE")  # e.g. a running campaign holding the write lock
    try:
        code, _, err = gyrostand("import", paper, "--db", db_path)
    finally:
        other_writer.execute("ROLLBACK")
        other_writer.close()
    assert code == 2
    assert err == (
        "gyrostand: error: nothing imported, the database refused the write: database is locked\n"
    )
    assert dump(db_path) == before


def test_import_waits_for_a_campaign_that_writes_and_commits_meanwhile(
    paper: Path, db_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Another writer (a running campaign) holds the write lock while the import starts, writes
    and commits half a second later: the import waits its turn (busy timeout) and then stores
    its campaign. Before: "database is locked" (the import's transaction had read the database
    before the other commit, so it could not write after it)."""
    import threading

    from gyrostand.db import io

    assert gyrostand("import", paper, "--db", db_path)[0] == 0
    other_writer = sqlite3.connect(db_path, isolation_level=None, check_same_thread=False)
    other_writer.execute("BEGIN IMMEDIATE")
    other_writer.execute("UPDATE campaign SET operator = 'campaign writer' WHERE id = 1")
    importing = threading.Event()

    def commit_later() -> None:
        importing.wait(60)
        time.sleep(0.5)  # the import is inside its transaction meanwhile
        other_writer.execute("COMMIT")

    def store_import(*args: object, **kwargs: object) -> object:
        importing.set()
        return real_store_import(*args, **kwargs)

    real_store_import = io.store_import
    monkeypatch.setattr(io, "store_import", store_import)
    committer = threading.Thread(target=commit_later)
    committer.start()
    try:
        code, out, err = gyrostand("import", paper, "--db", db_path)
    finally:
        importing.set()
        committer.join()
        other_writer.close()
    assert code == 0 and out.endswith("as campaign 2\n"), err
    assert campaign(db_path, 1).operator == "campaign writer"
    with sqlite3.connect(db_path) as connection:
        counts = connection.execute(
            "SELECT campaign_id, COUNT(*) FROM trial GROUP BY campaign_id ORDER BY 1"
        ).fetchall()
    assert counts == [(1, 6), (2, 6)]  # PAPER_CSV's 6 trials, imported twice
