"""End to end in a real headless browser (Debian's chromium and chromium-driver, driven by
Selenium): open the station, start the small simulated plan, answer its prompt before trial 1
on the page, watch the live trace grow, stop it, resume it, open the report. The campaign page's
screenshot while it runs is written to GYROSTAND_STATION_SCREENSHOT (default: the test's
temporary folder) and its path printed."""

import functools
import os
import shutil
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from gyrostand.db.session import open_database, sqlite_url
from gyrostand.station.app import create_app
from gyrostand.station.security import Access

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
    """A station on a new database, served by uvicorn in a thread; its address."""
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
    browser.find_element(By.CSS_SELECTOR, "#start button").click()
    wait.until(lambda b: b.current_url.endswith("/campaigns/1"))
    wait.until(lambda b: b.find_element(By.ID, "prompt").is_displayed())  # pushed: trial 1 waits
    assert text("prompt-text") == "serial number on the plate?"
    assert text("phase") in ("waiting for the operator", "-")
    browser.find_element(By.ID, "prompt-answer").send_keys("<script>GY-7</script>")
    browser.find_element(By.ID, "answer").click()
    wait.until(lambda b: "plate: <script>GY-7</script>" in text("events"))  # shown inert
    wait.until(lambda b: trace_points() >= 1)  # pushed by the stream: the trace grows
    assert int(text("heading-points")) > 0  # the acquisition's live heading trace
    # the screenshot while it runs
    screenshot = Path(os.environ.get("GYROSTAND_STATION_SCREENSHOT", tmp_path / "campaign.png"))
    screenshot.parent.mkdir(parents=True, exist_ok=True)
    assert browser.save_screenshot(str(screenshot))
    print(f"campaign page screenshot: {screenshot}")
    first = trace_points()
    updates = browser.execute_script("return window.stationUpdates")
    browser.find_element(By.ID, "stop").click()
    wait.until(lambda b: text("status") == "stopped")
    wait.until(lambda b: b.execute_script("return window.stationAcquiring") is False)
    stopped_at = trace_points()
    assert updates >= 2 and stopped_at >= first
    assert "stop" in text("events") and "interrupted" in text("events")

    browser.find_element(By.ID, "resume").click()
    wait.until(lambda b: trace_points() > stopped_at)  # the resumed run's trace streams on
    wait.until(lambda b: text("status") == "completed")
    assert trace_points() == 12 > stopped_at  # 2 trials x 2 series x N = 3
    assert text("observations") == "12/12"

    browser.find_element(By.ID, "report").click()
    link = wait.until(lambda b: b.find_element(By.CSS_SELECTOR, "#reports a"))
    assert link.text == "campaign-1.html"
    link.click()
    wait.until(lambda b: "/files/campaign-1.html" in b.current_url)
    assert "test compass" in browser.find_element(By.TAG_NAME, "body").text
