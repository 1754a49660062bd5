"""The trial table (section 4) as CSV: one row per trial in the paper's form, plain units."""

import csv
import io
from dataclasses import fields

from gyrostand.report.build import TrialRow

COLUMNS = tuple(f.name for f in fields(TrialRow))


def trial_table_csv(rows: tuple[TrialRow, ...]) -> str:
    """Columns: the `TrialRow` fields (deg, cm, s, rad/s, deg^2); empty cells where a value is
    absent (e.g. the variance of a control trial given pre-averaged); floats written with repr
    precision so the CSV reproduces the report's numbers exactly."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow(
            [
                "" if v is None else repr(float(v)) if isinstance(v, float) else v
                for v in (getattr(row, c) for c in COLUMNS)
            ]
        )
    return buffer.getvalue()
