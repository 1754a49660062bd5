"""Import of historical manual measurements (pandas: CSV, Parquet, Excel); report/export.py
writes the same forms back.

Three file forms, detected from the columns (extra per-observation columns are optional):

- observations: trial, role, direction_deg, amplitude_cm, period_s, j, k, value_deg
  [, window_start_ms, window_end_ms, frames_used, frames_lost, flags, compensation_deg,
  compensation_se_deg, compensation_shared]  (a compensated series: the transient subtracted
  from each raw value_deg, the SE of the compensation and, as JSON, its share in the period and
  damping error that all the campaign's compensations share (`analysis.gls.SharedError`), each
  the same on all the series' rows)
- series:       trial, role, direction_deg, amplitude_cm, period_s, j, mean_deg, variance_deg2,
  n_obs
- trials (the paper's table, seed 000 example): trial, role, direction_deg, amplitude_cm,
  period_s, delta_mean_deg, delta_var_deg2, n_obs  (delta_var_deg2 may be empty for control
  trials; variances in deg^2, not the paper's 1e-4 deg^2)

Every row is validated and every problem is reported with its line (CSV) or row (Excel,
Parquet); nothing is written unless the whole file is valid, and then in one transaction.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.models import TRIAL_ROLES, Campaign, Event, Observation, Series, Trial
from gyrostand.db.queries import CampaignHeader, new_campaign
from gyrostand.db.session import writer

COMMON_COLUMNS = ("trial", "role", "direction_deg", "amplitude_cm", "period_s")
FORM_COLUMNS = {
    "observations": COMMON_COLUMNS + ("j", "k", "value_deg"),
    "series": COMMON_COLUMNS + ("j", "mean_deg", "variance_deg2", "n_obs"),
    "trials": COMMON_COLUMNS + ("delta_mean_deg", "delta_var_deg2", "n_obs"),
}
OBS_FIELDS = (
    "k",
    "value_deg",
    "window_start_ms",
    "window_end_ms",
    "frames_used",
    "frames_lost",
    "flags",
    "compensation_deg",  # the fitted transient subtracted from value_deg (compensated series)
)
# per series, repeated on each of its observation rows
SERIES_FIELDS = ("compensation_se_deg", "compensation_shared")
SHARED_KEYS = {"sensitivity", "covariance", "record_ms", "at_ms", "previous_deg2", "earlier_deg2"}
EARLIER_KEYS = {"trial", "j", "deg2"}  # one entry of earlier_deg2: the series it names, the value
OBSERVATION_EXTRAS = OBS_FIELDS[2:] + SERIES_FIELDS  # optional columns of the observations form
MAX_REPORTED = 10

# seed 000 example: known constants B of the two-rotor gyrocompass and the site
SEED_000_METADATA: dict[str, Any] = {
    "model": "two-rotor gyrocompass (example of Potemkin 1982)",
    "serial": "Potemkin-1982",
    "lp_gcm2s2": 6.57e6,
    "h1_gcm2s": 1.55e8,
    "latitude_deg": 46.5,
    "earth_rate_rad_s": 7.3e-5,
    "gravity_cm_s2": 981.0,
}


class ImportFileError(ValueError):
    """The file cannot be imported; `problems` lists each one with its line or row."""

    def __init__(self, path: Path, problems: list[str]) -> None:
        self.path = path
        self.problems = problems
        shown = "; ".join(problems[:MAX_REPORTED])
        more = len(problems) - MAX_REPORTED
        tail = f"; ... and {more} more" if more > 0 else ""
        count = f"{len(problems)} problems: " if len(problems) > 1 else ""
        super().__init__(f"{path}: {count}{shown}{tail}")


class MetadataError(ValueError):
    """Campaign metadata (instrument, site, operator) missing or out of range."""


# ---------------------------------------------------------------- reading files into raw rows


@dataclass(frozen=True)
class RawRow:
    where: str  # "line 7" (CSV) or "row 7" (Excel sheet row, Parquet record)
    cells: dict[str, Any]


def _read_csv(path: Path) -> tuple[list[str], list[RawRow], list[str]]:
    # The csv module rather than pandas.read_csv: it gives the physical line of every record,
    # which the error messages need, and lets '#' lines be skipped without losing that count.
    problems: list[str] = []
    header: list[str] | None = None
    rows: list[RawRow] = []
    with path.open(newline="", encoding="utf-8-sig") as handle:
        reader = csv.reader(handle)
        for record in reader:
            if not any(cell.strip() for cell in record) or record[0].lstrip().startswith("#"):
                continue
            where = f"line {reader.line_num}"
            if header is None:
                header = [cell.strip() for cell in record]
            elif len(record) != len(header):
                problems.append(f"{where}: {len(record)} fields, the header has {len(header)}")
            else:
                rows.append(RawRow(where, dict(zip(header, record, strict=True))))
    return header or [], rows, problems


def _read_excel(path: Path) -> tuple[list[str], list[RawRow], list[str]]:
    """The first sheet; rows are numbered as the spreadsheet shows them."""
    sheet = pd.read_excel(path, sheet_name=0, header=None, dtype=object)
    header: list[str] | None = None
    rows: list[RawRow] = []
    for number, values in zip(sheet.index, sheet.itertuples(index=False), strict=True):
        cells = list(values)
        if all(_blank(cell) for cell in cells) or str(cells[0]).lstrip().startswith("#"):
            continue
        if header is None:
            header = ["" if _blank(cell) else str(cell).strip() for cell in cells]
        else:
            rows.append(RawRow(f"row {number + 1}", dict(zip(header, cells, strict=True))))
    return [name for name in header or [] if name], rows, []


def _read_parquet(path: Path) -> tuple[list[str], list[RawRow], list[str]]:
    table = pd.read_parquet(path)
    rows = [
        RawRow(f"row {number}", record)
        for number, record in enumerate(table.to_dict(orient="records"), start=1)
    ]
    return [str(c) for c in table.columns], rows, []


READERS: dict[str, Callable[[Path], tuple[list[str], list[RawRow], list[str]]]] = {
    ".csv": _read_csv,
    ".xlsx": _read_excel,
    ".parquet": _read_parquet,
}


# ---------------------------------------------------------------- cells to typed values


def _blank(value: Any) -> bool:
    if value is None or value is pd.NA:
        return True
    if isinstance(value, float):
        return math.isnan(value)
    return isinstance(value, str) and not value.strip()


def _to_float(value: Any) -> float:
    if isinstance(value, bool):
        raise ValueError
    number = float(value.strip()) if isinstance(value, str) else float(value)
    if not math.isfinite(number):
        raise ValueError
    return number


def _to_int(value: Any) -> int:
    number = _to_float(value)
    if not number.is_integer():
        raise ValueError
    return int(number)


def _to_str(value: Any) -> str:
    return str(value).strip()


def shared_error_json(value: Any) -> str:
    """A compensated series' share in the shared period and damping error, as canonical JSON
    text: the layout of `analysis.gls.SharedError.to_dict` (db imports no analysis; a test
    checks the two agree): two sensitivities, a 2x2 covariance, record_ms, at_ms,
    previous_deg2 and earlier_deg2, a list of {"trial": k >= 1, "j": 1 or 2, "deg2": v}, one
    per uncompensated series it covaries with (absent in files exported before it: empty);
    every number finite."""
    data = json.loads(str(value))
    if not isinstance(data, dict) or set(data) | {"earlier_deg2"} != SHARED_KEYS:
        raise ValueError
    g, cov = data["sensitivity"], data["covariance"]
    if len(g) != 2 or len(cov) != 2 or any(len(row) != 2 for row in cov):
        raise ValueError
    shared = {
        "sensitivity": [_to_float(v) for v in g],
        "covariance": [[_to_float(v) for v in row] for row in cov],
        "record_ms": _to_int(data["record_ms"]),
        "at_ms": _to_int(data["at_ms"]),
        "previous_deg2": _to_float(data["previous_deg2"]),
        "earlier_deg2": [_earlier(e) for e in data.get("earlier_deg2", [])],
    }
    return json.dumps(shared, sort_keys=True)


def _earlier(entry: Any) -> dict[str, Any]:
    """One entry of a shared error's earlier_deg2 (`shared_error_json`)."""
    if not isinstance(entry, dict) or set(entry) != EARLIER_KEYS:
        raise ValueError
    trial, j = _to_int(entry["trial"]), _to_int(entry["j"])
    if trial < 1 or j not in (1, 2):
        raise ValueError
    return {"trial": trial, "j": j, "deg2": _to_float(entry["deg2"])}


