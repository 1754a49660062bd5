"""Export of a stored campaign as tables in the import forms' columns (pandas: CSV, Parquet,
Excel), so that every export re-imports (`gyrostand import`, db/io.py). Series and trial
figures come from the analysis's own statistics (Potemkin 1982 eqs 2.1-2.4, analysis/trials.py):
the export and the analysis cannot disagree."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
from sqlalchemy.orm import Session

from gyrostand.analysis.trials import combine_series
from gyrostand.db.io import FORM_COLUMNS, OBS_FIELDS, OBSERVATION_EXTRAS, SERIES_FIELDS
from gyrostand.db.models import Trial
from gyrostand.db.queries import current_trials, load_campaign
from gyrostand.report.stored import applied_conditions, series_summary

EXPORT_FORMATS = ("csv", "parquet", "xlsx")
INTEGER_COLUMNS = ("window_start_ms", "window_end_ms", "frames_used", "frames_lost", "n_obs")


@dataclass(frozen=True)
class CampaignFrames:
    """A campaign as three tables in the import forms' columns."""

    observations: pd.DataFrame
    series: pd.DataFrame
    trials: pd.DataFrame

    def tables(self) -> dict[str, pd.DataFrame]:
        return {"observations": self.observations, "series": self.series, "trials": self.trials}


def _series_stats(trial: Trial) -> dict[int, tuple[float, float, int]]:
    """Mean (eq 2.1), variance (eq 2.2) and N of each series (`report.stored.series_summary`)."""
    summaries = {s.j: series_summary(s) for s in trial.series}
    return {j: (m.mean_deg, m.var_deg2, m.n) for j, m in summaries.items() if m is not None}


def campaign_frames(session: Session, campaign_id: int) -> CampaignFrames:
    """Observations as stored; series and trial figures by the analysis's statistics, or as
    imported for pre-averaged imports. K, A, tau are the applied values. A retried trial is its
    latest attempt (the one the analysis uses)."""
    campaign = load_campaign(session, campaign_id)
    observations, series, trials = [], [], []
    for trial in current_trials(campaign.trials):
        common = {"trial": trial.index} | applied_conditions(trial)
        for s in trial.series:
            series_fields = {name: getattr(s, name) for name in SERIES_FIELDS}
            if s.compensation_shared is not None:  # JSON text in a cell (db/io.py reads it)
                series_fields["compensation_shared"] = json.dumps(
                    s.compensation_shared, sort_keys=True
                )
            observations += [
                {
                    **common,
                    "j": s.j,
                    **{name: getattr(o, name) for name in OBS_FIELDS},
                    **series_fields,
                }
                for o in s.observations
            ]
        stats = _series_stats(trial)
        for j, (mean, var, n) in sorted(stats.items()):
            series.append({**common, "j": j, "mean_deg": mean, "variance_deg2": var, "n_obs": n})
        if trial.summary_delta_mean_deg is not None:
            delta = (trial.summary_delta_mean_deg, trial.summary_delta_var_deg2, trial.summary_n)
        elif 1 in stats and 2 in stats:
            (m1, v1, n1), (m2, v2, n2) = stats[1], stats[2]
            d, var, _, _ = combine_series(m1, v1, n1, m2, v2, n2)  # eqs 2.1-2.3
            delta = (float(d), float(var), n1 if n1 == n2 else None)
        else:
            continue
        trials.append(dict(zip(FORM_COLUMNS["trials"], (*common.values(), *delta), strict=True)))
    frames = []
    for rows, columns in (
        (observations, FORM_COLUMNS["observations"] + OBSERVATION_EXTRAS),
        (series, FORM_COLUMNS["series"]),
        (trials, FORM_COLUMNS["trials"]),
    ):
        frame = pd.DataFrame(rows, columns=list(columns))
        for column in frame.columns:
            if column in INTEGER_COLUMNS:
                frame[column] = frame[column].astype("Int64")
        frames.append(frame)
    return CampaignFrames(*frames)


def export_paths(out: Path, fmt: str) -> dict[str, Path]:
    """Where `export_campaign` writes: for xlsx one workbook (sheets observations, series, trials);
    for csv/parquet `out` holds the observations, `<stem>.series<ext>` and `<stem>.trials<ext>`
    the summaries."""
    if fmt == "xlsx":
        return dict.fromkeys(("observations", "series", "trials"), out)
    return {
        "observations": out,
        "series": out.with_name(f"{out.stem}.series{out.suffix}"),
        "trials": out.with_name(f"{out.stem}.trials{out.suffix}"),
    }


def export_campaign(session: Session, campaign_id: int, fmt: str, out: Path) -> CampaignFrames:
    """Write the campaign's three tables in `fmt` (csv, parquet, xlsx) to `export_paths(out)`."""
    if fmt not in EXPORT_FORMATS:
        raise ValueError(f"unknown export format {fmt!r} (one of {', '.join(EXPORT_FORMATS)})")
    frames = campaign_frames(session, campaign_id)
    tables = frames.tables()
    out.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "xlsx":
        with pd.ExcelWriter(out, engine="openpyxl") as workbook:
            for name, frame in tables.items():
                frame.to_excel(workbook, sheet_name=name, index=False)
        return frames
    for name, path in export_paths(out, fmt).items():
        if fmt == "csv":
            tables[name].to_csv(path, index=False)
        else:
            tables[name].to_parquet(path, index=False)
    return frames
