"""report.stored: trial inputs from each stored form, settings from the stored plan, the
analysis run recorded once per distinct result, and reports of campaigns that cannot be analysed."""

import json
import sqlite3
import threading
from pathlib import Path

import pytest
from sqlalchemy import func, select

from gyrostand.analysis.trials import SeriesSummary
from gyrostand.db.models import AnalysisRun, Campaign, Observation, Series, Trial
from gyrostand.db.queries import load_campaign
from gyrostand.report import stored as stored_module
from gyrostand.report.compliance import NOT_ASSESSED
from gyrostand.report.html import render_html
from gyrostand.report.json_doc import report_json
from gyrostand.report.settings import SEED_000_SETTINGS
from gyrostand.report.stored import analyze_stored, stored_inputs, trial_input

from .conftest import Stored, import_paper


def make_trial(**kwargs: object) -> Trial:
    fields = {
        "index": 1,
        "role": "fit",
        "cmd_direction_deg": 45.0,
        "cmd_amplitude_cm": 24.0,
        "cmd_period_s": 6.0,
        "status": "completed",
    }
    return Trial(**{**fields, **kwargs})


def test_observations_become_raw_series_with_the_measured_motion() -> None:
    trial = make_trial(meas_direction_deg=44.5, meas_amplitude_cm=23.8, meas_period_s=6.01)
    trial.series = [
        Series(j=j, observations=[Observation(k=k, value_deg=v) for k, v in enumerate(vs, 1)])
        for j, vs in ((1, (10.0, 10.2, 10.1)), (2, (10.5, 10.4, 10.6)))
    ]
    found = trial_input(trial)
    assert not isinstance(found, str)
    assert (found.before_deg, found.under_deg) == ((10.0, 10.2, 10.1), (10.5, 10.4, 10.6))
    assert (found.direction_deg, found.amplitude_cm, found.period_s) == (44.5, 23.8, 6.01)


def test_series_and_trial_summaries_and_unusable_trials() -> None:
    trial = make_trial()
    trial.series = [
        Series(j=1, summary_mean_deg=1.0, summary_variance_deg2=1e-4, summary_n=5),
        Series(j=2, summary_mean_deg=1.3, summary_variance_deg2=2e-4, summary_n=5),
    ]
    found = trial_input(trial)
    assert not isinstance(found, str)
    assert found.before == SeriesSummary(1.0, 1e-4, 5) and found.under == SeriesSummary(
        1.3, 2e-4, 5
    )
    paper_form = trial_input(
        make_trial(summary_delta_mean_deg=-0.117, summary_delta_var_deg2=0.8e-4, summary_n=5)
    )
    assert not isinstance(paper_form, str)
    assert (paper_form.delta_mean_deg, paper_form.delta_var_deg2, paper_form.n_obs) == (
        -0.117,
        0.8e-4,
        5,
    )
    failed = trial_input(make_trial(status="failed", failure_reason="bus silence"))
    assert failed == "trial failed: bus silence"
    assert "no observations" in str(trial_input(make_trial()))


def test_import_without_a_plan_uses_the_example_settings_and_says_so(tmp_path: Path) -> None:
    stored = import_paper(tmp_path)
    with stored.sessions() as session:
        inputs = stored_inputs(load_campaign(session, stored.campaign_id))
    assert inputs.settings == SEED_000_SETTINGS  # the paper's own metadata, so equal
    assert len(inputs.notes) == 2 and "[analysis]" in inputs.notes[0]
    assert [t.index for t in inputs.trials] == [1, 2, 3, 4, 5, 6] and inputs.left_out == ()


def runs(stored: Stored) -> int:
    with stored.sessions() as session:
        return session.scalar(select(func.count(AnalysisRun.id)))