def _shared_ok(text: str) -> bool:
    """Variances >= 0 and stand times >= 0."""
    shared = json.loads(text)
    (var_p, _), (_, var_r) = shared["covariance"]
    return min(var_p, var_r, shared["record_ms"], shared["at_ms"]) >= 0


@dataclass(frozen=True)
class Field:
    """One column: how to convert a cell, the admissible values, whether it may be empty."""

    convert: Callable[[Any], Any]
    what: str  # "an integer", "a finite number", "text"
    ok: Callable[[Any], bool]
    rule: str
    optional: bool = False


INTEGER, NUMBER = "an integer", "a finite number"
FIELDS: dict[str, Field] = {
    "trial": Field(_to_int, INTEGER, lambda v: v >= 1, ">= 1"),
    "role": Field(_to_str, "text", lambda v: v in TRIAL_ROLES, "fit or control"),
    "direction_deg": Field(_to_float, NUMBER, lambda v: 0 <= v < 360, "in [0, 360)"),
    "amplitude_cm": Field(_to_float, NUMBER, lambda v: v > 0, "> 0"),
    "period_s": Field(_to_float, NUMBER, lambda v: v > 0, "> 0"),
    "j": Field(_to_int, INTEGER, lambda v: v in (1, 2), "1 (still) or 2 (rocking)"),
    "k": Field(_to_int, INTEGER, lambda v: v >= 1, ">= 1"),
    "value_deg": Field(_to_float, NUMBER, lambda v: abs(v) <= 360, "within +-360"),
    "mean_deg": Field(_to_float, NUMBER, lambda v: abs(v) <= 360, "within +-360"),
    "variance_deg2": Field(_to_float, NUMBER, lambda v: v >= 0, ">= 0"),
    "n_obs": Field(_to_int, INTEGER, lambda v: v >= 2, ">= 2"),
    "delta_mean_deg": Field(_to_float, NUMBER, lambda v: abs(v) <= 180, "within +-180"),
    "delta_var_deg2": Field(_to_float, NUMBER, lambda v: v >= 0, ">= 0", optional=True),
    "window_start_ms": Field(_to_int, INTEGER, lambda v: v >= 0, ">= 0", optional=True),
    "window_end_ms": Field(_to_int, INTEGER, lambda v: v >= 0, ">= 0", optional=True),
    "frames_used": Field(_to_int, INTEGER, lambda v: v >= 0, ">= 0", optional=True),
    "frames_lost": Field(_to_int, INTEGER, lambda v: v >= 0, ">= 0", optional=True),
    "flags": Field(
        _to_str, "text", lambda v: len(v) <= 200, "at most 200 characters", optional=True
    ),
    "compensation_deg": Field(
        _to_float, NUMBER, lambda v: abs(v) <= 360, "within +-360", optional=True
    ),
    "compensation_se_deg": Field(_to_float, NUMBER, lambda v: v >= 0, ">= 0", optional=True),
    "compensation_shared": Field(
        shared_error_json,
        "a shared error (JSON: sensitivity, covariance, record_ms, at_ms, previous_deg2, "
        "earlier_deg2 [{trial, j, deg2}])",
        _shared_ok,
        "its variances and times >= 0",
        optional=True,
    ),
}


