"""Import (three forms, row-by-row validation, one transaction) and export round trips."""

import hashlib
import json
import sqlite3
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.analysis.gls import SharedError
from gyrostand.analysis.trials import trial_statistics
from gyrostand.db.io import (
    SEED_000_METADATA,
    ImportedFile,
    ImportedTrial,
    ImportFileError,
    MetadataError,
    import_file,
    read_import_file,
    shared_error_json,
)
from gyrostand.db.models import Campaign, Event, Instrument
from gyrostand.db.queries import load_campaign
from gyrostand.report.export import campaign_frames, export_campaign, export_paths
from gyrostand.report.stored import series_summary, stored_inputs

ROOT = Path(__file__).resolve().parents[2]

# Potemkin (1982), seed 000 example table; S^2 printed in 1e-4 deg^2, here in deg^2
PAPER_CSV = """\
# seed 000 example: six trials, 1-4 fit, 5-6 control, N = 5
trial,role,direction_deg,amplitude_cm,period_s,delta_mean_deg,delta_var_deg2,n_obs
1,fit,332,24,8,-0.117,0.80e-4,5
2,fit,18,24,6.3,+0.21,4.64e-4,5
3,fit,316,23,5.5,-0.466,1.84e-4,5
4,fit,346,17.8,3.5,-0.401,2.12e-4,5
5,control,31,23.5,6.2,+0.32,,5
6,control,346,17.8,5.5,-0.11,,5
"""
PAPER = {  # trial: (role, K deg, A cm, tau s, <delta> deg, S^2 deg^2)
    1: ("fit", 332, 24, 8, -0.117, 0.80e-4),
    2: ("fit", 18, 24, 6.3, 0.21, 4.64e-4),
    3: ("fit", 316, 23, 5.5, -0.466, 1.84e-4),
    4: ("fit", 346, 17.8, 3.5, -0.401, 2.12e-4),
    5: ("control", 31, 23.5, 6.2, 0.32, None),
    6: ("control", 346, 17.8, 5.5, -0.11, None),
}


def dump(db: Path) -> str:
    """The whole database content as SQL text (compares equal iff nothing was written)."""
    with sqlite3.connect(db) as conn:
        return "\n".join(conn.iterdump())


def assert_paper_campaign(sessions: sessionmaker[Session], campaign_id: int) -> None:
    with sessions() as session:
        campaign = load_campaign(session, campaign_id)
        assert (campaign.source, campaign.status, campaign.n_obs) == ("import", "completed", 5)
        assert len(campaign.trials) == 6
        for trial in campaign.trials:
            role, k, a, tau, delta, var = PAPER[trial.index]
            assert trial.role == role
            assert (trial.cmd_direction_deg, trial.cmd_amplitude_cm, trial.cmd_period_s) == (
                k,
                a,
                tau,
            )
            assert trial.summary_delta_mean_deg == delta
            assert trial.summary_delta_var_deg2 == (None if var is None else pytest.approx(var))
            assert trial.summary_n == 5 and trial.series == []


def test_paper_table_import(sessions: sessionmaker[Session], tmp_path: Path) -> None:
    path = tmp_path / "paper.csv"
    path.write_text(PAPER_CSV)
    campaign_id = import_file(sessions, path, {**SEED_000_METADATA, "operator": "V. Potemkin"})
    assert_paper_campaign(sessions, campaign_id)
    with sessions() as session:
        campaign = session.get_one(Campaign, campaign_id)
        assert campaign.operator == "V. Potemkin"
        assert (campaign.latitude_deg, campaign.earth_rate_rad_s) == (46.5, 7.3e-5)
        assert campaign.instrument.constants_json == {"lp_gcm2s2": 6.57e6, "h1_gcm2s": 1.55e8}
        plan = tomllib.loads(campaign.plan_toml)
        assert plan["instrument"]["h1_gcm2s"] == 1.55e8 and plan["site"]["gravity_cm_s2"] == 981
        assert campaign.plan_hash == hashlib.sha256(campaign.plan_toml.encode()).hexdigest()
        [event] = campaign.events
        assert event.kind == "import"
        assert hashlib.sha256(path.read_bytes()).hexdigest() in event.message


@pytest.mark.skipif(not (ROOT / "examples/paper.csv").exists(), reason="no examples/paper.csv yet")
def test_shipped_paper_csv_holds_the_paper_numbers(sessions: sessionmaker[Session]) -> None:
    assert_paper_campaign(
        sessions, import_file(sessions, ROOT / "examples/paper.csv", SEED_000_METADATA)
    )


