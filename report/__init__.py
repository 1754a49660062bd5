"""The stand report: the certification document of a campaign, in HTML, PDF, JSON and CSV.

Pure rendering over plain dataclasses (no database, no bus): `report.stored` gathers the
inputs, the CLI (`gyrostand report`) composes.

- `model`: the report's inputs (`ReportInputs`: identification, plan, acquisition, events,
  heading records, signatures);
- `compliance`: limits profiles (`load_profile`; shipped in ``profiles/``: imo-a424, imo-a821,
  iso-22090-1, each limit with its clause, source, verified flag and who verified it at the
  laboratory; the decision rule), `assess` and the overall `Compliance.decision`;
- `build`: `build_report(inputs, analysis, profile, generated_at=...) -> Report`;
- `plots`: the figures as inline SVG; `html`: `render_html(report)`; `pdf`: `write_pdf` (the
  HTML laid out by Typst, templates/report.typ: PDF/A-3a carrying the JSON, CSV and plan);
  `json_doc`: `report_document` / `report_json` (schema gyrostand.report/1); `csv_table`;
- `writer`: `write_report(report, out_dir, formats) -> {format: path}`;
- `stored`: a stored campaign's recorded analysis (with `worst_case.WorstCase`, the forecast's
  worst cases over the shipped profiles' envelopes) into the report; `stored_plan`: its plan;
- `collector_paused`: the cycle collector off while a report is made (the commands).
"""

import atexit
import gc
from collections.abc import Iterator
from contextlib import contextmanager

FORMATS = ("html", "pdf", "json", "csv")  # what `writer.write_report` writes
SHIPPED = "imo-a424"  # the default limits profile (`compliance.load_profile`)
SHIPPED_PROFILES = ("imo-a424", "imo-a821", "iso-22090-1")


@contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cycle collector off while a report is made, back on after it without a
    collection (a command exits with its garbage uncollected; a longer-lived caller collects
    it with its next garbage). A report allocates millions of short-lived objects
    (matplotlib's artists, SQLAlchemy's rows) that set the collector scanning every object
    alive again and again: about 0.4 s of the paper campaign's first report (4 s of CPU),
    against some 10 MB of cyclic garbage (the figures) held meanwhile. At the process's exit
    the collector's last full scan is skipped too (`gc.freeze` when the interpreter shuts
    down, after the exit handlers: 0.2 s; the files are written and closed by then)."""
    atexit.unregister(gc.freeze)  # once per process
    atexit.register(gc.freeze)
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
