"""The operator station's cost to the acquisition: the paper campaign (examples/paper.toml,
simulated stand, virtual time) run by `gyrostand campaign run` with nobody watching and with
the campaign page open in headless Chromium on a `gyrostand station` (separate processes, as in
use), alternating, in one run. Prints ingest frames/s (the raw log's frames over the campaign's
stored start..finish) for both, the cost of the live view, and the page updates/s the browser
received while the campaign ran.

Targets (issue 20): the live view costs <= 10 % of ingest throughput; >= 5 page updates/s.

Run: .venv/bin/python bench/bench_station.py [--pairs 2]"""

from __future__ import annotations

import argparse
import shutil
import socket
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from contextlib import closing
from datetime import datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GYROSTAND = [sys.executable, "-m", "gyrostand"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ingest_rate(db: Path, campaign_id: int) -> float:
    """Frames/s of the campaign: its raw log's frames over its stored start..finish."""
    with closing(sqlite3.connect(db)) as conn:
        started, finished = conn.execute(
            "SELECT started_at, finished_at FROM campaign WHERE id = ?", (campaign_id,)
        ).fetchone()
        frames = conn.execute(
            "SELECT sum(frames) FROM raw_log_segment WHERE campaign_id = ?", (campaign_id,)
        ).fetchone()[0]
    wall = (datetime.fromisoformat(finished) - datetime.fromisoformat(started)).total_seconds()
    return frames / wall


def wait_running(db: Path, campaign_id: int, proc: subprocess.Popen, limit_s: float = 60) -> None:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            with closing(sqlite3.connect(db)) as conn:
                row = conn.execute(
                    "SELECT status FROM campaign WHERE id = ?", (campaign_id,)
                ).fetchone()
            if row is not None and row[0] == "running":
                return
        except sqlite3.OperationalError:  # not created yet
            pass
        time.sleep(0.02)
    raise SystemExit(f"campaign {campaign_id} did not start")


def run(db: Path, campaign_id: int, browser: object | None, port: int) -> tuple[float, float]:
    """One paper campaign (id `campaign_id` in `db`): its ingest frames/s and, with a browser
    on its page, the page updates/s it received (NaN without)."""
    proc = subprocess.Popen(
        [*GYROSTAND, "campaign", "run", str(ROOT / "examples" / "paper.toml"), "--db", str(db),
         "--quiet"],
        stdout=subprocess.DEVNULL,
    )  # fmt: skip
    updates = float("nan")
    if browser is not None:
        wait_running(db, campaign_id, proc)
        browser.get(f"http://127.0.0.1:{port}/campaigns/{campaign_id}")  # type: ignore[attr-defined]
        t0 = time.monotonic()
        proc.wait()
        seen = browser.execute_script("return window.stationUpdates")  # type: ignore[attr-defined]
        updates = seen / (time.monotonic() - t0)
    if proc.wait() != 0:
        raise SystemExit("the paper campaign failed")
    return ingest_rate(db, campaign_id), updates


def chromium() -> object:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or "chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu"):
        options.add_argument(arg)
    return webdriver.Chrome(options=options, service=Service(shutil.which("chromedriver")))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=2, help="campaigns without/with a browser")
    pairs = parser.parse_args().pairs
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "station.sqlite"
        port = free_port()
        station = subprocess.Popen(
            [*GYROSTAND, "station", "--db", str(db), "--port", str(port), "--reports", tmp],
            stderr=subprocess.DEVNULL,
        )
        browser = chromium()
        try:
            alone, watched, updates = [], [], []
            campaign_id = 0
            for _ in range(pairs):
                campaign_id += 1
                alone.append(run(db, campaign_id, None, port)[0])
                campaign_id += 1
                rate, per_s = run(db, campaign_id, browser, port)
                watched.append(rate)
                updates.append(per_s)
        finally:
            browser.quit()  # type: ignore[attr-defined]
            station.terminate()
            station.wait(10)
    a, w = statistics.median(alone), statistics.median(watched)

    def each(values: list[float], digits: int = 0) -> str:
        return ", ".join(f"{v:,.{digits}f}" for v in values)

    print(f"paper campaign, virtual time, {pairs} pairs (median, then each):")
    print(f"  ingest without a browser: {a:,.0f} frames/s ({each(alone)})")
    print(f"  ingest with the campaign page open: {w:,.0f} frames/s ({each(watched)})")
    print(f"  cost of the live view: {100 * (1 - w / a):+.1f} % (target <= 10 %)")
    u = statistics.median(updates)
    print(f"  page updates: {u:.1f} /s (target >= 5; {each(updates, 1)})")


if __name__ == "__main__":
    main()
