"""The station's pages, stream and actions through Starlette's TestClient (no browser): what
the database holds is shown, plans are checked per field, the token is required beyond
loopback, cross-site actions are refused and stored text stays text."""

import os
import re
from pathlib import Path

import pytest
from sqlalchemy import create_engine, text

from gyrostand.cmd_report import write_campaign_report
from gyrostand.station.security import TOKEN_COOKIE, is_loopback
from gyrostand.station.state import decimate, read_live

from .conftest import SERIAL, write_plan


def csrf(client) -> dict[str, str]:
    return {"csrf": client.access.csrf}


def test_campaigns_page_lists_and_filters(client_for) -> None:
    client = client_for()
    page = client.get("/").text
    assert 'href="/campaigns/1"' in page and "completed" in page and "not analysed" in page
    assert 'href="/campaigns/1"' not in client.get("/?status=stopped").text
    assert 'href="/campaigns/1"' in client.get("/?q=test+compass").text
    assert 'href="/campaigns/1"' not in client.get("/?q=nobody").text
    assert client.get("/campaigns/9").status_code == 404


def test_campaign_page_and_stream_hold_the_stored_campaign(client_for) -> None:
    client = client_for()
    page = client.get("/campaigns/1").text
    assert '<strong id="status">completed</strong>' in page
    body = ""
    with client.stream("GET", "/campaigns/1/stream") as response:  # "end": nothing acquiring
        assert response.headers["content-type"].startswith("text/event-stream")
        for line in response.iter_lines():
            body += line + "\n"
            if line == "event: end":
                break
    events = re.findall(r"^event: (\w+)$", body, re.M)
    assert events == ["state", "end"]
    assert '"observations":12' in body and '"status":"completed"' in body
    assert body.count('"kind":') >= 1  # the acquisition's events


def test_markup_in_stored_text_is_shown_inert(client_for) -> None:
    client = client_for()
    for path in ("/", "/campaigns/1"):
        page = client.get(path).text
        assert "<script>alert" not in page
    assert "&lt;script&gt;alert(&#39;serial&#39;)&lt;/script&gt;" in client.get("/").text
    assert "\\u003cscript\\u003ealert" in client.get("/campaigns/1").text  # JSON for the script
    with client.stream("GET", "/campaigns/1/stream") as response:
        lines = response.iter_lines()
        assert any(SERIAL in line for line in lines)  # data; the page sets it as text


def test_plan_problems_are_listed_per_field(client_for, tmp_path: Path) -> None:
    client = client_for()
    plan = write_plan(tmp_path, "bad.toml")
    plan.write_text(plan.read_text().replace("n_obs = 3", "n_obs = 0").replace("6.0", "0"))
    response = client.post("/campaigns", data={"plan": str(plan), **csrf(client)})
    assert response.status_code == 400
    rows = re.findall(r"<tr><td>([^<]*)</td><td>([^<]*)</td></tr>", response.text)
    assert ("[campaign] n_obs", "must be &gt;= 2") in rows
    assert ("[[trials]] 1 period_s", "must be &gt; 0") in rows
    missing = client.post("/campaigns", data={"plan": str(tmp_path / "no.toml"), **csrf(client)})
    assert missing.status_code == 400 and "cannot read the file" in missing.text


def test_actions_on_a_campaign_not_acquired_here_say_why(client_for) -> None:
    client = client_for()
    response = client.post("/campaigns/1/stop", data=csrf(client))
    assert response.status_code == 200  # redirected to the campaign page, with the reason
    assert "is not being acquired: nothing to stop" in response.text


def test_beyond_loopback_the_token_is_required(client_for) -> None:
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")
    client = client_for("0.0.0.0", token="s3cret")
    for path in ("/", "/campaigns/1", "/campaigns/1/stream", "/static/station.js"):
        assert client.get(path).status_code == 401, path
    assert client.get("/?token=wrong").status_code == 401
    assert client.get("/", headers={"Authorization": "Bearer s3cret"}).status_code == 200
    first = client.get("/campaigns/1?token=s3cret", follow_redirects=False)
    assert first.status_code == 303 and first.headers["location"] == "/campaigns/1"
    assert "samesite=strict" in first.headers["set-cookie"].lower()
    assert client.cookies.get(TOKEN_COOKIE) == "s3cret"
    assert client.get("/campaigns/1").status_code == 200
    assert client_for("0.0.0.0").access.token  # none given: a new one (printed at start)
    evil = {"Host": "evil.example", "Authorization": "Bearer s3cret"}
    assert client.get("/", headers=evil).status_code == 400  # the Host first, then the token


