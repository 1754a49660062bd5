"""The stand report of the paper campaign (examples/paper.toml, run on the simulated stand in
virtual time): CPU and wall seconds per stage of `gyrostand report` in a fresh process (imports,
the analysis with the reading's signal analysis and the recorded run, JSON and CSV, the figures
with the HTML, the PDF laid out by Typst from that HTML), then the command itself, each against
the target of issue 33 (OK or NOT), and the PDF's pages.

Target (issue 33): <= 3 s of CPU for all formats; the fleet report <= 2 s. Not reached. The
report now rebuilds the analysis the campaign recorded when it completed (`campaign run` records
it; `report.stored.stored_analysis`: the run whose inputs hash and software version match,
typed round trip of the analysis, the signal section and the heading traces), so it neither
fits, nor analyses the reading, nor decodes the raw log, and imports no scipy.stats,
scipy.signal or scipy.integrate (t quantiles by scipy.special). Measured with the machine
shared by about six sessions (load 10-30; contention inflates CPU time too), CPU s:
- before: imports 4.2-5.8, analysis 2.2-2.4, JSON + CSV 0.1, figures + HTML 2.7-3.8,
  PDF 1.1-1.2: 11.4-12.7 s;
- now (load 25-30, wall 12 times the CPU): imports 3.0-3.5, analysis (rebuilt) 0.9-1.05,
  JSON + CSV 0.3 (scipy.special's import for the t quantiles lands here), figures + HTML
  2.8-3.1, PDF 1.0-1.2: 8.1-9.1 s, median 8.4; `gyrostand report` as a command 9.8 s.
What is left, by size: the imports (the plan's pydantic models 0.7 s, matplotlib 0.8 s,
SQLAlchemy's ORM and the models 0.6 s, alembic through db.session's open_db 0.3-0.9 s); the 13
figures (0.2 s each: matplotlib's tick and text layout, SVG text as paths; text as SVG text
saved about 10 %); the envelope's worst case of the compliance section (a Powell search and
scipy.optimize's import, about 0.5 s); the campaign read twice (0.3 s each). The fleet report
(6 units) took 5-7 s of CPU: it analyses the fleet with scipy.stats and imports the stand
report's modules to tell simulated campaigns. Three runs, then the median per stage.

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
from gyrostand.report.csv_table import trial_table_csv
from gyrostand.report.html import render_html
from gyrostand.report.json_doc import report_json
from gyrostand.report.pdf import write_pdf
from gyrostand.report.writer import attachments, report_paths
t.append((time.process_time(), time.perf_counter()))
sessions = open_db(sys.argv[1], must_exist=True)
report = campaign_report(
    sessions, 1, database=sys.argv[1], profile=load_profile(), generated_at="bench"
)
t.append((time.process_time(), time.perf_counter()))
paths = report_paths(Path(sys.argv[2]), 1)
paths["json"].parent.mkdir(exist_ok=True)
document, table = report_json(report), trial_table_csv(report.trials)
paths["json"].write_text(document)
paths["csv"].write_text(table)
t.append((time.process_time(), time.perf_counter()))
html = render_html(report)
paths["html"].write_text(html)
t.append((time.process_time(), time.perf_counter()))
write_pdf(html, paths["pdf"], attachments(report, document, table, paths), report.generated_at)
t.append((time.process_time(), time.perf_counter()))
print(*(f"{b[0] - a[0]:.3f},{b[1] - a[1]:.3f}" for a, b in zip(t, t[1:])))
"""
NAMES = ("imports", "analysis", "json + csv", "figures + html", "pdf (Typst)", "total")
TARGET_CPU_S = 3.0  # issue 33: the paper campaign's report, all formats, in a fresh process
RUNS = 3
FLEET_TARGET_CPU_S = 2.0  # issue 33: the fleet report
FLEET_MODEL = "two-rotor marine gyrocompass"  # the simulated fleet's (the demo plan's)


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
        for i, name in enumerate(NAMES):
            cells = "  ".join(f"{run[i][0]:5.2f}/{run[i][1]:5.2f}" for run in runs)
            cpu, wall = (statistics.median(run[i][k] for run in runs) for k in (0, 1))
            print(f"  {name:<15} {cells}   median CPU {cpu:5.2f} s, wall {wall:5.2f} s")
        total = statistics.median(run[-1][0] for run in runs)
        verdict = "OK" if total <= TARGET_CPU_S else "NOT"
        print(f"  all formats: median CPU {total:.2f} s: {verdict} (target <= {TARGET_CPU_S:g} s)")
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
            verdict = "OK" if cpu <= TARGET_CPU_S else "NOT"
            print(
                f"  `gyrostand report -f {formats}` as a command: CPU {cpu:.2f} s, "
                f"wall {time.perf_counter() - start:.2f} s: {verdict} (target <= "
                f"{TARGET_CPU_S:g} s CPU)"
            )
        pdf = folder / "campaign-1.pdf"
        info = subprocess.run(["pdfinfo", str(pdf)], capture_output=True, text=True, check=True)
        pages = next(line.split()[-1] for line in info.stdout.splitlines() if "Pages" in line)
        print(f"  {pages} pages, {pdf.stat().st_size / 1e6:.2f} MB")
        fleet(folder)


def command_cpu(*args: str, cwd: Path) -> tuple[float, float]:
    """CPU and wall seconds of one gyrostand command in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "gyrostand", *args], check=True, cwd=cwd)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return cpu, time.perf_counter() - start


def fleet(folder: Path) -> None:
    """The fleet report of a simulated fleet (`fleet simulate`: 2 factories x 3 units, the
    quick plan) in each format, against its target."""
    db = str(folder / "fleet.sqlite")
    subprocess.run(
        [sys.executable, "-m", "gyrostand", "fleet", "simulate", "--db", db]
        + ["--groups", "2", "--units-per-group", "3"],
        check=True,
        cwd=folder,
        capture_output=True,
    )
    for suffix in ("json", "html", "pdf"):
        out = str(folder / f"fleet.{suffix}")
        cpu, wall = command_cpu(
            "fleet",
            "report",
            "--model",
            FLEET_MODEL,
            "--by",
            "factory",
            "--db",
            db,
            "-o",
            out,
            cwd=folder,
        )
        verdict = "OK" if cpu <= FLEET_TARGET_CPU_S else "NOT"
        print(
            f"  `gyrostand fleet report -o fleet.{suffix}` (6 units): CPU {cpu:.2f} s, wall "
            f"{wall:.2f} s: {verdict} (target <= {FLEET_TARGET_CPU_S:g} s CPU)"
        )


if __name__ == "__main__":
    main()
