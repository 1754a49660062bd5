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
- `writer`: `write_report(report, out_dir, formats) -> {format: path}`.
"""

FORMATS = ("html", "pdf", "json", "csv")  # what `writer.write_report` writes
SHIPPED = "imo-a424"  # the default limits profile (`compliance.load_profile`)
SHIPPED_PROFILES = ("imo-a424", "imo-a821", "iso-22090-1")
