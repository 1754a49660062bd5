"""`gyrostand fleet simulate` and `fleet report` end to end: a simulated fleet of three factories
(two units each, on the quick test plan), factory B's C 40 % larger; the analysis and the report
set B apart and no other (`fleet analyze`, text and JSON); each campaign stores the plan it ran;
the one-line refusals of analyze, report and simulate."""

import json
import re
import shlex
import sqlite3
from dataclasses import dataclass
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.cmd_demo import DEMO_PLAN
from gyrostand.db.models import Campaign
from gyrostand.db.session import open_database
from gyrostand.plan.model import parse_plan
from gyrostand.simulated_fleet import QUICK, with_tables
from tests.acquisition.harness import FAST_SIM, plan_text

TRIALS = [
    (332.0, 24.0, 8.0, "fit"),
    (18.0, 24.0, 6.3, "fit"),
    (316.0, 23.0, 5.5, "fit"),
    (346.0, 17.8, 3.5, "fit"),
]
MODEL = "cli compass"


@dataclass(frozen=True)
class Fleet:
    db: str
    folder: Path
    output: str
    progress: str  # stderr


def gyrostand(*args: str) -> str:
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Fleet:
    folder = tmp_path_factory.mktemp("fleet-cli")
    db = f"sqlite:///{folder / 'lab.sqlite'}"
    text = plan_text(TRIALS, n_obs=10, database=db, raw_dir=str(folder / "raw")) + FAST_SIM
    plan = folder / "plan.toml"
    plan.write_text(text.replace("acquisition_only = true", "acquisition_only = false"))
    result = CliRunner().invoke(
        app,
        [
            *("fleet", "simulate", "--db", db, "--plan", str(plan), "--model", MODEL),
            *("--groups", "3", "--units-per-group", "2", "--shift", "0.4", "--seed", "3"),
        ],
    )
    assert result.exit_code == 0, result.output
    return Fleet(db, folder, result.stdout, result.stderr)


def analysis(fleet: Fleet) -> dict[str, object]:
    args = ("--model", MODEL, "--by", "factory", "--db", fleet.db)
    return json.loads(gyrostand("fleet", "analyze", *args, "--json"))


def test_simulate_says_what_it_made_and_what_to_run_next(fleet: Fleet) -> None:
    lines = fleet.output.splitlines()
    assert lines[0] == (
        f"fleet of {MODEL}: 3 factories x 2 units, factory B's C shifted by +40%; one campaign "
        f"a unit into {fleet.db}"
    )
    units = [line for line in lines if line.startswith("  campaign ")]
    assert [u.split(":")[1].split()[0] for u in units] == [
        "A-001",
        "A-002",
        "B-001",
        "B-002",
        "C-001",
        "C-002",
    ]
    where = f"--model {shlex.quote(MODEL)} --by factory --db {fleet.db}"
    assert "the measurement/type split (fleet analysis) against the known truth; " in fleet.output
    checks = [line for line in lines if re.match(r"  [CT]: actual errors RMS ", line)]
    assert len(checks) == 2 and "drawn with 3%" in checks[0] and "drawn with 0.03 s" in checks[1]
    assert f"  gyrostand fleet analyze {where}" in lines
    assert f"  gyrostand fleet report {where} -o fleet.pdf" in lines


def test_simulate_tells_its_progress_on_stderr(fleet: Fleet) -> None:
    """Off a terminal: a plain line per unit, then the summary with the time taken."""
    lines = fleet.progress.splitlines()
    assert "\x1b" not in fleet.progress
    assert lines[:-1] == [
        "fleet simulate: running and analysing unit 1/6 on the simulated stand",
        *(f"fleet simulate: unit {k}/6 done; running unit {k + 1}" for k in range(1, 6)),
    ]
    assert re.fullmatch(r"fleet simulate: 6 campaigns run and analysed \(\d+\.\d s\)", lines[-1])


