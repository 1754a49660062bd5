"""The PDF of the HTML report, by WeasyPrint (the `pdf` extra), as PDF/A-3b for archiving (ISO
19005-3: fonts embedded, sRGB output intent, XMP metadata). WeasyPrint needs Pango and its fonts
from the system; without them its import fails, and the error says how to install them."""

from pathlib import Path

from gyrostand.report.errors import ReportError

PDF_VARIANT = "pdf/a-3b"  # archival (ISO 19005-3, level B); WeasyPrint writes what it requires

INSTALL_HINT = (
    "PDF output needs WeasyPrint (pip install 'gyrostand[pdf]') and its system libraries "
    "(Debian/Ubuntu: apt-get install libpango-1.0-0 libpangoft2-1.0-0 fonts-dejavu-core)"
)


def write_pdf(html: str, path: Path) -> Path:
    """Render the report's HTML text to a PDF file (ReportError when WeasyPrint cannot run)."""
    try:
        import weasyprint  # heavy, optional: imported only when a PDF is asked for
    except (ImportError, OSError) as exc:  # OSError: a system library failed to load
        raise ReportError(f"{INSTALL_HINT}: {exc}") from None
    weasyprint.HTML(string=html, base_url=str(path.parent)).write_pdf(path, pdf_variant=PDF_VARIANT)
    return path
