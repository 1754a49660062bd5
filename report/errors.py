"""The report's own error: a bad compliance profile, a missing PDF engine, an unwritable file."""

from gyrostand.analysis.errors import AnalysisError


class ReportError(AnalysisError):
    """The report cannot be produced as asked; the message says why in one line."""