def test_each_campaign_stores_the_plan_it_ran(fleet: Fleet) -> None:
    printed = {
        line.split(":")[1].split()[0]: float(line.split("C = ")[1].split("e7")[0]) * 1e7
        for line in fleet.output.splitlines()
        if line.startswith("  campaign ")
    }
    sessions = open_database(fleet.db)
    with sessions() as session:
        for campaign in session.query(Campaign):
            plan = parse_plan(campaign.plan_toml)
            assert plan.instrument.model == MODEL
            serial = plan.instrument.serial
            compass = plan.bus.simulator.compass
            assert compass.c_gcm2s2 == pytest.approx(printed[serial], rel=1e-3)
    assert len(printed) == 6


def test_the_shifted_factory_is_set_apart_in_c_and_no_factory_in_t(fleet: Fleet) -> None:
    document = analysis(fleet)
    assert document["n_units"] == 6 and len(document["units"]) == 6
    c, t = document["parameters"]
    assert c["anova"]["groups_differ"] and not t["anova"]["groups_differ"]
    assert [g["group"] for g in c["groups"] if g["differs"]] == ["B"]
    assert not [g["group"] for g in t["groups"] if g["differs"]]
    text = gyrostand("fleet", "analyze", "--model", MODEL, "--by", "factory", "--db", fleet.db)
    assert "Sveshnikov, section 8.2" in text and "the groups differ" in text


def test_the_report_in_html_and_json(fleet: Fleet) -> None:
    args = ("fleet", "report", "--model", MODEL, "--by", "factory", "--db", fleet.db)
    html_path, json_path = fleet.folder / "out" / "fleet.html", fleet.folder / "fleet.json"
    identified = ("--number", "FL-1", "--laboratory", "Stand lab")
    assert gyrostand(*args, *identified, "-o", str(html_path)) == f"wrote html: {html_path}\n"
    html = html_path.read_text(encoding="utf-8")
    assert "SIMULATION: the instruments and the stand were simulated" in html
    assert html.count("set apart: <b>factory B</b>") == 1 and html.count("set apart: <b>") == 1
    assert "DRAFT" not in html and "<title>Fleet report FL-1: cli compass, by factory<" in html
    gyrostand(*args, "--out", str(json_path), "--laboratory", "Stand lab")  # no number
    document = json.loads(json_path.read_text(encoding="utf-8"))
    assert document["schema"] == "gyrostand.fleet-report/1" and document["draft"] is True
    assert document["missing"] == ["report number"]
    assert document["simulated_campaigns"] == [1, 2, 3, 4, 5, 6]
    assert document["parameters"] == analysis(fleet)["parameters"]


def test_the_quick_plan_is_the_papers_trials_on_a_quicker_compass() -> None:
    paper = parse_plan(Path(str(DEMO_PLAN)).read_text(encoding="utf-8"))
    quick = with_tables(paper, QUICK)
    assert quick.trials == paper.trials and quick.campaign.n_obs == paper.campaign.n_obs
    assert quick.bus.simulator.compass.undamped_period_s == 240.0
    assert quick.settle.undamped_period_s == 240.0
    assert "undamped_period_s = 240.0" in quick.text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ("report", "--model", MODEL, "--by", "factory", "-o", "fleet.txt"),
            "--out fleet.txt: the suffix names no fleet report format (.html, .pdf, .json)",
        ),
        (("report", "--model", "nope", "--by", "factory"), "no completed campaign of model 'nope'"),
        (("report", "--model", MODEL, "--by", "Lot!"), "--by 'Lot!' is no label key"),
        (
            ("report", "--model", MODEL, "--by", "lot"),
            f"model {MODEL}: the fleet has 0 groups by lot: at least 2 are needed to compare them "
            "(left out: campaigns 1, 2, 3, 4, 5, 6: no label lot (campaign run/import --tag "
            "lot=...))",
        ),
        (("analyze", "--model", "nope", "--by", "factory"), "no completed campaign of model"),
        (("analyze", "--model", MODEL, "--by", "Lot!"), "--by 'Lot!' is no label key"),
        (
            ("analyze", "--model", MODEL, "--by", "lot"),
            f"model {MODEL}: the fleet has 0 groups by lot: at least 2 are needed",
        ),
        (("simulate", "--shift-group", "D"), "--shift-group 'D' is not among the groups A, B, C"),
        (("simulate", "--groups", "1"), "Invalid value for '--groups'"),
        (("simulate", "--units-per-group", "1"), "Invalid value for '--units-per-group'"),
    ],
)
def test_refusals_are_one_line(fleet: Fleet, args: tuple[str, ...], message: str) -> None:
    result = CliRunner().invoke(app, ["fleet", *args, "--db", fleet.db])
    assert result.exit_code == 2, result.output
    assert result.stderr.startswith("gyrostand: error: ") and message in result.stderr
    assert len(result.stderr.splitlines()) == 1


