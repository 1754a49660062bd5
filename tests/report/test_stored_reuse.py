"""The stored analysis reused: a typed round trip (analysis, signal section, heading traces to
the run's JSON and back), a report of an unchanged campaign rebuilt from its run without
fitting again, and a changed observation, raw log or software version computing it again."""

import json
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy import func, select

from gyrostand.analysis.campaign import CampaignAnalysis
from gyrostand.analysis.nlsq import FitResult
from gyrostand.analysis.typed_json import decode, encode
from gyrostand.db.models import AnalysisRun, Observation
from gyrostand.report import stored as stored_module
from gyrostand.report.signal import SignalSection
from gyrostand.report.stored import (
    analyze_stored,
    compute_stored,
    read_campaign,
    stored_analysis,
)

from .conftest import Simulated, run_simulated


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Simulated:
    return run_simulated(tmp_path_factory.mktemp("reuse"))


def same(a: Any, b: Any, where: str = "") -> None:
    """`a` and `b` equal field by field, of the same types (arrays element-wise, NaN = NaN)."""
    assert type(a) is type(b), where
    if is_dataclass(a):
        for f in fields(a):
            same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), where
    elif isinstance(a, tuple | list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            same(a[k], b[k], f"{where}[{k}]")
    elif isinstance(a, float):
        assert a == b or (np.isnan(a) and np.isnan(b)), where
    else:
        assert a == b, where


def test_the_analysis_and_its_signal_section_round_trip_typed(sim: Simulated) -> None:
    computed = compute_stored(read_campaign(sim.sessions, sim.campaign_id))
    for value, cls in ((computed.analysis, CampaignAnalysis), (computed.signal, SignalSection)):
        text = json.dumps(encode(value), allow_nan=False)
        same(value, decode(cls, json.loads(text)), cls.__name__)
    assert computed.signal.noise is not None  # the round trip covered the noise arrays


def test_non_finite_floats_and_arrays_survive_and_a_wrong_shape_is_refused() -> None:
    fit = FitResult(
        names=("C",),
        estimates={"C": 1.5},
        std_errors={"C": float("nan")},
        covariance=np.array([[np.inf]]),
        correlation=np.eye(1),
        xtx_inv=np.array([[-np.inf]]),
        jacobian=np.zeros((2, 1)),
        fitted=np.array([0.1, np.nan]),
        residuals=np.array([1, 2], dtype=np.int64),
        rss=float("inf"),
        s2=0.5,
        n=2,
        dof=1,
        iterations=3,
        converged=False,
        reason="r",
        path="gauss-newton",
        fallback_reason=None,
        condition_number=1e10,
        log=(),
    )
    same(fit, decode(FitResult, json.loads(json.dumps(encode(fit), allow_nan=False))))
    with pytest.raises(TypeError):
        decode(FitResult, encode(fit) | {"n": "two"})


def counting_fits(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    calls: list[int] = []
    fit = stored_module.analyze_campaign

    def counted(*args: object, **kwargs: object) -> object:
        calls.append(1)
        return fit(*args, **kwargs)

    monkeypatch.setattr(stored_module, "analyze_campaign", counted)
    return calls


def runs(sim: Simulated) -> int:
    with sim.sessions() as session:
        return session.scalar(select(func.count(AnalysisRun.id)))


def test_an_unchanged_campaign_reuses_its_run_and_a_changed_one_fits_again(
    sim: Simulated, monkeypatch: pytest.MonkeyPatch
) -> None:
    fits = counting_fits(monkeypatch)
    first = analyze_stored(sim.sessions, sim.campaign_id)
    before = runs(sim)
    assert len(fits) == 1 and first.run_id is not None
    again = stored_analysis(sim.sessions, sim.campaign_id)
    assert len(fits) == 1, "a matching run was fitted again"
    assert again.run_id == first.run_id and runs(sim) == before
    same(first.analysis, again.analysis, "analysis")
    same(first.signal, again.signal, "signal")
    same(first.traces, again.traces, "traces")
    assert any(t is not None and t.frames for t in again.traces.values())
    report = sim.report()  # the report too rebuilds it
    assert len(fits) == 1 and report.inputs.identification.analysis_run == first.run_id

    monkeypatch.setattr(stored_module, "SOFTWARE_VERSION", "another version")
    assert stored_analysis(sim.sessions, sim.campaign_id).run_id is None and len(fits) == 2
    monkeypatch.undo()
    fits = counting_fits(monkeypatch)

    with sim.sessions.begin() as session:  # one observation changed: stale
        observation = session.scalars(select(Observation).order_by(Observation.id)).first()
        observation.value_deg += 0.01
    changed = analyze_stored(sim.sessions, sim.campaign_id)
    assert len(fits) == 1 and changed.inputs.sha256() != first.inputs.sha256()
    assert changed.run_id != first.run_id and runs(sim) == before + 1
    assert changed.analysis.trials != first.analysis.trials


def test_a_changed_raw_log_makes_the_run_stale(
    sim: Simulated, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    digest = stored_analysis(sim.sessions, sim.campaign_id).inputs.sha256()
    data = sim.log.read_bytes()
    try:
        sim.log.write_bytes(data + b"\0")  # no longer the recorded SHA-256
        fits = counting_fits(monkeypatch)
        stale = stored_analysis(sim.sessions, sim.campaign_id)
        assert stale.inputs.sha256() != digest and stale.run_id is None and len(fits) == 1
        assert stale.signal.record is None  # the reading is not taken from a mismatching log
    finally:
        sim.log.write_bytes(data)


def test_the_forecasts_worst_cases_are_recorded_and_reused(
    sim: Simulated, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The envelope's worst case of the forecast, found for each shipped profile when the
    analysis is recorded, comes back with the run, and the report takes it from there: the
    same compliance as a search made at report time, without searching."""
    from gyrostand.analysis import forecast
    from gyrostand.report import SHIPPED_PROFILES
    from gyrostand.report.compliance import assess, load_profile, worst_cases

    first = analyze_stored(sim.sessions, sim.campaign_id)
    again = stored_analysis(sim.sessions, sim.campaign_id)
    assert again.run_id == first.run_id and first.analysis.forecasts
    same(first.worst_cases, again.worst_cases, "worst cases")
    searched = {p: worst_cases(load_profile(p), again.analysis) for p in SHIPPED_PROFILES}
    assert set(again.worst_cases) == {w for found in searched.values() for w in found}
    fresh = {p: assess(load_profile(p), again.analysis) for p in SHIPPED_PROFILES}

    def no_search(*args: object, **kwargs: object) -> object:
        raise AssertionError("the worst case was searched again")

    monkeypatch.setattr(forecast, "envelope_worst", no_search)
    for p in SHIPPED_PROFILES:
        reused = assess(load_profile(p), again.analysis, worst_cases=again.worst_cases)
        assert reused == fresh[p]
    report = sim.report()  # the report of the recorded run searches nothing
    assert report.compliance.predictions == fresh["imo-a424"].predictions
    assert report.compliance.predictions[0].evidence == "rolling_error_forecast"
