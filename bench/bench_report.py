"""The stand report of the paper campaign (examples/paper.toml, run on the simulated stand in
virtual time): CPU and wall seconds per stage of `gyrostand report` (imports, analysis with
the reading's signal analysis, HTML with the figures, PDF layout and writing) and the pages.

Target (issue 17): the report "in seconds" (it took 18 s of CPU, 52 s wall on a loaded machine).

Run: .venv/bin/python bench/bench_report.py"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

STAGES = """
import sys, time
from pathlib import Path
t = [(time.process_time(), time.perf_counter())]
from gyrostand.cmd_data import open_db
from gyrostand.report.compliance import load_profile
from gyrostand.report.html import render_html
from gyrostand.report.pdf import write_pdf
from gyrostand.report.stored import campaign_report
t.append((time.process_time(), time.perf_counter()))
sessions = open_db(sys.argv[1], must_exist=True)
with sessions.begin() as session:
    report = campaign_report(
        session, 1, database=sys.argv[1], profile=load_profile(), generated_at="bench"
    )
t.append((time.process_time(), time.perf_counter()))
html = render_html(report)
t.append((time.process_time(), time.perf_counter()))
write_pdf(html, Path(sys.argv[2]))
t.append((time.process_time(), time.perf_counter()))
names = ("imports", "analysis", "html + figures", "pdf")
for name, a, b in zip(names, t, t[1:]):
    print(f"  {name:<16} CPU {b[0] - a[0]:6.2f} s   wall {b[1] - a[1]:6.2f} s")
print(f"  {'total':<16} CPU {t[-1][0] - t[0][0]:6.2f} s   wall {t[-1][1] - t[0][1]:6.2f} s")
"""


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="gyrostand-bench-report-") as tmp:
        folder = Path(tmp)
        db = folder / "paper.sqlite"
        gyrostand = [sys.executable, "-m", "gyrostand"]
        start = time.perf_counter()
        subprocess.run(
            [*gyrostand, "campaign", "run", str(ROOT / "examples" / "paper.toml"), "--db", str(db)]
            + ["--quiet"],
            check=True,
            cwd=folder,
        )
        print(f"paper campaign acquired in {time.perf_counter() - start:.1f} s (virtual time)")
        pdf = folder / "report.pdf"
        print("gyrostand report, by stage (a fresh process, as the command runs):")
        subprocess.run([sys.executable, "-c", STAGES, str(db), str(pdf)], check=True, cwd=folder)
        info = subprocess.run(["pdfinfo", str(pdf)], capture_output=True, text=True, check=True)
        pages = next(line.split()[-1] for line in info.stdout.splitlines() if "Pages" in line)
        print(f"  {pages} pages, {pdf.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
