"""The campaign page shows what the database holds (TestClient, no browser): why a run stopped
from its stored events, not its process's last stderr line; during a prompt no series of the
previous trial as current; the latest analysis's C and T with intervals and decisions, the
report's decision and every report file; reports generated without blocking; the start form's
plan summary, device under test and operator; the list's filter searching labels."""

import json
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

from gyrostand.db.queries import live_file_of
from gyrostand.plan.model import load_plan, parse_plan
from gyrostand.station.operator import unit_values, with_unit
from gyrostand.station.processes import Acquisition

from .conftest import write_plan
from .test_operator import PROMPTS, csrf, initial

RESULTS = {
    "q": 0.05,
    "fit": {
        "estimates": {"C_gcm2s2": 7.12e7, "T_s": 0.563},
        "confidence_intervals": {"C_gcm2s2": [6.9e7, 7.34e7], "T_s": [0.541, 0.585]},
    },
    "cochran": {"homogeneous": True},
    "adequacy": {"adequate_mean_basis": False},
}


def sql(client, statement: str, *args: object) -> list[tuple]:
    """A statement on the client's copy of the station database."""
    with closing(sqlite3.connect(client.app.state.processes.db)) as conn, conn:
        return conn.execute(statement, args).fetchall()


def event(client, kind: str, message: str) -> None:
    sql(client, "INSERT INTO event (campaign_id, wall_time, kind, severity, message) VALUES "
                "(1, '2026-01-01 00:00:00', ?, 'info', ?)", kind, message)  # fmt: skip


def ended(stderr: str, code: int) -> Acquisition:
    """A process that wrote `stderr` and exited with `code`, as the station keeps one."""
    import tempfile

    err = tempfile.TemporaryFile()  # noqa: SIM115
    script = f"import sys; sys.stderr.write({stderr!r}); sys.exit({code})"
    process = subprocess.Popen([sys.executable, "-c", script], stderr=err)
    process.wait(30)
    return Acquisition(process, err, "campaign run")


def test_a_stopped_run_says_why_from_its_events_not_its_stderr(client_for) -> None:
    client = client_for()
    sql(client, "UPDATE campaign SET status = 'stopped'")
    event(client, "interrupted", "safe stop requested at the station: stand told to stop rocking")
    # a stopped run exits 1; its stderr's last line is the wrapped end of a prompt's question
    wrapped = "before the next trial: compass mounted and powered? (answer\nyes at the station)\n"
    client.app.state.processes.acquisitions[1] = ended(wrapped, 1)
    state = initial(client.get("/campaigns/1").text)
    assert state["status"] == "stopped" and state["process_error"] is None
    assert state["reason"] == "safe stop requested at the station: stand told to stop rocking"
    # a run that ended without storing its outcome: its error line, for the operator
    sql(client, "UPDATE campaign SET status = 'running'")
    client.app.state.processes.acquisitions[1] = ended(
        "gyrostand: error: the CAN bus went away (bus off)\n", 1
    )
    state = initial(client.get("/campaigns/1").text)
    assert state["status"] == "interrupted" and state["reason"] is None
    assert state["process_error"] == "the CAN bus went away (bus off)"


def test_during_a_prompt_the_ended_series_is_not_shown_as_current(client_for) -> None:
    client = client_for()
    sql(client, "UPDATE campaign SET plan_toml = plan_toml || ?", PROMPTS)
    event(client, "prompt", "mounted: compass mounted?")
    (raw,) = sql(client, "SELECT path FROM raw_log_segment ORDER BY seq DESC LIMIT 1")[0]
    live = live_file_of(raw)
    snapshot = {"trial": 2, "n_trials": 2, "j": 2, "k": 3, "n_obs": 3, "now_ms": 634000,
                "phase": "waiting for the operator", "values_deg": [120.4, 120.41, 120.42],
                "settle_spread_deg": None, "remaining_ms": 114000, "wall_time": 0.0,
                "heading_trace": []}  # fmt: skip
    live.write_text(json.dumps(snapshot))
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    client.app.state.processes.acquisitions[1] = Acquisition(sleeper, None, "campaign run")  # type: ignore[arg-type]
    try:
        state = initial(client.get("/campaigns/1").text)
    finally:
        sleeper.kill()
        sleeper.wait()
        live.unlink()
    assert state["acquiring"] and state["prompt"]["id"] == "mounted"
    assert state["live"] is None  # trial 1's ended series, not the current one