def test_over_tls_the_token_cookie_is_secure(client_for) -> None:
    client = client_for("0.0.0.0", token="s3cret")
    client.base_url = client.base_url.copy_with(scheme="https")
    first = client.get("/campaigns/1?token=s3cret", follow_redirects=False)
    assert first.status_code == 303 and "secure" in first.headers["set-cookie"].lower()
    plain = client_for("0.0.0.0", token="s3cret")
    assert (
        "secure"
        not in plain.get("/?token=s3cret", follow_redirects=False).headers["set-cookie"].lower()
    )


def test_cross_site_actions_are_refused(client_for) -> None:
    client = client_for()
    evil = {"Origin": "http://evil.example"}
    assert client.post("/campaigns/1/stop", data=csrf(client), headers=evil).status_code == 403
    no_token = client.post("/campaigns/1/stop", data={}, follow_redirects=False)
    assert no_token.status_code == 403 and "token" in no_token.text
    wrong = client.post("/campaigns/1/stop", data={"csrf": "x"}, follow_redirects=False)
    assert wrong.status_code == 403
    site = {"Sec-Fetch-Site": "cross-site"}
    assert client.post("/campaigns/1/resume", data=csrf(client), headers=site).status_code == 403
    same = {"Origin": "http://testserver"}
    ok = client.post("/campaigns/1/stop", data=csrf(client), headers=same, follow_redirects=False)
    assert ok.status_code == 303


def test_sign_off_is_stored_tested_then_checked_by_someone_else(client_for, tmp_path: Path) -> None:
    """... and the report names who signed off (the signatures themselves stay by hand)."""
    client = client_for()

    def sign(role: str, name: str) -> str:
        data = {"role": role, "name": name, **csrf(client)}
        return client.post("/campaigns/1/signoff", data=data).text

    assert "sign &#39;tested by&#39; first" in sign("checked_by", "B. Checker")
    assert "signed" in sign("tested_by", "<b>A. Tester</b>")
    assert "must not be the tester" in sign("checked_by", "<b>a. tester</b>")
    page = sign("checked_by", "B. Checker")
    assert '<span class="signed">&lt;b&gt;A. Tester&lt;/b&gt;</span>' in page
    assert '<span class="signed">B. Checker</span>' in page
    assert "already signed" in sign("tested_by", "C")
    report = write_campaign_report(str(tmp_path / "db.sqlite"), 1, tmp_path / "r", ("html",))
    block = report["html"].read_text().split('<section id="signatures">')[1].split("</section>")[0]
    assert "<td>&lt;b&gt;A. Tester&lt;/b&gt;</td><td></td><td>20" in block  # name, by hand, date
    assert "<td>B. Checker</td>" in block


def test_schema_0007_downgrade_refuses_while_signed(client_for, tmp_path: Path) -> None:
    from alembic import command

    from gyrostand.db.session import alembic_config, sqlite_url

    client = client_for()
    config = alembic_config()
    engine = create_engine(sqlite_url(tmp_path / "db.sqlite"))
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.downgrade(config, "0006")  # nothing signed: the table goes
        assert "sign_off" not in connection.execute(text("SELECT name FROM sqlite_master")).all()
        command.upgrade(config, "head")  # the station reads the current schema
    engine.dispose()
    data = {"role": "tested_by", "name": "A", **csrf(client)}
    assert "signed" in client.post("/campaigns/1/signoff", data=data).text
    with engine.begin() as connection, pytest.raises(RuntimeError, match="1 sign-offs"):
        config.attributes["connection"] = connection
        command.downgrade(config, "0006")
    engine.dispose()