def _typed_row(raw: RawRow, columns: tuple[str, ...], problems: list[str]) -> dict[str, Any] | None:
    """The row's cells converted and range-checked, or None (problems appended)."""
    values: dict[str, Any] = {}
    before = len(problems)
    for name in columns:
        field, cell = FIELDS[name], raw.cells.get(name)
        if _blank(cell):
            if not field.optional:
                problems.append(f"{raw.where}: {name} is empty")
            values[name] = "" if name == "flags" else None
            continue
        try:
            value = field.convert(cell)
        except (TypeError, ValueError):
            problems.append(f"{raw.where}: {name} {cell!r} is not {field.what}")
            continue
        if not field.ok(value):
            problems.append(f"{raw.where}: {name} = {value!r} is not {field.rule}")
        values[name] = value
    return values if len(problems) == before else None


# ---------------------------------------------------------------- the validated content


@dataclass(frozen=True)
class ImportedObservation:
    k: int
    value_deg: float
    window_start_ms: int | None = None
    window_end_ms: int | None = None
    frames_used: int | None = None
    frames_lost: int | None = None
    flags: str = ""
    compensation_deg: float | None = None


@dataclass(frozen=True)
class ImportedSeries:
    j: int
    observations: tuple[ImportedObservation, ...] = ()
    mean_deg: float | None = None  # seed 000 eq 2.1, when imported pre-averaged
    variance_deg2: float | None = None  # seed 000 eq 2.2
    n_obs: int | None = None
    compensation_se_deg: float | None = None  # SE of the compensation (compensated series)
    compensation_shared: str | None = None  # its SharedError as JSON (issue 34's GLS)


