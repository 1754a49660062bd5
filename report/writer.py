"""Write a report's files: HTML, PDF, JSON and the trial-table CSV, named after the campaign
and, for any but the default limits profile, the profile (a report against another profile does
not overwrite the default one)."""

import re
from collections.abc import Callable, Iterable
from pathlib import Path

from gyrostand.report import FORMATS, SHIPPED
from gyrostand.report.build import Report
from gyrostand.report.csv_table import trial_table_csv
from gyrostand.report.errors import ReportError
from gyrostand.report.html import render_html
from gyrostand.report.json_doc import report_json
from gyrostand.report.pdf import Attachment, write_pdf


def report_paths(out_dir: Path, campaign_id: int, profile_id: str = SHIPPED) -> dict[str, Path]:
    """Where each format goes: campaign-ID.html/.pdf/.json and campaign-ID-trials.csv for the
    default profile; campaign-ID-PROFILE.html, ... and campaign-ID-PROFILE-trials.csv for
    another (its id, characters a file name cannot carry as '_')."""
    stem = f"campaign-{campaign_id}"
    if profile_id != SHIPPED:
        stem += "-" + re.sub(r"[^A-Za-z0-9._-]", "_", profile_id)
    return {
        "html": out_dir / f"{stem}.html",
        "pdf": out_dir / f"{stem}.pdf",
        "json": out_dir / f"{stem}.json",
        "csv": out_dir / f"{stem}-trials.csv",
    }


def attachments(
    report: Report, document: str, table: str, paths: dict[str, Path]
) -> tuple[Attachment, ...]:
    """The files the PDF carries: the report's JSON, the trial table and the plan as stored."""
    campaign = report.inputs.identification.campaign_id
    return (
        Attachment(paths["json"].name, document, "application/json", "the report as data"),
        Attachment(paths["csv"].name, table, "text/csv", "the trial table"),
        Attachment(
            f"campaign-{campaign}-plan.toml",
            report.inputs.plan.plan_toml,
            "application/toml",
            "the test plan as stored with the campaign",
        ),
    )


def write_report(
    report: Report,
    out_dir: Path,
    formats: Iterable[str] = FORMATS,
    stage: Callable[[str], None] = lambda what: None,
) -> dict[str, Path]:
    """Write the asked formats (the PDF last, so a missing PDF engine leaves the others written);
    returns the paths written, by format. `stage` hears what takes seconds before it starts."""
    wanted = list(dict.fromkeys(formats))
    unknown = [f for f in wanted if f not in FORMATS]
    if unknown:
        raise ReportError(f"unknown report format {unknown[0]!r} (known: {', '.join(FORMATS)})")
    campaign_id, profile_id = report.inputs.identification.campaign_id, report.compliance.profile_id
    paths = report_paths(out_dir, campaign_id, profile_id)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        written: dict[str, Path] = {}
        document = report_json(report) if {"json", "pdf"} & set(wanted) else ""
        table = trial_table_csv(report.trials) if {"csv", "pdf"} & set(wanted) else ""
        if "json" in wanted:
            paths["json"].write_text(document, encoding="utf-8")
            written["json"] = paths["json"]
        if "csv" in wanted:
            paths["csv"].write_text(table, encoding="utf-8")
            written["csv"] = paths["csv"]
        if "html" in wanted or "pdf" in wanted:
            stage("drawing the figures")
            html = render_html(report)
            if "html" in wanted:
                paths["html"].write_text(html, encoding="utf-8")
                written["html"] = paths["html"]
            if "pdf" in wanted:
                stage("laying out the PDF")
                try:
                    written["pdf"] = write_pdf(
                        html,
                        paths["pdf"],
                        attachments(report, document, table, paths),
                        report.generated_at,
                    )
                except ReportError as exc:
                    done = ", ".join(str(p) for p in written.values()) or "nothing"
                    raise ReportError(f"{exc} (written: {done})") from None
    except OSError as exc:
        raise ReportError(f"cannot write the report in {out_dir}: {exc}") from None
    return written