def test_trace_decimation_keeps_extremes() -> None:
    points = [(float(i), float(i % 7)) for i in range(10_000)]
    points[5000] = (5000.0, 99.0)
    kept = decimate(points, 600)
    assert len(kept) <= 600 and (5000.0, 99.0) in kept and kept == sorted(kept)
    assert decimate(points[:10], 600) == points[:10]


def test_live_file_is_read_while_written_and_gone_after_the_run(station_db: Path, tmp_path: Path):
    from gyrostand.acquisition.engine import Phase, Snapshot
    from gyrostand.acquisition.progress import LiveFile
    from gyrostand.db.queries import live_file_of

    assert not list((station_db.parent / "raw").glob("*.live.json"))  # the run deleted it
    path = live_file_of(tmp_path / "campaign-7.blf")
    assert path.name == "campaign-7.live.json" and read_live(path) is None
    live = LiveFile(path, every_s=0.0)
    live.update(Snapshot(1, 2, 2, 3, 5, Phase.OBSERVE, 61_000, (0.5, 0.7), None, 9_000))
    snapshot = read_live(path)
    assert snapshot is not None and snapshot["phase"] == "observing"
    assert snapshot["now_ms"] == 61_000 and snapshot["values_deg"] == [0.5, 0.7]
    live.close()
    assert not path.exists() and read_live(path) is None


def test_live_file_is_rewritten_often_only_while_a_page_watches(tmp_path: Path) -> None:
    from gyrostand.acquisition.engine import Phase, Snapshot
    from gyrostand.acquisition.progress import LiveFile

    def snap(now_ms: int) -> Snapshot:
        return Snapshot(1, 2, 1, 1, 5, Phase.SETTLE, now_ms, (), None, 9_000)

    path = tmp_path / "campaign-7.live.json"
    live = LiveFile(path, every_s=0.0, unwatched_s=3600.0)
    live.update(snap(1000))  # the first one is written: a page's first view shows it
    live.update(snap(2000))  # nobody watches: not rewritten for an hour
    assert read_live(path)["now_ms"] == 1000
    live.watch.touch()  # what the station's update stream does every tick
    assert live.watch.name == "campaign-7.live.watch"
    live.update(snap(3000))
    assert read_live(path)["now_ms"] == 3000
    os.utime(live.watch, (0, 0))  # a watch long ago: none now
    live.update(snap(4000))
    assert read_live(path)["now_ms"] == 3000
    live.close()
    assert list(tmp_path.iterdir()) == []


def test_live_heading_trace_keeps_extremes_of_the_last_20_minutes(tmp_path: Path) -> None:
    import numpy as np

    from gyrostand.acquisition.engine import Phase, Snapshot
    from gyrostand.acquisition.progress import LiveFile
    from gyrostand.frames.batch import Headings

    def batch(t_ms: list[int], deg: list[float], valid: list[int]) -> Headings:
        n = len(t_ms)
        return Headings(np.arange(n), np.array(t_ms), np.array(deg), np.array(valid), np.zeros(n))

    live = LiveFile(tmp_path / "live.json", every_s=0.0, unwatched_s=0.0)
    snap = Snapshot(1, 2, 1, 1, 5, Phase.SETTLE, 0, (), 0.1, 9_000)
    live.headings(batch([1000, 0, 5000, 3000], [3.0, 1.0, 2.0, 99.0], [1, 1, 1, 0]))
    live.update(snap)
    assert read_live(tmp_path / "live.json")["heading_trace"] == [
        [2.0, 1.0],
        [2.0, 3.0],
        [6.0, 2.0],
    ]
    live.headings(batch([2_000_000], [7.0], [1]))  # 20 min later: the early slices are gone
    live.update(snap)
    assert read_live(tmp_path / "live.json")["heading_trace"] == [[2002.0, 7.0]]


def test_station_command_refuses_a_port_in_use_in_one_line(tmp_path: Path) -> None:
    import socket

    from typer.testing import CliRunner

    from gyrostand.cli import app

    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = str(taken.getsockname()[1])
        result = CliRunner().invoke(
            app, ["station", "--db", str(tmp_path / "s.db"), "--port", port]
        )
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "in use" in lines[0]
    assert lines[0].startswith(f"gyrostand: error: cannot listen on 127.0.0.1:{port}: ")
