"""End to end in a real headless browser (Debian's chromium and chromium-driver, driven by
Selenium): open the station, check the small simulated plan, start it with the device under
test and the operator typed in, answer its prompt before trial 1 in the dialog, watch the live
trace grow, stop it, resume it, generate the report; and an analysed campaign's result in a
narrow window. Screenshots of each step are kept in GYROSTAND_STATION_SCREENSHOTS (default: the
test's temporary folder; the paths are printed)."""

import functools
import json
import os
import shutil
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app as cli
from gyrostand.cmd_report import write_campaign_report
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.station.app import create_app
from gyrostand.station.security import Access
from tests.acquisition.harness import plan_text
from tests.cli.test_fleet_commands import TRIALS

from .conftest import write_plan

CHROMIUM = shutil.which("chromium")
DRIVER = shutil.which("chromedriver")
WAIT_S = 60.0
PACED = 'timing = "realtime"\nspeedup = 250.0'  # ~5 s of wall time: time to press stop
PROMPT = """
[[prompt]]
id = "plate"
text = "serial number on the plate?"
kind = "text"
before = 1
"""
LOADED = {"ack_s = 2.0": "ack_s = 20.0", "bus_silence_s = 5.0": "bus_silence_s = 5000.0"}
"""Paced by the wall clock, a busy machine must not look like a stand that does not answer:
timeouts of 20 s of wall time (ack_s is in wall seconds, bus silence in stand seconds)."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def station(tmp_path: Path) -> Iterator[str]:
    """A station on the database tmp_path/db.sqlite (reports in tmp_path/reports), served by
    uvicorn in a thread; its address."""
    import uvicorn

    db = tmp_path / "db.sqlite"
    app = create_app(str(db), open_database(sqlite_url(db)), Access.for_host("127.0.0.1", None),
                     tmp_path / "reports")  # fmt: skip
    port = free_port()
    server = uvicorn.Server(
        uvicorn.Config(app, port=port, log_level="warning", timeout_graceful_shutdown=1)
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        for acquisition in app.state.processes.acquisitions.values():
            if acquisition.running:
                acquisition.process.terminate()
                acquisition.process.wait(30)
        server.should_exit = True
        thread.join(10)


@pytest.fixture
def browser() -> Iterator[object]:
    if CHROMIUM is None or DRIVER is None:
        pytest.skip(
            "no chromium/chromedriver: install Debian's chromium-driver (tools/system-deps)"
        )
    from selenium import webdriver
    from selenium.common.exceptions import WebDriverException
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--window-size=1280,1100", "--disable-gpu"):  # fmt: skip
        options.add_argument(arg)
    try:
        driver = webdriver.Chrome(options=options, service=Service(DRIVER))
    except WebDriverException as exc:
        pytest.skip(f"chromium does not start here: {exc.msg}")
    driver.implicitly_wait(0)
    try:
        yield driver
    finally:
        driver.quit()


def screenshot(browser, tmp_path: Path, name: str) -> None:
    """The page as the operator sees it now, kept (GYROSTAND_STATION_SCREENSHOTS)."""
    folder = Path(os.environ.get("GYROSTAND_STATION_SCREENSHOTS", tmp_path / "screenshots"))
    folder.mkdir(parents=True, exist_ok=True)
    assert browser.save_screenshot(str(folder / f"{name}.png"))
    print(f"station screenshot: {folder / name}.png")


def test_start_watch_stop_resume_report_in_a_browser(station: str, browser, tmp_path: Path):
    from selenium.common.exceptions import NoSuchElementException, StaleElementReferenceException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    reloading = (NoSuchElementException, StaleElementReferenceException)  # after an action
    wait = WebDriverWait(browser, WAIT_S, poll_frequency=0.05, ignored_exceptions=reloading)

    def text(element_id: str) -> str:
        return browser.find_element(By.ID, element_id).text

    def trace_points() -> int:
        return int(text("trace-points") or 0)

    plan = write_plan(tmp_path, bus_extra=PACED)
    plan.write_text(
        functools.reduce(lambda s, kv: s.replace(*kv), LOADED.items(), plan.read_text()) + PROMPT
    )
    browser.get(station + "/campaigns/new")
    browser.find_element(By.NAME, "plan").send_keys(str(plan))
    browser.find_element(By.ID, "check").click()
    wait.until(lambda b: b.find_element(By.ID, "plan-summary").is_displayed())
    assert "2 trials (1 fit, 1 control)" in text("plan-summary")
    serial = browser.find_element(By.NAME, "instrument.serial")
    assert serial.get_attribute("value") == "T-1"  # from the plan
    serial.clear()
    serial.send_keys("GY-7")
    operator = browser.find_element(By.NAME, "campaign.operator")
    operator.clear()
    operator.send_keys("A. Ivanova")
    screenshot(browser, tmp_path, "1-start")
    browser.find_element(By.ID, "start-campaign").click()
    wait.until(lambda b: b.current_url.endswith("/campaigns/1"))
    wait.until(lambda b: b.find_element(By.ID, "prompt").is_displayed())  # pushed: trial 1 waits
    assert browser.execute_script("return document.getElementById('prompt').open") is True
    assert text("prompt-text") == "serial number on the plate?"
    assert text("status").lower() == "waiting for the operator"
    assert (
        "test compass #GY-7, operator A. Ivanova" in browser.find_element(By.TAG_NAME, "main").text
    )
    assert text("process-error") == ""  # nothing answered yet: no error
    screenshot(browser, tmp_path, "2-prompt")
    browser.find_element(By.ID, "prompt-answer").send_keys("<script>GY-7</script>")
    browser.find_element(By.ID, "answer").click()
    wait.until(lambda b: "plate: <script>GY-7</script>" in text("events"))  # shown inert
    wait.until(lambda b: trace_points() >= 1)  # pushed by the stream: the trace grows
    assert int(text("heading-points")) > 0  # the acquisition's live heading trace
    assert not browser.find_element(By.ID, "prompt").is_displayed()
    screenshot(browser, tmp_path, "3-running")
    first = trace_points()
    updates = browser.execute_script("return window.stationUpdates")
    browser.find_element(By.ID, "stop").click()
    wait.until(lambda b: text("status").lower() == "stopped")
    wait.until(lambda b: b.execute_script("return window.stationAcquiring") is False)
    stopped_at = trace_points()
    assert updates >= 2 and stopped_at >= first
    assert "stop" in text("events") and "interrupted" in text("events")
    assert "safe stop requested at the station" in text("status-detail")  # from the events
    assert text("process-error") == ""  # not the stopped process's stderr
    assert text("phase").startswith("stand at rest (stopped)")  # not the last snapshot's phase
    screenshot(browser, tmp_path, "4-stopped")

    browser.find_element(By.ID, "resume").click()
    wait.until(lambda b: trace_points() > stopped_at)  # the resumed run's trace streams on
    wait.until(lambda b: text("status").lower() == "completed")
    assert not browser.find_elements(By.ID, "message")  # no stale "stop requested" line
    assert trace_points() == 12 > stopped_at  # 2 trials x 2 series x N = 3
    assert text("observations") == "12/12"
    assert browser.find_element(By.ID, "progress").get_attribute("value") == "12"

    browser.find_element(By.ID, "report").click()
    wait.until(lambda b: b.find_element(By.ID, "report-stage").text.startswith("writing"))
    screenshot(browser, tmp_path, "5-report-running")
    wait.until(lambda b: not b.find_element(By.ID, "report-progress").is_displayed())
    names = [a.text for a in browser.find_elements(By.CSS_SELECTOR, "#report-links a")]
    assert sorted(names) == ["campaign-1.html", "campaign-1.json"]
    assert (tmp_path / "reports" / "campaign-1.html").is_file()  # `gyrostand report --out`'s
    link = next(a for a in browser.find_elements(By.CSS_SELECTOR, "#report-links a")
                if a.text == "campaign-1.html")  # fmt: skip
    link.click()
    wait.until(lambda b: "/files/campaign-1.html" in b.current_url)
    assert "test compass" in browser.find_element(By.TAG_NAME, "body").text


def test_an_analysed_campaign_in_a_narrow_window(station: str, browser, tmp_path: Path):
    """The result as the report's JSON states it (C and T with intervals, decisions); the
    charts within a phone-wide window."""
    from selenium.webdriver.common.by import By

    text = plan_text(TRIALS, n_obs=4, database=str(tmp_path / "db.sqlite"),
                     raw_dir=str(tmp_path / "raw"))  # fmt: skip
    plan = write_plan(tmp_path, text=text.replace("acquisition_only = true", ""))
    run = CliRunner().invoke(cli, ["campaign", "run", str(plan), "--quiet", "--tag", "factory=K"])
    assert run.exit_code == 0, run.output
    files = write_campaign_report(str(tmp_path / "db.sqlite"), 1, tmp_path / "reports",
                                  ("html", "json"))  # fmt: skip
    report = json.loads(files["json"].read_text())
    c_low, c_high = report["analysis"]["fit"]["confidence_intervals"]["C_gcm2s2"]
    c = report["analysis"]["fit"]["estimates"]["C_gcm2s2"]
    browser.set_window_size(480, 1000)
    browser.get(station + "/campaigns/1")
    result = browser.find_element(By.ID, "result")
    assert result.is_displayed()
    shown = browser.find_element(By.ID, "result-c").text
    assert shown == (
        f"{c / 1e7:.4f} ({c_low / 1e7:.4f} to {c_high / 1e7:.4f}) ×10⁷ g·cm²·s⁻², 95 % confidence"
    )
    assert browser.find_element(By.ID, "result-decision").text == report["conformity"]["verdict"]
    width = browser.execute_script("return document.documentElement.clientWidth")
    right = browser.execute_script(
        "return document.getElementById('trace').getBoundingClientRect().right"
    )
    assert right <= width  # the chart fits the window
    screenshot(browser, tmp_path, "6-result-narrow")
    browser.get(station + "/?q=factory")
    assert browser.find_elements(By.CSS_SELECTOR, "#campaigns a[href='/campaigns/1']")