def test_an_unwritable_report_is_one_line(fleet: Fleet) -> None:
    (fleet.folder / "file").write_text("")
    out = fleet.folder / "file" / "fleet.html"
    result = CliRunner().invoke(
        app,
        ["fleet", "report", "--model", MODEL, "--by", "factory", "--db", fleet.db, "-o", str(out)],
    )
    assert result.exit_code == 2
    *stages, error = result.stderr.splitlines()  # the stage line, then the error
    assert error == f"gyrostand: error: cannot write {out}: {out.parent} is a file"
    assert not [line for line in stages if "error" in line]


def stored_failures(db: Path) -> list[tuple[int, bool | None, bool | None]]:
    """Each campaign's latest analysis run as stored: (campaign, homogeneous, adequate)."""
    with sqlite3.connect(db) as connection:
        rows = connection.execute(
            "SELECT campaign_id, results_json FROM analysis_run WHERE id IN"
            " (SELECT max(id) FROM analysis_run GROUP BY campaign_id) ORDER BY campaign_id"
        ).fetchall()
    return [
        (c, r["cochran"]["homogeneous"], r["adequacy"]["adequate_mean_basis"])
        for c, r in ((c, json.loads(text)) for c, text in rows)
    ]


COCHRAN = "Cochran's test: the trials' variances are not homogeneous"
FISHER = "Fisher's test: the model is not adequate on the trial means"  # the decision basis


def failed(db: Path) -> list[tuple[int, str]]:
    """The failed tests of each campaign's latest run as stored, in words (a test not made,
    None: Fisher's after Cochran's failed, is not failed)."""
    return [
        (c, "; ".join(w for w, ok in ((COCHRAN, homogeneous), (FISHER, adequate)) if ok is False))
        for c, homogeneous, adequate in stored_failures(db)
        if False in (homogeneous, adequate)
    ]


def test_a_unit_whose_own_analysis_failed_a_test_is_named(fleet: Fleet, tmp_path: Path) -> None:
    """The units whose latest run failed Cochran's or Fisher's test stay in the fleet and are
    named, in the text and the JSON, as their stored runs say; a run made to fail Fisher's test
    is added."""
    copy = tmp_path / "lab.sqlite"
    with sqlite3.connect(fleet.folder / "lab.sqlite") as source, sqlite3.connect(copy) as target:
        source.backup(target)  # with what is still in the write-ahead log
    args = ("fleet", "analyze", "--model", MODEL, "--by", "factory", "--db", f"sqlite:///{copy}")

    def named() -> list[tuple[int, str]]:
        document = json.loads(gyrostand(*args, "--json"))
        assert document["n_units"] == 6
        return [(f["campaign_id"], f["checks"]) for f in document["failed_checks"]]

    assert named() == failed(copy)
    passing = next(
        c for c, homogeneous, adequate in stored_failures(copy) if homogeneous and adequate
    )
    with sqlite3.connect(copy) as connection:
        run, text = connection.execute(
            "SELECT id, results_json FROM analysis_run WHERE campaign_id = ? ORDER BY id DESC",
            (passing,),
        ).fetchone()
        results = json.loads(text)
        results["adequacy"]["adequate_mean_basis"] = False
        connection.execute(
            "UPDATE analysis_run SET results_json = ? WHERE id = ?", (json.dumps(results), run)
        )
        (serial,) = connection.execute(
            "SELECT serial FROM instrument JOIN campaign ON campaign.instrument_id = instrument.id"
            " WHERE campaign.id = ?",
            (passing,),
        ).fetchone()
    assert (passing, FISHER) in failed(copy)
    assert named() == failed(copy)
    assert f"its own analysis failed: campaign {passing} (serial {serial}): {FISHER}" in (
        gyrostand(*args)
    )