def test_the_latest_analysis_and_every_report_are_on_the_campaign_page(client_for) -> None:
    client = client_for()
    reports = Path(client.app.state.processes.db).parent / "reports"
    reports.mkdir()
    for name in ("campaign-1.html", "campaign-1-trials.csv", "campaign-1.iso-22090-1.html",
                 "campaign-12.html", "campaign-1.html.tmp"):  # fmt: skip
        (reports / name).write_text("a report")
    (reports / "campaign-1.json").write_text(json.dumps({"conformity": {"verdict": "FAIL"}}))
    before = initial(client.get("/campaigns/1").text)
    assert before["result"] is None and before["decision"] == "FAIL"
    assert sorted(before["reports"]) == [
        "campaign-1-trials.csv",
        "campaign-1.html",
        "campaign-1.iso-22090-1.html",
        "campaign-1.json",
    ]
    sql(client, "INSERT INTO analysis_run (campaign_id, inputs_hash, results_json, "
                "software_version, created_at) VALUES (1, ?, ?, 'test', '2026-01-01 00:00:00')",
        "0" * 64, json.dumps(RESULTS))  # fmt: skip
    result = initial(client.get("/campaigns/1").text)["result"]
    assert result["c_gcm2s2"] == {"value": 7.12e7, "low": 6.9e7, "high": 7.34e7}
    assert result["t_s"] == {"value": 0.563, "low": 0.541, "high": 0.585}
    assert result["confidence"] == 0.95
    assert (result["homogeneous"], result["adequate"]) == (True, False)
    assert result["verdict"] == "homogeneous yes, adequate on trial means no"
    assert client.get("/campaigns/1/files/campaign-1.iso-22090-1.html").text == "a report"
    assert client.get("/campaigns/1/files/campaign-12.html").status_code == 404


FAKE_REPORT = """
import sys, time
from pathlib import Path
out = Path(sys.argv[sys.argv.index("--out") + 1])
print("report: analysing it", file=sys.stderr, flush=True)
go = out / "go"
deadline = time.monotonic() + 30
while not go.exists() and time.monotonic() < deadline:
    time.sleep(0.02)
(out / "campaign-1.html").write_text("written")
print("wrote html: campaign-1.html", file=sys.stderr)
"""


def test_a_report_is_generated_without_blocking_the_page(client_for, tmp_path: Path) -> None:
    client = client_for()
    script = tmp_path / "fake_report.py"  # `gyrostand report`'s stages, until told to finish
    script.write_text(FAKE_REPORT)
    processes = client.app.state.processes
    processes.command = (sys.executable, str(script))
    reports = Path(processes.db).parent / "reports"
    reports.mkdir()
    started = time.monotonic()
    answer = client.post("/campaigns/1/report", data={"formats": "html+pdf", **csrf(client)})
    assert answer.status_code == 200 and time.monotonic() - started < 20  # not its 30 s
    args = processes.reports[1].process.process.args
    assert args[args.index("--out") + 1] == str(reports)  # where `gyrostand report --out` goes
    assert args[args.index("--format") + 1] == "html,pdf,json"
    while "analysing" not in processes.reports[1].progress()["stage"]:
        time.sleep(0.02)
    state = initial(client.get("/campaigns/1").text)  # the page as it is now, not at the POST
    assert state["report"]["running"] and state["report"]["stage"] == "analysing it"
    assert '<option value="html+pdf" selected>' in answer.text  # the format chosen, kept
    (reports / "go").touch()
    processes.reports[1].process.process.wait(30)
    state = initial(client.get("/campaigns/1").text)
    assert not state["report"]["running"] and state["report"]["error"] is None
    assert state["reports"] == ["campaign-1.html"]


def test_the_start_form_shows_the_plan_then_takes_device_and_operator(
    client_for, tmp_path: Path
) -> None:
    client = client_for()
    plan = write_plan(tmp_path)
    checked = client.post("/campaigns", data={"plan": str(plan), **csrf(client)})
    assert checked.status_code == 200 and 'id="plan-summary"' in checked.text
    assert "2 trials (1 fit, 1 control)" in checked.text and "N = 3" in checked.text
    assert 'name="instrument.serial" value="T-1"' in checked.text  # pre-filled from the plan
    assert 'name="campaign.operator" value="test"' in checked.text
    empty = client.post("/campaigns", data={"plan": str(plan), "start": "1",
                                             "campaign.operator": " ", **csrf(client)})  # fmt: skip
    assert empty.status_code == 400 and "must not be empty" in empty.text
    loaded = load_plan(plan)
    form = {"instrument.serial": 'GY "7"', "campaign.operator": "Ivanova"}
    text, problems = with_unit(loaded, unit_values(loaded, form))
    edited = parse_plan(text)
    assert problems == [] and edited.instrument.serial == 'GY "7"'
    assert edited.campaign.operator == "Ivanova" and edited.instrument.model == "test compass"
    changed = [
        (a, b)
        for a, b in zip(plan.read_text().splitlines(), text.splitlines(), strict=True)
        if a != b
    ]
    assert changed == [('operator = "test"', 'operator = "Ivanova"'),
                       ('serial = "T-1"', 'serial = "GY \\"7\\""')]  # fmt: skip
    assert with_unit(loaded, unit_values(loaded, {}))[0] == loaded.text  # as written


def test_the_list_filter_searches_labels(client_for) -> None:
    client = client_for()
    sql(
        client,
        "INSERT INTO campaign_label (campaign_id, key, value) VALUES (1, 'factory', 'Kaliningrad')",
    )
    assert '<a href="/campaigns/1">' in client.get("/?q=kalin").text
    assert '<a href="/campaigns/1">' in client.get("/?q=FACTORY").text
    assert "no campaign" in client.get("/?q=Murmansk").text
