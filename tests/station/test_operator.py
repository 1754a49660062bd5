"""The station and an acquisition it did not start (`gyrostand campaign run` in a terminal, in
virtual time): its prompt answered on the page, its safe stop through the database; a campaign
whose process died shown interrupted; plans uploaded and their prompts before the campaign."""

import json
import re
import sqlite3
import subprocess
import sys
from contextlib import closing
from pathlib import Path

from starlette.testclient import TestClient
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.station.app import create_app
from gyrostand.station.security import Access
from tests.acquisition.test_prompts import WAIT_S, rows, until

from .conftest import write_plan

PROMPTS = """
[[prompt]]
id = "plate"
text = "serial number on the plate?"
kind = "text"
before = 1

[[prompt]]
id = "mounted"
text = "compass mounted and powered?"
before = 2
"""
CAMPAIGN_PROMPT = """
[[prompt]]
id = "oil"
text = "fluid topped up?"
before = "campaign"
"""


def csrf(client) -> dict[str, str]:
    return {"csrf": client.access.csrf}


def station(db: Path, reports: Path) -> TestClient:
    access = Access.for_host("127.0.0.1", None, ["testserver"])
    client = TestClient(create_app(str(db), open_database(sqlite_url(db)), access, reports))
    client.access = access  # type: ignore[attr-defined]
    return client


def initial(page: str) -> dict:
    """The state the campaign page starts from (its JSON script)."""
    found = re.search(r'<script id="initial" type="application/json">(.*?)</script>', page, re.S)
    assert found is not None
    return json.loads(found[1])


def prompts_of(db: Path) -> list[str]:
    """The prompt events ([] while the database is being created)."""
    try:
        found = rows(db, "SELECT message FROM event WHERE kind = 'prompt' ORDER BY id")
    except sqlite3.OperationalError:
        return []
    return [m for (m,) in found]