@dataclass(frozen=True)
class ImportedTrial:
    index: int
    role: str
    direction_deg: float
    amplitude_cm: float
    period_s: float
    series: tuple[ImportedSeries, ...] = ()
    delta_mean_deg: float | None = None  # seed 000: <delta_i> = <delta_2i> - <delta_1i>
    delta_var_deg2: float | None = None  # seed 000 eq 2.3
    n_obs: int | None = None


@dataclass(frozen=True)
class ImportedFile:
    path: Path
    sha256: str
    form: str  # "observations", "series" or "trials"
    n_obs: int  # N of every series
    trials: tuple[ImportedTrial, ...]


def _detect_form(path: Path, columns: list[str]) -> str:
    present = set(columns)
    matching = [form for form, cols in FORM_COLUMNS.items() if set(cols) <= present]
    if len(matching) == 1:
        form = matching[0]
        extras = OBSERVATION_EXTRAS if form == "observations" else ()
        unknown = [c for c in columns if c not in FORM_COLUMNS[form] and c not in extras]
        if unknown:
            raise ImportFileError(path, [f"unknown column(s) {', '.join(unknown)} ({form} form)"])
        return form
    if len(matching) > 1:
        raise ImportFileError(path, [f"columns fit several forms ({', '.join(matching)})"])
    closest = max(FORM_COLUMNS, key=lambda f: len(set(FORM_COLUMNS[f]) & present))
    missing = [c for c in FORM_COLUMNS[closest] if c not in present]
    expected = " | ".join(",".join(cols) for cols in FORM_COLUMNS.values())
    raise ImportFileError(
        path,
        [f"header has no {', '.join(missing)} for the {closest} form; expected one of: {expected}"],
    )