def observation_rows(seed: int = 7, n_obs: int = 4) -> pd.DataFrame:
    """Synthetic per-observation rows with full-precision random values."""
    rng = np.random.default_rng(seed)
    rows = []
    for trial, (role, k_deg, a_cm, tau_s) in enumerate(
        [("fit", 332.0, 24.0, 8.0), ("fit", 18.0, 24.0, 6.3), ("control", 31.0, 23.5, 6.2)], 1
    ):
        for j in (1, 2):
            for k in range(1, n_obs + 1):
                start = int(rng.integers(0, 10**9))
                rows.append(
                    dict(
                        trial=trial,
                        role=role,
                        direction_deg=k_deg,
                        amplitude_cm=a_cm,
                        period_s=tau_s,
                        j=j,
                        k=k,
                        value_deg=float(rng.normal(120.0 + 0.3 * j, 0.02)),
                        window_start_ms=start,
                        window_end_ms=start + 64_000,
                        frames_used=640,
                        frames_lost=int(rng.integers(0, 3)),
                        flags="gap" if k == 2 else "",
                    )
                )
    return pd.DataFrame(rows)


def test_observation_import_summaries_match_numpy(
    sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    rows = observation_rows()
    rows.sample(frac=1, random_state=1).to_csv(tmp_path / "obs.csv", index=False)  # any order
    campaign_id = import_file(sessions, tmp_path / "obs.csv", SEED_000_METADATA)
    with sessions() as session:
        frames = campaign_frames(session, campaign_id)
    assert len(frames.observations) == 24
    for trial in (1, 2, 3):
        s1 = rows[(rows.trial == trial) & (rows.j == 1)].value_deg.to_numpy()
        s2 = rows[(rows.trial == trial) & (rows.j == 2)].value_deg.to_numpy()
        series = frames.series[frames.series.trial == trial].set_index("j")
        assert series.loc[1, "mean_deg"] == pytest.approx(np.mean(s1), rel=1e-15)
        assert series.loc[2, "variance_deg2"] == pytest.approx(np.var(s2, ddof=1), rel=1e-12)
        row = frames.trials.set_index("trial").loc[trial]
        assert row.delta_mean_deg == pytest.approx(np.mean(s2) - np.mean(s1), abs=1e-12)
        assert row.delta_var_deg2 == pytest.approx(np.var(s1, ddof=1) + np.var(s2, ddof=1))
        assert row.n_obs == 4


@pytest.mark.parametrize("fmt", ["csv", "parquet", "xlsx"])
def test_export_reimports_to_identical_numbers(
    sessions: sessionmaker[Session], tmp_path: Path, fmt: str
) -> None:
    observation_rows().to_csv(tmp_path / "obs.csv", index=False)
    first = import_file(sessions, tmp_path / "obs.csv", SEED_000_METADATA)
    out = tmp_path / f"export.{fmt}"
    with sessions() as session:
        exported = export_campaign(session, first, fmt, out)
    second = import_file(sessions, out, SEED_000_METADATA)
    with sessions() as session:
        again = campaign_frames(session, second)
    # CSV and Parquet are bit-exact; openpyxl writes 16 significant digits (Excel keeps 15)
    exact = {"check_exact": True} if fmt != "xlsx" else {"check_exact": False, "rtol": 1e-15}
    pd.testing.assert_frame_equal(again.observations, exported.observations, **exact)
    pd.testing.assert_frame_equal(again.trials, exported.trials, **exact)
    if fmt != "xlsx":
        assert again.observations.value_deg.tolist() == observation_rows().value_deg.tolist()
    if fmt != "xlsx":  # the summaries re-import too, in their own forms
        third = import_file(sessions, export_paths(out, fmt)["series"], SEED_000_METADATA)
        with sessions() as session:
            from_series = campaign_frames(session, third)
        pd.testing.assert_frame_equal(from_series.trials, exported.trials, check_exact=True)
    with sessions() as session:  # the same instrument and constants: one instrument row
        assert len(session.scalars(select(Instrument)).all()) == 1


def test_series_form_import(sessions: sessionmaker[Session], tmp_path: Path) -> None:
    path = tmp_path / "series.csv"
    path.write_text(
        "trial,role,direction_deg,amplitude_cm,period_s,j,mean_deg,variance_deg2,n_obs\n"
        "1,fit,332,24,8,1,10.250,0.00004,5\n"
        "1,fit,332,24,8,2,10.133,0.00004,5\n"
    )
    with sessions() as session:
        trials = campaign_frames(session, import_file(sessions, path, SEED_000_METADATA)).trials
    assert trials.delta_mean_deg.tolist() == [pytest.approx(-0.117, abs=1e-12)]
    assert trials.delta_var_deg2.tolist() == [pytest.approx(0.8e-4)]


def test_export_and_analysis_agree_across_north(
    sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    """An imported series pair at 359.9 / 0.1 deg: the export and the analysis both give
    <delta> = +0.20 deg (one statistics path)."""
    path = tmp_path / "north.csv"
    path.write_text(
        "trial,role,direction_deg,amplitude_cm,period_s,j,mean_deg,variance_deg2,n_obs\n"
        "1,fit,332,24,8,1,359.9,0.00004,5\n"
        "1,fit,332,24,8,2,0.1,0.00004,5\n"
    )
    campaign_id = import_file(sessions, path, SEED_000_METADATA)
    with sessions() as session:
        exported = campaign_frames(session, campaign_id).trials.delta_mean_deg.tolist()
        analysed = trial_statistics(stored_inputs(load_campaign(session, campaign_id)).trials[0])
    assert exported == [pytest.approx(0.2)]
    assert analysed.delta_deg == pytest.approx(0.2)


def test_excel_and_parquet_errors_name_sheet_rows_and_records(tmp_path: Path) -> None:
    frame = observation_rows()
    frame.loc[2, "role"] = "fitt"
    frame.to_excel(tmp_path / "bad.xlsx", index=False)  # header on row 1: frame row 2 is row 4
    frame.to_parquet(tmp_path / "bad.parquet", index=False)  # record numbers from 1
    for name, where in (("bad.xlsx", "row 4"), ("bad.parquet", "row 3")):
        with pytest.raises(ImportFileError) as caught:
            read_import_file(tmp_path / name)
        assert caught.value.problems == [f"{where}: role = 'fitt' is not fit or control"]


HEADER = "trial,role,direction_deg,amplitude_cm,period_s,j,k,value_deg\n"


def obs_lines(n_obs: int = 2, trial: int = 1, skip: tuple[tuple[int, int], ...] = ()) -> str:
    return "".join(
        f"{trial},fit,332,24,8,{j},{k},{0.1 * k + j}\n"
        for j in (1, 2)
        for k in range(1, n_obs + 1)
        if (j, k) not in skip
    )


BAD_FILES = {
    "bad role": (
        HEADER + "# a comment\n" + obs_lines().replace("fit", "fitt", 1),
        ["line 3: role = 'fitt' is not fit or control"],
    ),
    "bad j": (
        HEADER + obs_lines() + "1,fit,332,24,8,3,1,0.5\n",
        ["line 6: j = 3 is not 1 (still) or 2 (rocking)"],
    ),
    "not a number": (
        HEADER + obs_lines().replace("1.1", "abc", 1),
        ["line 2: value_deg 'abc' is not a finite number"],
    ),
    "nan": (
        HEADER + obs_lines().replace("1.1", "nan", 1),
        ["line 2: value_deg 'nan' is not a finite number"],
    ),
    "fractional k": (
        HEADER + obs_lines().replace(",1,1.1", ",1.5,1.1", 1),
        ["line 2: k '1.5' is not an integer"],
    ),
    "empty cell": (HEADER + obs_lines().replace("332", "", 1), ["line 2: direction_deg is empty"]),
    "k gap": (
        HEADER + obs_lines(3, skip=((1, 2),)),
        [
            "line 2: trial 1 j = 1 has no k = 2 (k must run 1..N)",
            "all series must have the same N, found N = 2 at line 2, N = 3 at line 4",
        ],
    ),
    "duplicate k": (
        HEADER + obs_lines() + "1,fit,332,24,8,2,2,0.3\n",
        ["line 6: trial 1 j = 2 k = 2 repeats line 5"],
    ),
    "N = 1": (
        HEADER + obs_lines(1),
        [
            "line 2: trial 1 j = 1 has 1 observation, N >= 2",
            "line 3: trial 1 j = 2 has 1 observation, N >= 2",
        ],
    ),
    "no rocking series": (
        HEADER + obs_lines(skip=((2, 1), (2, 2))),
        ["line 2: trial 1 has no rows with j = 2"],
    ),
    "unequal N": (
        HEADER + obs_lines(2) + obs_lines(3, trial=2),
        ["all series must have the same N, found N = 2 at line 2, N = 3 at line 6"],
    ),
    "trial changes": (
        HEADER + obs_lines().replace("24,8,2,2", "23,8,2,2"),
        ["line 5: trial 1 amplitude_cm differs from line 2"],
    ),
    "ragged": (
        HEADER + obs_lines() + "1,fit,332,24,8,2,3,0.3,9\n",
        ["line 6: 9 fields, the header has 8"],
    ),
    "unknown column": (
        HEADER.replace("\n", ",note\n") + obs_lines().replace("\n", ",x\n"),
        ["unknown column(s) note (observations form)"],
    ),
    "no value column": (
        HEADER.replace(",value_deg", ",valeu_deg"),
        [
            "header has no value_deg for the observations form; expected one of: "
            "trial,role,direction_deg,amplitude_cm,period_s,j,k,value_deg | "
            "trial,role,direction_deg,amplitude_cm,period_s,j,mean_deg,variance_deg2,n_obs | "
            "trial,role,direction_deg,amplitude_cm,period_s,delta_mean_deg,delta_var_deg2,n_obs"
        ],
    ),
    "k far out": (
        HEADER + obs_lines() + "1,fit,332,24,8,2,1000000000,0.3\n",
        [
            "line 4: trial 1 j = 2 has no k = 3 (k must run 1..N)",
            "all series must have the same N, found N = 2 at line 2, N = 3 at line 4",
        ],
    ),
    "window order": (
        HEADER.replace("\n", ",window_start_ms,window_end_ms\n")
        + obs_lines().replace("\n", ",1000,2000\n").replace("1000,2000", "3000,2000", 1),
        ["line 2: window_end_ms 2000 is before window_start_ms 3000"],
    ),
    "header only": (HEADER, ["no data rows"]),
    "empty": ("# nothing\n\n", ["no header row (empty file?)"]),
    "fit trial without variance": (
        PAPER_CSV.replace("4.64e-4", ""),
        ["line 4: delta_var_deg2 is empty for fit trial 2"],
    ),
    "trial repeated": (
        PAPER_CSV + "6,control,346,17.8,5.5,-0.12,,5\n",
        ["line 9: trial 6 repeats line 8"],
    ),
    "negative variance": (
        PAPER_CSV.replace("1.84e-4", "-1.84e-4"),
        ["line 5: delta_var_deg2 = -0.000184 is not >= 0"],
    ),
    "direction 360": (
        PAPER_CSV.replace("346,17.8,3.5", "360,17.8,3.5"),
        ["line 6: direction_deg = 360.0 is not in [0, 360)"],
    ),
    "several problems": (
        PAPER_CSV.replace("332,24,8", "332,-24,0"),
        [
            "line 3: amplitude_cm = -24.0 is not > 0",
            "line 3: period_s = 0.0 is not > 0",
        ],
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_file_gives_every_problem_and_writes_nothing(
    sessions: sessionmaker[Session], db_path: Path, tmp_path: Path, case: str
) -> None:
    (tmp_path / "good.csv").write_text(PAPER_CSV)
    import_file(sessions, tmp_path / "good.csv", SEED_000_METADATA)
    before = dump(db_path)
    text, problems = BAD_FILES[case]
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(ImportFileError) as caught:
        import_file(sessions, tmp_path / "bad.csv", SEED_000_METADATA)
    assert caught.value.problems == problems
    count = f"{len(problems)} problems: " if len(problems) > 1 else ""
    assert str(caught.value) == f"{tmp_path / 'bad.csv'}: {count}{'; '.join(problems)}"
    assert dump(db_path) == before


def test_long_problem_lists_are_cut_in_the_message(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(HEADER + obs_lines(15).replace(",fit,", ",x,"))
    with pytest.raises(ImportFileError) as caught:
        read_import_file(path)
    assert len(caught.value.problems) == 30
    assert str(caught.value).endswith("line 11: role = 'x' is not fit or control; ... and 20 more")


def test_unsupported_or_missing_files(tmp_path: Path) -> None:
    with pytest.raises(ImportFileError, match=r"unsupported file type '\.txt'"):
        read_import_file(tmp_path / "notes.txt")
    with pytest.raises(ImportFileError, match="cannot read it: .*No such file"):
        read_import_file(tmp_path / "absent.csv")
    (tmp_path / "zip.xlsx").write_bytes(b"PK\x03\x04 not really a workbook")
    (tmp_path / "bad.parquet").write_bytes(b"PAR1 not really parquet")
    for name in ("zip.xlsx", "bad.parquet"):
        with pytest.raises(ImportFileError, match=f"{name}: cannot read it: "):
            read_import_file(tmp_path / name)


def test_bad_metadata_is_refused_before_anything_is_written(
    sessions: sessionmaker[Session], db_path: Path, tmp_path: Path
) -> None:
    (tmp_path / "paper.csv").write_text(PAPER_CSV)
    before = dump(db_path)
    metadata = {**SEED_000_METADATA, "latitude_deg": 95.0}
    del metadata["h1_gcm2s"]
    with pytest.raises(MetadataError) as caught:
        import_file(sessions, tmp_path / "paper.csv", metadata)
    assert str(caught.value) == (
        "campaign metadata: h1_gcm2s is missing; latitude_deg = 95.0 is not a number in (-90, 90)"
    )
    assert dump(db_path) == before


def test_a_failure_while_storing_rolls_everything_back(
    sessions: sessionmaker[Session], db_path: Path, tmp_path: Path
) -> None:
    """Validation is bypassed on purpose: the database's own CHECK fails on the third trial,
    after the instrument, campaign and two trials were added in the same transaction."""
    trials = tuple(
        ImportedTrial(
            i, "fit", direction, 24.0, 8.0, delta_mean_deg=0.1, delta_var_deg2=1e-4, n_obs=5
        )
        for i, direction in ((1, 10.0), (2, 20.0), (3, 400.0))
    )
    data = ImportedFile(tmp_path / "x.csv", "0" * 64, "trials", 5, trials)
    from gyrostand.db.io import store_import

    before = dump(db_path)
    with pytest.raises(IntegrityError, match="ck_trial_cmd_direction"), sessions.begin() as session:
        store_import(session, data, SEED_000_METADATA)
    assert dump(db_path) == before
    with sessions() as session:
        assert session.scalars(select(Event)).all() == []


def compensated_rows() -> pd.DataFrame:
    """observation_rows with trial 2's still series compensated: a decaying transient per
    observation and the settle point's SE repeated on its rows."""
    frame = observation_rows()
    frame["compensation_deg"] = np.nan
    frame["compensation_se_deg"] = np.nan
    rows = (frame.trial == 2) & (frame.j == 1)
    frame.loc[rows, "compensation_deg"] = [0.04, 0.02, 0.01, 0.005]
    frame.loc[rows, "compensation_se_deg"] = 0.003
    frame["compensation_shared"] = None
    frame.loc[rows, "compensation_shared"] = json.dumps(SHARED)
    return frame


# a compensated series' share in the period and damping error (analysis.gls.SharedError)
SHARED = {
    "sensitivity": [1.5e-6, -0.02],
    "covariance": [[900.0, 0.01], [0.01, 4e-4]],
    "record_ms": 7_200_000,
    "at_ms": 3_600_000,
    "previous_deg2": -2e-6,
    "earlier_deg2": [
        {"deg2": 3e-7, "j": 1, "trial": 1},  # Cov with the plain means of the series it names
        {"deg2": -1e-7, "j": 2, "trial": 1},
    ],
}


def test_compensation_survives_export_and_import(
    sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    frame = compensated_rows()
    frame.to_csv(tmp_path / "obs.csv", index=False)
    first = import_file(sessions, tmp_path / "obs.csv", SEED_000_METADATA)
    with sessions() as session:
        exported = export_campaign(session, first, "csv", tmp_path / "export.csv")
    second = import_file(sessions, tmp_path / "export.csv", SEED_000_METADATA)
    with sessions() as session:
        again = campaign_frames(session, second)
    pd.testing.assert_frame_equal(again.observations, exported.observations, check_exact=True)
    with sessions() as session:  # the shared error too, as the acquisition stores it
        trials = load_campaign(session, second).trials
        shared = [
            (t.index, s.j, s.compensation_shared)
            for t in trials
            for s in t.series
            if s.compensation_shared is not None
        ]
        summaries = {(t.index, s.j): series_summary(s) for t in trials for s in t.series}
    assert shared == [(2, 1, SHARED)]
    older = {k: v for k, v in SHARED.items() if k != "earlier_deg2"}  # exported before it
    assert json.loads(shared_error_json(json.dumps(older)))["earlier_deg2"] == []
    # the variance of a compensated mean is the compensation's SE^2 (issue 34), not S^2/N + SE^2
    assert summaries[2, 1].var_mean_deg2 == 0.003**2
    assert summaries[2, 2].var_mean_deg2 is None
    # the analysis's series: value - compensation, variance + N SE^2 (report.stored.series_summary)
    rows = frame[(frame.trial == 2) & (frame.j == 1)]
    corrected = (rows.value_deg - rows.compensation_deg).to_numpy()
    series = again.series.set_index(["trial", "j"]).loc[(2, 1)]
    assert series.mean_deg == pytest.approx(corrected.mean(), rel=1e-15)
    assert series.variance_deg2 == pytest.approx(np.var(corrected, ddof=1) + 4 * 0.003**2)
    raw = frame[(frame.trial == 2) & (frame.j == 2)].value_deg.to_numpy()
    delta = again.trials.set_index("trial").loc[2].delta_mean_deg
    assert delta == pytest.approx(raw.mean() - corrected.mean(), abs=1e-12)


@pytest.mark.parametrize(
    ("edit", "problem"),
    [
        (
            lambda f: f.assign(compensation_se_deg=np.nan),
            "has compensation_deg without compensation_se_deg",
        ),
        (
            lambda f: f.assign(compensation_deg=np.nan, compensation_shared=None),
            "has no compensation_deg for compensation_se_deg",
        ),
        (
            lambda f: f.assign(
                compensation_se_deg=f.compensation_se_deg.where(f.compensation_deg != 0.02, 0.004)
            ),
            "compensation_se_deg differs by row",
        ),
        (
            lambda f: f.assign(
                compensation_shared=f.compensation_shared.where(
                    f.compensation_deg != 0.02, json.dumps({**SHARED, "at_ms": 1})
                )
            ),
            "compensation_shared differs by row",
        ),
        (
            lambda f: f.assign(compensation_deg=np.nan, compensation_se_deg=np.nan),
            "has no compensation_deg for compensation_shared",
        ),
    ],
)
def test_inconsistent_compensation_is_refused(tmp_path: Path, edit, problem: str) -> None:
    edit(compensated_rows()).to_csv(tmp_path / "obs.csv", index=False)
    with pytest.raises(ImportFileError) as caught:
        read_import_file(tmp_path / "obs.csv")
    assert caught.value.problems == [f"line 10: trial 2 j = 1 {problem}"]  # its first row


def test_the_import_reads_the_shared_error_the_analysis_writes() -> None:
    """db/io.py checks the layout of analysis.gls.SharedError itself (db imports no analysis)."""
    shared = SharedError.from_dict(SHARED)
    text = shared_error_json(json.dumps(shared.to_dict()))
    assert json.loads(text) == shared.to_dict() == SHARED
    assert SharedError.from_dict(json.loads(text)) == shared
    for key in set(SHARED) - {"earlier_deg2"}:  # each key is needed (that one: not before it)
        with pytest.raises(ValueError):
            shared_error_json(json.dumps({k: v for k, v in SHARED.items() if k != key}))


@pytest.mark.parametrize(
    ("shared", "problem"),
    [
        ("{", "is not a shared error"),
        (json.dumps({**SHARED, "sensitivity": [1.0]}), "is not a shared error"),
        (
            json.dumps({**SHARED, "covariance": [[-1.0, 0.0], [0.0, 1.0]]}),
            "variances and times >= 0",
        ),
        (json.dumps({**SHARED, "at_ms": "soon"}), "is not a shared error"),
        # earlier_deg2 names each series (a bare list of numbers said nothing of which)
        (json.dumps({**SHARED, "earlier_deg2": [3e-7, -1e-7]}), "is not a shared error"),
        (json.dumps({**SHARED, "earlier_deg2": 3e-7}), "is not a shared error"),
        (
            json.dumps({**SHARED, "earlier_deg2": [{"trial": 1, "j": 3, "deg2": 0.0}]}),
            "is not a shared error",
        ),
        (
            json.dumps({**SHARED, "earlier_deg2": [{"trial": 1, "j": 1, "deg2": "NaN"}]}),
            "is not a shared error",
        ),
        (json.dumps({**SHARED, "earlier_deg2": [{"trial": 1, "j": 1}]}), "is not a shared error"),
    ],
)
def test_a_malformed_shared_error_is_refused(tmp_path: Path, shared: str, problem: str) -> None:
    frame = compensated_rows()
    frame.loc[frame.compensation_shared.notna(), "compensation_shared"] = shared
    frame.to_csv(tmp_path / "obs.csv", index=False)
    with pytest.raises(ImportFileError) as caught:
        read_import_file(tmp_path / "obs.csv")
    assert len(caught.value.problems) == 4  # each of the series' rows
    assert caught.value.problems[0].startswith("line 10: compensation_shared")
    assert problem in caught.value.problems[0]