def test_prompt_answered_and_stop_requested_for_a_run_started_elsewhere(tmp_path: Path) -> None:
    plan = write_plan(tmp_path)
    plan.write_text(plan.read_text() + PROMPTS)
    db = tmp_path / "db.sqlite"
    run = subprocess.Popen(
        [sys.executable, "-m", "gyrostand", "campaign", "run", str(plan), "--quiet"],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        until(lambda: db.exists() and prompts_of(db), "the first prompt")
        client = station(db, tmp_path / "reports")
        page = client.get("/campaigns/1").text
        assert '<strong id="status">running</strong>' in page  # its lease is held elsewhere
        assert initial(page)["prompt"] == {
            "id": "plate",
            "text": "serial number on the plate?",
            "kind": "text",
        }
        assert "<td>running</td>" in client.get("/").text
        wrong = client.post("/campaigns/1/answer", data={"prompt": "mounted", "answer": "yes",
                                                          **csrf(client)})  # fmt: skip
        assert "mounted: not asked now" in wrong.text
        empty = client.post("/campaigns/1/answer", data={"prompt": "plate", "answer": " ",
                                                          **csrf(client)})  # fmt: skip
        assert "plate: the answer is empty" in empty.text
        data = {"prompt": "plate", "answer": "<b>GY-7</b>", **csrf(client)}
        assert "prompt plate: answer recorded" in client.post("/campaigns/1/answer", data=data).text
        until(lambda: len(prompts_of(db)) == 2, "the second prompt")
        assert rows(db, "SELECT message FROM event WHERE kind = 'answer'") == [
            ("plate: <b>GY-7</b>",)
        ]
        page = client.get("/campaigns/1").text
        assert "<b>GY-7" not in page and "\\u003cb\\u003eGY-7" in page  # inert
        assert initial(page)["prompt"]["kind"] == "confirm"
        stopped = client.post("/campaigns/1/stop", data=csrf(client))
        assert "stop requested" in stopped.text
        assert run.wait(WAIT_S) == 1
    finally:
        run.kill()
        run.wait()
    assert rows(db, "SELECT status FROM campaign") == [("stopped",)]
    assert rows(db, "SELECT count(*) FROM observation") == [(6,)]  # trial 1, then held
    assert rows(db, "SELECT message FROM event WHERE kind = 'interrupted'") == [
        ("safe stop requested at the station: stand told to stop rocking",)
    ]
    page = client.get("/campaigns/1").text
    assert '<strong id="status">stopped</strong>' in page and initial(page)["prompt"] is None
    late = client.post("/campaigns/1/stop", data=csrf(client))
    assert "is not being acquired: nothing to stop" in late.text
    # resumed from a terminal without one, the trial's prompt answered on the command line
    resume = ["campaign", "resume", "1", "--db", str(db), "--quiet"]
    bad = CliRunner().invoke(app, [*resume, "--answer", "mounted=no"])
    assert bad.exit_code == 2 and "answer yes to confirm" in bad.stderr
    resumed = CliRunner().invoke(app, [*resume, "--answer", "mounted=yes"])
    assert resumed.exit_code == 0, resumed.output
    assert rows(db, "SELECT status FROM campaign") == [("completed",)]
    assert rows(db, "SELECT count(*) FROM observation") == [(12,)]
    assert rows(db, "SELECT message FROM event WHERE kind = 'answer' ORDER BY id") == [
        ("plate: <b>GY-7</b>",),
        ("mounted: yes",),
    ]


def test_a_campaign_whose_process_died_shows_interrupted(client_for) -> None:
    client = client_for()
    db = Path(client.app.state.processes.db)  # the client's copy
    with closing(sqlite3.connect(db)) as conn, conn:
        conn.execute("UPDATE campaign SET status = 'running'")  # as a kill -9 leaves it
    assert '<strong id="status">interrupted</strong>' in client.get("/campaigns/1").text
    listing = client.get("/").text
    assert "<td>interrupted</td>" in listing and "<td>running</td>" not in listing
    body = ""
    with client.stream("GET", "/campaigns/1/stream") as response:
        for line in response.iter_lines():
            body += line + "\n"
            if line == "event: end":
                break
    assert '"status":"interrupted"' in body and '"acquiring":false' in body


def test_plan_upload_is_checked_per_field_and_asks_the_campaign_prompts(
    client_for, tmp_path: Path
) -> None:
    client = client_for()
    plan = write_plan(tmp_path)
    bad = plan.read_text().replace("n_obs = 3", "n_obs = 0")
    files = {"upload": ("bad.toml", bad.encode(), "application/toml")}
    response = client.post("/campaigns", data=csrf(client), files=files)
    assert response.status_code == 400
    cells = re.findall(r"<tr><td>([^<]*)</td><td>([^<]*)</td></tr>", response.text)
    assert cells == [("[campaign] n_obs", "must be &gt;= 2")]
    assert not (tmp_path / "reports" / "plans").exists()  # nothing kept of a bad plan
    files = {"upload": ("p.toml", (plan.read_text() + CAMPAIGN_PROMPT).encode(), "text/plain")}
    checked = client.post("/campaigns", data=csrf(client), files=files)
    assert checked.status_code == 200 and 'id="problems"' not in checked.text  # asked, no error
    assert 'type="checkbox" name="answer-oil" value="yes"' in checked.text
    saved = re.search(r'name="plan" value="([^"]+)"', checked.text)
    assert saved is not None and Path(saved[1]).read_text().endswith(CAMPAIGN_PROMPT)
    asked = client.post("/campaigns", data={"plan": saved[1], "start": "1", **csrf(client)})
    assert asked.status_code == 400
    cells = re.findall(r"<tr><td>([^<]*)</td><td>([^<]*)</td></tr>", asked.text)
    assert cells == [("[[prompt]] oil", "answer yes to confirm (fluid topped up?)")]
    garbled = {"upload": ("x.toml", b"\xff\xfe", "text/plain")}
    text = client.post("/campaigns", data=csrf(client), files=garbled).text
    assert "x.toml is not UTF-8 text" in text