def test_a_run_is_recorded_once_per_distinct_result(tmp_path: Path) -> None:
    stored = import_paper(tmp_path)
    first = analyze_stored(stored.sessions, stored.campaign_id)
    again = analyze_stored(stored.sessions, stored.campaign_id)
    with stored.sessions() as session:
        row = session.get(AnalysisRun, again.run_id)
        results = {k: v for k, v in row.results_json.items() if k != "stored"}
        assert results == json.loads(json.dumps(first.analysis.to_dict()))
        assert row.inputs_hash == first.inputs.sha256()
    assert again.run_id == first.run_id and runs(stored) == 1
    with stored.sessions.begin() as session:
        trial = session.scalar(select(Trial).where(Trial.index == 2))
        trial.summary_delta_mean_deg = 0.22
    changed = analyze_stored(stored.sessions, stored.campaign_id)
    assert changed.inputs.sha256() != first.inputs.sha256()
    assert changed.run_id != first.run_id and runs(stored) == 2


def test_a_recorded_analysis_is_not_reused_by_other_analysis_code(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Before: keyed by the version string alone, an analysis recorded by earlier code (same
    version, another commit) was rebuilt from its record: stale texts and numbers."""
    stored = import_paper(tmp_path)
    first = analyze_stored(stored.sessions, stored.campaign_id)
    assert stored_module.stored_analysis(stored.sessions, stored.campaign_id).run_id == first.run_id
    digest = first.inputs.sha256()
    monkeypatch.setattr(stored_module, "analysis_code_sha256", lambda: "other code")
    later = stored_module.stored_analysis(stored.sessions, stored.campaign_id)
    assert later.run_id is None and later.inputs.sha256() != digest


def test_a_writer_holding_the_lock_meanwhile_delays_the_run_and_fails_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """While the analysis computes, another process (a campaign acquiring into the same file)
    takes the write lock, writes and commits a moment later. The analysis read before that
    commit; its run is recorded once the lock is free (one transaction spanning the read and
    the write fails here: "database is locked", its snapshot being stale)."""
    stored = import_paper(tmp_path)
    acquisition = sqlite3.connect(stored.path, isolation_level=None, check_same_thread=False)
    compute = stored_module.analyze_campaign
    released = threading.Event()

    def holding_the_lock(*args: object, **kwargs: object) -> object:
        acquisition.execute("BEGIN IMMEDIATE")
        acquisition.execute("UPDATE campaign SET operator = 'acquiring' WHERE id = 1")

        def commit() -> None:
            acquisition.execute("COMMIT")
            released.set()

        threading.Timer(0.3, commit).start()
        return compute(*args, **kwargs)

    monkeypatch.setattr(stored_module, "analyze_campaign", holding_the_lock)
    run = analyze_stored(stored.sessions, stored.campaign_id)
    assert released.is_set()  # the run's write waited for the other writer's commit
    with stored.sessions() as session:
        assert session.get_one(Campaign, stored.campaign_id).operator == "acquiring"
        assert session.get_one(AnalysisRun, run.run_id).inputs_hash == run.inputs.sha256()
    assert runs(stored) == 1
    acquisition.close()


def test_a_campaign_that_cannot_be_analysed_still_gets_its_report(tmp_path: Path) -> None:
    stored = import_paper(tmp_path)
    with stored.sessions.begin() as session:
        for trial in session.scalars(select(Trial).where(Trial.index <= 2)):
            trial.status, trial.failure_reason = "failed", "stand refused 'set'"
    report = stored.report()
    assert report.analysis is None
    assert "fit trials" in str(report.analysis_error)
    assert {i.verdict for i in report.compliance.items} == {NOT_ASSESSED}
    assert [t.analysed for t in report.inputs.acquisition] == [False] * 6
    assert report.inputs.identification.analysis_run is None and runs(stored) == 0
    doc = json.loads(report_json(report))
    assert doc["analysis"] is None and doc["analysis_error"] == report.analysis_error
    html = render_html(report)
    assert "could not be analysed" in html and "stand refused &#39;set&#39;" in html