def read_import_file(path: Path) -> ImportedFile:
    """Read and fully validate `path` (.csv, .xlsx, .parquet). Raises ImportFileError."""
    path = Path(path)
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise ImportFileError(path, [f"unsupported file type {path.suffix!r} (csv, xlsx, parquet)"])
    try:
        content = path.read_bytes()
        columns, raw_rows, problems = reader(path)
    except (OSError, ValueError, ImportError, zipfile.BadZipFile) as error:
        raise ImportFileError(path, [f"cannot read it: {error}"]) from error
    if not columns:
        raise ImportFileError(path, ["no header row (empty file?)"])
    form = _detect_form(path, columns)
    if not raw_rows:
        raise ImportFileError(path, ["no data rows"])
    wanted = FORM_COLUMNS[form] + tuple(c for c in OBSERVATION_EXTRAS if c in columns)
    rows: list[tuple[str, dict[str, Any]]] = []
    for raw in raw_rows:
        values = _typed_row(raw, wanted, problems)
        if values is not None:
            rows.append((raw.where, values))
    if problems:  # grouping checks on a partial set of rows would only echo these problems
        raise ImportFileError(path, problems)
    trials, n_obs = _assemble(form, rows, problems)
    if problems:
        raise ImportFileError(path, problems)
    return ImportedFile(path, hashlib.sha256(content).hexdigest(), form, n_obs, trials)


def _assemble(
    form: str, rows: list[tuple[str, dict[str, Any]]], problems: list[str]
) -> tuple[tuple[ImportedTrial, ...], int]:
    """Group valid rows into trials and series; check consistency, duplicates, k = 1..N, equal N."""
    by_trial: dict[int, list[tuple[str, dict[str, Any]]]] = {}
    for where, values in rows:
        by_trial.setdefault(values["trial"], []).append((where, values))
    sizes: dict[int, str] = {}  # N -> where it was first seen
    trials = []
    for index in sorted(by_trial):
        group = by_trial[index]
        first_where, first = group[0]
        for where, values in group[1:] if form != "trials" else ():
            changed = [c for c in COMMON_COLUMNS[1:] if values[c] != first[c]]
            if changed:
                problems.append(
                    f"{where}: trial {index} {', '.join(changed)} differs from {first_where}"
                )
        common = dict(
            index=index,
            role=first["role"],
            direction_deg=first["direction_deg"],
            amplitude_cm=first["amplitude_cm"],
            period_s=first["period_s"],
        )
        if form == "trials":
            for where, _ in group[1:]:
                problems.append(f"{where}: trial {index} repeats {first_where}")
            if first["delta_var_deg2"] is None and first["role"] == "fit":
                problems.append(f"{first_where}: delta_var_deg2 is empty for fit trial {index}")
            sizes.setdefault(first["n_obs"], first_where)
            trials.append(
                ImportedTrial(
                    **common,
                    delta_mean_deg=first["delta_mean_deg"],
                    delta_var_deg2=first["delta_var_deg2"],
                    n_obs=first["n_obs"],
                )
            )
            continue
        series = []
        for j in (1, 2):
            rows_j = [(w, v) for w, v in group if v["j"] == j]
            if not rows_j:
                problems.append(f"{first_where}: trial {index} has no rows with j = {j}")
                continue
            built = _series(form, index, j, rows_j, problems)
            sizes.setdefault(built.n_obs or len({o.k for o in built.observations}), rows_j[0][0])
            series.append(built)
        trials.append(ImportedTrial(**common, series=tuple(series)))
    if len(sizes) > 1:
        seen = ", ".join(f"N = {n} at {where}" for n, where in sizes.items())
        problems.append(f"all series must have the same N, found {seen}")
    return tuple(trials), next(iter(sizes), 0)


