"""`gyrostand campaign remove`: a confirmation (or --yes), every row of the campaigns gone in one
transaction and nothing else, a removal record with who, when, why and the content's SHA-256,
raw logs kept or deleted; refusals change nothing. On both database back ends."""

import threading
from pathlib import Path

import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from gyrostand.acquisition.store import CampaignStore
from gyrostand.campaign_procedures import run_procedures_of
from gyrostand.cli import app
from gyrostand.db.merge import campaign_rows, content_sha256, copy_campaign
from gyrostand.db.models import (
    AnalysisRun,
    Base,
    CampaignRemoval,
    RawLogSegment,
)
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.plan.model import parse_plan
from tests.acquisition.harness import ROOT
from tests.procedures.test_campaign_procedures import plan as procedures_plan

PAPER_CSV = str(ROOT / "examples" / "paper.csv")


def gyrostand(*args: str, input: str | None = None) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, list(args), input=input)
    return result.exit_code, result.stdout, result.stderr


def counts(url: str) -> dict[str, int]:
    sessions = open_database(url)
    with sessions() as session:
        found = {
            t.name: session.scalar(select(func.count()).select_from(t))
            for t in Base.metadata.sorted_tables
        }
    sessions.kw["bind"].dispose()
    return found


@pytest.fixture
def three(db_url: str, tmp_path: Path) -> list[Path]:
    """Campaign 1 imported from the paper, 2 and 3 copies of it; 1 analysed; a raw log for each
    of 1 and 2 (a serial log beside 1's), and 3 refers to 2's log (as a replay of it would)."""
    assert gyrostand("import", PAPER_CSV, "--db", db_url)[0] == 0
    logs = [tmp_path / "raw-1.blf", tmp_path / "raw-2.blf"]
    for log in logs:
        log.write_bytes(b"frames")
    (tmp_path / "raw-1.nmea").write_text("sentences")
    sessions = open_database(db_url)
    with sessions.begin() as session:
        paper = campaign_rows(session, 1)
        assert [copy_campaign(session, paper) for _ in range(2)] == [2, 3]
        session.add(AnalysisRun(campaign_id=1, inputs_hash="0" * 64, results_json={},
                                software_version="test"))  # fmt: skip
        for campaign, log in ((1, logs[0]), (2, logs[1]), (3, logs[1])):
            session.add(RawLogSegment(campaign_id=campaign, seq=1, path=str(log), start="new"))
    sessions.kw["bind"].dispose()
    return logs


def test_remove_takes_every_row_of_the_campaigns_and_records_each_removal(
    db_url: str, three: list[Path]
) -> None:
    sessions = open_database(db_url)
    with sessions() as session:
        rows = {c: campaign_rows(session, c) for c in (1, 2, 3)}
    sessions.kw["bind"].dispose()
    before = {c: content_sha256(r) for c, r in rows.items()}
    one = counts(db_url)
    args = ["campaign", "remove", "1", "2", "--db", db_url, "--yes"]
    code, out, err = gyrostand(*args, "--by", "A. Tester", "--reason", "a simulated fleet")
    assert code == 0, err
    assert out.splitlines() == [
        f"removed campaign 1 (content SHA-256 {before[1][:16]}, removal record 1); raw logs "
        f"kept: {three[0]}",
        f"removed campaign 2 (content SHA-256 {before[2][:16]}, removal record 2); raw logs "
        f"kept: {three[1]}",
    ]
    after = counts(db_url)
    for table, kept in after.items():  # each table lost the two campaigns' rows, no other
        gone = sum(len(rows[c].tables.get(table, [])) for c in (1, 2))
        assert one[table] - kept == (-2 if table == "campaign_removal" else gone), table
    assert (one["trial"], one["event"], one["analysis_run"]) == (18, 3, 1)  # 3 imports of 6 trials
    assert (after["trial"], after["event"], after["analysis_run"]) == (6, 1, 0)
    assert after["campaign_removal"] == 2 and after["instrument"] == one["instrument"]
    sessions = open_database(db_url)
    with sessions() as session:
        records = session.scalars(select(CampaignRemoval).order_by(CampaignRemoval.id)).all()
        assert session.scalar(select(func.count(AnalysisRun.id))) == 0
    sessions.kw["bind"].dispose()
    assert [(r.campaign_id, r.content_sha256) for r in records] == [(1, before[1]), (2, before[2])]
    first = records[0]
    assert (first.removed_by, first.reason, first.raw_logs) == (
        "A. Tester",
        "a simulated fleet",
        "kept",
    )
    assert first.record["instrument"]["serial"] == "Potemkin-1982"
    assert first.record["status"] == "completed" and first.record["source"] == "import"
    assert first.record["raw_logs"] == [{"path": str(three[0]), "sha256": None, "frames": None}]
    assert first.record["analysis_runs"] == 1 and first.software_version.startswith("gyrostand ")
    assert all(log.is_file() for log in three)  # kept where they are
    sessions = open_database(db_url)
    with sessions() as session:
        assert content_sha256(campaign_rows(session, 3)) == before[3]
    sessions.kw["bind"].dispose()


