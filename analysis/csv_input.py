"""Trials from a CSV table in the paper's per-trial form (examples/paper.csv).

Columns: trial, role (fit | control), direction_deg, amplitude_cm, period_s, delta_mean_deg,
delta_var_deg2 (S^2{<delta_i>} of eq 2.3 in deg^2; may be empty for control trials), n_obs (N per
series). Lines starting with '#' are comments.
"""

from pathlib import Path

import pandas as pd

from gyrostand.analysis.errors import AnalysisError, MissingDataError
from gyrostand.analysis.trials import TrialInput

COLUMNS = (
    "trial",
    "role",
    "direction_deg",
    "amplitude_cm",
    "period_s",
    "delta_mean_deg",
    "delta_var_deg2",
    "n_obs",
)


def read_trials_csv(path: str | Path) -> list[TrialInput]:
    """Parse and validate the table; errors name the file, line and column at fault."""
    try:
        frame = pd.read_csv(path, comment="#", skipinitialspace=True, dtype={"role": str})
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        why = " ".join(str(exc).split())  # pandas ends its message with a newline
        raise AnalysisError(f"{path}: cannot read the CSV table ({why})") from exc
    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise MissingDataError(f"{path}: missing column(s) {', '.join(missing)}")
    trials = []
    for row in frame.itertuples(index=False):
        where = f"{path}: trial {row.trial}"
        try:
            numbers = {
                c: float(getattr(row, c))
                for c in ("direction_deg", "amplitude_cm", "period_s", "delta_mean_deg")
            }
            variance = None if pd.isna(row.delta_var_deg2) else float(row.delta_var_deg2)
            n_obs = None if pd.isna(row.n_obs) else float(row.n_obs)
            index = int(row.trial)
        except (TypeError, ValueError) as exc:
            raise AnalysisError(f"{where}: not a number ({exc})") from exc
        if n_obs is not None and not n_obs.is_integer():
            raise AnalysisError(f"{where}: n_obs = {n_obs} is not an integer")
        trials.append(
            TrialInput(
                index=index,
                role=str(row.role).strip(),
                delta_var_deg2=variance,
                n_obs=None if n_obs is None else int(n_obs),
                **numbers,
            )
        )
    if not trials:
        raise MissingDataError(f"{path}: no trials")
    return trials