def _series(
    form: str, index: int, j: int, rows: list[tuple[str, dict[str, Any]]], problems: list[str]
) -> ImportedSeries:
    first_where, first = rows[0]
    if form == "series":
        for where, _ in rows[1:]:
            problems.append(f"{where}: trial {index} j = {j} repeats {first_where}")
        return ImportedSeries(
            j,
            mean_deg=first["mean_deg"],
            variance_deg2=first["variance_deg2"],
            n_obs=first["n_obs"],
        )
    seen: dict[int, str] = {}
    for where, values in rows:
        if values["k"] in seen:
            problems.append(
                f"{where}: trial {index} j = {j} k = {values['k']} repeats {seen[values['k']]}"
            )
        seen.setdefault(values["k"], where)
        start, end = values.get("window_start_ms"), values.get("window_end_ms")
        if start is not None and end is not None and end < start:
            problems.append(f"{where}: window_end_ms {end} is before window_start_ms {start}")
    missing = [k for k in range(1, len(seen) + 1) if k not in seen]  # k distinct, >= 1
    if missing:
        problems.append(
            f"{first_where}: trial {index} j = {j} has no k = {', '.join(map(str, missing))}"
            " (k must run 1..N)"
        )
    if len(seen) < 2:
        problems.append(f"{first_where}: trial {index} j = {j} has {len(seen)} observation, N >= 2")
    observations = tuple(
        ImportedObservation(**{name: values[name] for name in values if name in OBS_FIELDS})
        for _, values in sorted(rows, key=lambda row: row[1]["k"])
    )
    return ImportedSeries(
        j,
        observations=observations,
        compensation_se_deg=_series_field("compensation_se_deg", index, j, rows, problems),
        compensation_shared=_series_field("compensation_shared", index, j, rows, problems),
    )


def _series_field(
    name: str, index: int, j: int, rows: list[tuple[str, dict[str, Any]]], problems: list[str]
) -> Any:
    """A series' compensation figure (`SERIES_FIELDS`): one value on all its rows, given only
    with a compensation; its SE also always with one (the shared error may be absent: a series
    compensated before it was stored)."""
    first_where = rows[0][0]
    values = {v.get(name) for _, v in rows}
    compensated = any(v.get("compensation_deg") is not None for _, v in rows)
    if len(values) > 1:
        problems.append(f"{first_where}: trial {index} j = {j} {name} differs by row")
        return None
    (value,) = values
    if value is not None and not compensated:
        problems.append(f"{first_where}: trial {index} j = {j} has no compensation_deg for {name}")
    elif value is None and compensated and name == "compensation_se_deg":
        problems.append(f"{first_where}: trial {index} j = {j} has compensation_deg without {name}")
    return value


# ---------------------------------------------------------------- storing


METADATA_RULES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "model": (lambda v: isinstance(v, str) and v.strip() != "", "non-empty text"),
    "serial": (lambda v: isinstance(v, str) and v.strip() != "", "non-empty text"),
    "lp_gcm2s2": (lambda v: _positive(v), "a number > 0 (g*cm^2*s^-2)"),
    "h1_gcm2s": (lambda v: _positive(v), "a number > 0 (g*cm^2*s^-1)"),
    "latitude_deg": (lambda v: _number(v) and -90 < v < 90, "a number in (-90, 90)"),
    "earth_rate_rad_s": (lambda v: _positive(v), "a number > 0 (rad/s)"),
    "gravity_cm_s2": (lambda v: _positive(v), "a number > 0 (cm/s^2)"),
}


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _positive(value: Any) -> bool:
    return _number(value) and value > 0


def check_metadata(metadata: Mapping[str, Any]) -> None:
    """Raise MetadataError naming every missing or bad key of the campaign metadata."""
    problems = []
    for key, (ok, rule) in METADATA_RULES.items():
        if key not in metadata:
            problems.append(f"{key} is missing")
        elif not ok(metadata[key]):
            problems.append(f"{key} = {metadata[key]!r} is not {rule}")
    for key in ("operator", "software_version", "plan_toml"):
        if key in metadata and not isinstance(metadata[key], str):
            problems.append(f"{key} = {metadata[key]!r} is not text")
    operator = metadata.get("operator")
    if isinstance(operator, str) and not operator.strip():  # as a plan's [campaign] operator
        problems.append(f"operator = {operator!r} is not non-empty text")
    if problems:
        raise MetadataError("campaign metadata: " + "; ".join(problems))