def test_delete_raw_logs_deletes_only_files_no_campaign_left_refers_to(
    db_url: str, three: list[Path]
) -> None:
    live = three[0].with_suffix(".live.json")  # a killed run's progress file
    live.write_text("{}")
    args = ["campaign", "remove", "1", "2", "--db", db_url, "--yes", "--delete-raw-logs"]
    code, out, err = gyrostand(*args)
    assert code == 0, err
    assert out.count("raw logs deleted") == 2
    assert not three[0].exists() and not three[0].with_suffix(".nmea").exists()
    assert not live.exists()
    assert three[1].is_file()  # campaign 3 still refers to it
    sessions = open_database(db_url)
    with sessions() as session:
        assert session.scalars(select(CampaignRemoval.raw_logs)).all() == ["deleted", "deleted"]
    sessions.kw["bind"].dispose()


REFUSED = [
    (["1"], "campaign remove asks before removing: confirm with --yes"),
    (["1", "9", "--yes"], "no campaign 9 in "),
    (["1", "--yes", "--by", " "], "--by: say who removes the campaigns"),
    (["1", "--yes", "--reason", ""], "--reason: the reason is empty"),
]


def test_refusals_change_nothing(db_url: str, three: list[Path]) -> None:
    before = counts(db_url)
    for args, message in REFUSED:
        code, _, err = gyrostand("campaign", "remove", *args, "--db", db_url)
        assert code == 2 and err.startswith("gyrostand: error: ") and message in err, err
        assert "Traceback" not in err and counts(db_url) == before


def test_the_confirmation_on_a_terminal(
    db_url: str, three: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("gyrostand.cmd_campaign_remove._interactive", lambda: True)
    before = counts(db_url)
    code, _, err = gyrostand("campaign", "remove", "3", "--db", db_url, input="n\n")
    assert code == 1 and "nothing removed" in err and counts(db_url) == before
    assert "campaign 3: two-rotor gyrocompass (example of Potemkin 1982) Potemkin-1982, " in err
    assert "Remove 1 campaign(s) from " in err
    code, out, err = gyrostand("campaign", "remove", "3", "--db", db_url, input="y\n")
    assert code == 0 and "removed campaign 3 (" in out, err
    assert counts(db_url)["campaign"] == 2


def test_a_campaign_stopped_in_its_procedures_names_and_deletes_their_raw_log(
    tmp_path: Path,
) -> None:
    """Stopped before its trials began (no raw log segment): the procedures' log it wrote is
    its raw log, named in the removal record and deleted with --delete-raw-logs."""
    plan = parse_plan(procedures_plan(tmp_path))
    sessions = open_database(sqlite_url(plan.database))
    store = CampaignStore.create(sessions, plan)
    stop = threading.Event()
    stop.set()  # the procedures stop once their first stage is saved
    assert run_procedures_of(plan, store, True, stop) is False
    store.set_status("stopped")
    store.lease.release()
    (log,) = (tmp_path / "raw").iterdir()
    assert log.name == "p-campaign-1.procedures.blf"
    # the logs resumed runs on a real bus write beside it (campaign_procedures._on_the_bus)
    resumed = [log.with_name(f"p-campaign-1.procedures-resume{k}.blf") for k in (1, 2)]
    for path in resumed:
        path.write_bytes(log.read_bytes())
    args = ["campaign", "remove", "1", "--db", str(plan.database), "--yes"]
    code, out, err = gyrostand(*args, "--delete-raw-logs")
    assert code == 0, err
    assert out.endswith("; raw logs deleted\n") and not log.exists()
    assert list((tmp_path / "raw").iterdir()) == []
    with sessions() as session:
        removal = session.scalars(select(CampaignRemoval)).one()
    assert removal.raw_logs == "deleted"
    assert removal.record["raw_logs"] == [{"path": str(log), "sha256": None, "frames": None}]
