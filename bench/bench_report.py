"""The stand report of the paper campaign (examples/paper.toml, run on the simulated stand in
virtual time): CPU and wall seconds per stage of `gyrostand report` in a fresh process (imports,
the analysis with the reading's signal analysis, JSON and CSV, the figures with the HTML, the
PDF laid out by Typst), then the command itself and the PDF's pages.

Target (issue 33): <= 3 s of CPU for all formats. Not reached: on a machine shared with other
jobs the stages took imports 3.4, analysis 1.8, figures + HTML 2.5 and figures + PDF 3.4 s of
CPU (the PDF's own layout by Typst is about 0.6 s; WeasyPrint's took about 7 s for 21 pages).
What is left is the recomputed analysis (scipy.stats and scipy.signal alone are about 1.5 s to
import), the plan's pydantic models (about 0.6 s to import) and 13 matplotlib figures. Three
runs (the machine's noise is large when other jobs share it), then the median per stage.

Run: .venv/bin/python bench/bench_report.py"""

from __future__ import annotations

import resource
import statistics
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
from gyrostand.report.stored import campaign_report
from gyrostand.report.writer import write_report
t.append((time.process_time(), time.perf_counter()))
sessions = open_db(sys.argv[1], must_exist=True)
report = campaign_report(
    sessions, 1, database=sys.argv[1], profile=load_profile(), generated_at="bench"
)
t.append((time.process_time(), time.perf_counter()))
out = Path(sys.argv[2])
write_report(report, out, ("json", "csv"))
t.append((time.process_time(), time.perf_counter()))
write_report(report, out, ("html",))
t.append((time.process_time(), time.perf_counter()))
write_report(report, out, ("pdf",))
t.append((time.process_time(), time.perf_counter()))
print(*(f"{b[0] - a[0]:.3f},{b[1] - a[1]:.3f}" for a, b in zip(t, t[1:])))
"""
NAMES = ("imports", "analysis", "json + csv", "figures + html", "figures + pdf", "total")
RUNS = 3


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
        runs = []
        for _ in range(RUNS):
            out = subprocess.run(
                [sys.executable, "-c", STAGES, str(db), str(folder / "stages")],
                check=True,
                cwd=folder,
                capture_output=True,
                text=True,
            ).stdout.split()
            stages = [tuple(map(float, pair.split(","))) for pair in out]
            runs.append([*stages, tuple(map(sum, zip(*stages, strict=True)))])
        print(f"gyrostand report, by stage, {RUNS} fresh processes (CPU s / wall s, the median):")
        print("  (the html and the pdf stages each draw the figures: the command draws them once)")
        for i, name in enumerate(NAMES):
            cells = "  ".join(f"{run[i][0]:5.2f}/{run[i][1]:5.2f}" for run in runs)
            cpu, wall = (statistics.median(run[i][k] for run in runs) for k in (0, 1))
            print(f"  {name:<15} {cells}   median CPU {cpu:5.2f} s, wall {wall:5.2f} s")
        for formats in ("html,pdf,json,csv", "pdf"):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            subprocess.run(
                [*gyrostand, "report", "1", "--db", str(db), "--out", str(folder), "-f", formats],
                check=True,
                cwd=folder,
                capture_output=True,
            )
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
            print(
                f"  `gyrostand report -f {formats}` as a command: CPU {cpu:.2f} s, "
                f"wall {time.perf_counter() - start:.2f} s"
            )
        pdf = folder / "campaign-1.pdf"
        info = subprocess.run(["pdfinfo", str(pdf)], capture_output=True, text=True, check=True)
        pages = next(line.split()[-1] for line in info.stdout.splitlines() if "Pages" in line)
        print(f"  {pages} pages, {pdf.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