def metadata_toml(metadata: Mapping[str, Any]) -> str:
    """The instrument and site metadata as a small TOML plan (stored when no plan file is given)."""

    def value(v: Any) -> str:
        return json.dumps(v) if isinstance(v, str) else repr(float(v))

    tables = {
        "instrument": ("model", "serial", "lp_gcm2s2", "h1_gcm2s"),
        "site": ("latitude_deg", "earth_rate_rad_s", "gravity_cm_s2"),
    }
    lines = ["# campaign metadata of an imported file (no plan file was given)"]
    for table, keys in tables.items():
        lines += ["", f"[{table}]"] + [f"{key} = {value(metadata[key])}" for key in keys]
    return "\n".join(lines) + "\n"


def store_import(
    session: Session,
    data: ImportedFile,
    metadata: Mapping[str, Any],
    labels: Mapping[str, str] | None = None,
) -> Campaign:
    """Add the imported campaign (status completed, source import, with its `labels`) to
    `session` and flush.

    `metadata`: model, serial, lp_gcm2s2, h1_gcm2s, latitude_deg, earth_rate_rad_s, gravity_cm_s2;
    optional operator, software_version, plan_toml (default: `metadata_toml(metadata)`)."""
    check_metadata(metadata)
    plan_toml = metadata.get("plan_toml") or metadata_toml(metadata)
    header = CampaignHeader(
        model=metadata["model"],
        serial=metadata["serial"],
        lp_gcm2s2=float(metadata["lp_gcm2s2"]),
        h1_gcm2s=float(metadata["h1_gcm2s"]),
        latitude_deg=float(metadata["latitude_deg"]),
        earth_rate_rad_s=float(metadata["earth_rate_rad_s"]),
        gravity_cm_s2=float(metadata["gravity_cm_s2"]),
        plan_toml=plan_toml,
        operator=metadata.get("operator", "unknown"),
        n_obs=data.n_obs,
        software_version=metadata.get("software_version", "unknown"),
    )
    campaign = new_campaign(session, header, status="completed", source="import", labels=labels)
    for trial in data.trials:
        campaign.trials.append(
            Trial(
                index=trial.index,
                role=trial.role,
                cmd_direction_deg=trial.direction_deg,
                cmd_amplitude_cm=trial.amplitude_cm,
                cmd_period_s=trial.period_s,
                status="completed",
                summary_delta_mean_deg=trial.delta_mean_deg,
                summary_delta_var_deg2=trial.delta_var_deg2,
                summary_n=trial.n_obs,
                series=[
                    Series(
                        j=s.j,
                        status="completed",
                        summary_mean_deg=s.mean_deg,
                        summary_variance_deg2=s.variance_deg2,
                        summary_n=s.n_obs,
                        compensation_se_deg=s.compensation_se_deg,
                        compensation_shared=None
                        if s.compensation_shared is None
                        else json.loads(s.compensation_shared),
                        observations=[Observation(**vars(o)) for o in s.observations],
                    )
                    for s in trial.series
                ],
            )
        )
    campaign.events.append(
        Event(
            kind="import",
            severity="info",
            message=f"imported {data.form} form, {len(data.trials)} trials, from {data.path} "
            f"(sha256 {data.sha256})",
        )
    )
    session.add(campaign)
    session.flush()
    return campaign


def import_file(sessions: sessionmaker[Session], path: Path, metadata: Mapping[str, Any]) -> int:
    """Validate metadata and file completely, then store them in one transaction; the new
    campaign's id. Raises MetadataError or ImportFileError (the database is then untouched)."""
    check_metadata(metadata)
    data = read_import_file(path)
    with writer(sessions).begin() as session:
        return store_import(session, data, metadata).id


# ---------------------------------------------------------------- export
