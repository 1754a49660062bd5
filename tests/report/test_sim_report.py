"""The report of a simulated campaign with a raw CAN log: heading records from the log (checked
against the frames decoded one by one by the cantools codec), acquisition facts from the store,
and a tampered log that is refused."""

import json
from pathlib import Path

import numpy as np
import pytest

from gyrostand.report.build import Report
from gyrostand.report.html import render_html
from gyrostand.report.json_doc import report_json
from gyrostand.stand.protocol import Codec, HeadingFrame

from .conftest import SIM_TRIALS, Simulated, run_simulated


def headings_in(simulated: Simulated, span: tuple[float, float]) -> np.ndarray:
    """Valid headings (deg) inside a stand-time span, decoded frame by frame with cantools."""
    codec = Codec()
    frames = (codec.decode(m) for m in simulated.stream)
    return np.array(
        [
            f.heading_deg
            for f in frames
            if isinstance(f, HeadingFrame) and f.valid and span[0] <= f.stand_time_ms <= span[1]
        ]
    )


def trial_span(report: Report, index: int) -> tuple[float, float]:
    record = next(r for r in report.inputs.records if r.index == index)
    times = [e.stand_time_ms for e in report.inputs.events if e.trial_index == index]
    for s in record.series:
        times += [s.settle_started_ms, s.settle_done_ms]
        times += [t for o in s.observations for t in (o.window_start_ms, o.window_end_ms)]
    times = [t for t in times if t is not None]
    return min(times), max(times)


def test_heading_records_come_from_the_raw_log(
    simulated: Simulated, simulated_report: Report
) -> None:
    ident = simulated_report.inputs.identification
    assert ident.raw_log_check == "verified" and ident.source == "stand"
    assert ident.stand == (
        "simulated gyrocompass and roll stand on a virtual CAN bus (a software model in place "
        "of the hardware), seed 1, "
        "virtual time (stand time follows the acquisition: repeatable for a seed)"
    )
    assert len(simulated_report.inputs.records) == len(SIM_TRIALS)
    for record in simulated_report.inputs.records:
        trace = record.trace
        assert trace is not None
        expected = headings_in(simulated, trial_span(simulated_report, record.index))
        assert trace.frames == expected.size > 1000
        assert trace.min_deg.min() == pytest.approx(expected.min(), abs=1e-9)
        assert trace.max_deg.max() == pytest.approx(expected.max(), abs=1e-9)
        assert np.all(np.diff(trace.t_ms) > 0) and trace.t_ms.size <= 600
        # the stored observations are window means of these very frames
        values = [o.value_deg for s in record.series for o in s.observations]
        assert expected.min() <= min(values) and max(values) <= expected.max()


def test_acquisition_summary_matches_the_store(simulated_report: Report) -> None:
    rows = simulated_report.inputs.acquisition
    assert [(t.cmd_direction_deg, t.cmd_amplitude_cm, t.cmd_period_s, t.role) for t in rows] == [
        tuple(t) for t in SIM_TRIALS
    ]
    for t in rows:
        assert t.status == "completed" and t.analysed
        assert (t.observations_before, t.observations_under) == (4, 4)
        assert t.meas_amplitude_cm == pytest.approx(t.cmd_amplitude_cm, rel=0.05)
        assert t.meas_period_s == pytest.approx(t.cmd_period_s, rel=0.05)
        assert t.frames_used is not None and t.frames_used > 0 and t.frames_lost == 0
    kinds = {e.kind for e in simulated_report.inputs.events}
    assert "command" in kinds
    assert simulated_report.inputs.plan.still_window_s == 30.0
    assert simulated_report.inputs.plan.rocking_window_periods == 4


def test_html_has_a_heading_plot_per_trial(simulated_report: Report) -> None:
    html = render_html(simulated_report)
    for index in range(1, len(SIM_TRIALS) + 1):
        assert f"Trial {index} (" in html
    figures = html.count('<img src="data:image/svg+xml;base64,')
    assert figures == len(SIM_TRIALS) + 4 + 3  # + the noise plots
    doc = json.loads(report_json(simulated_report))
    assert [r["trace"]["bins"] for r in doc["acquisition"]["records"]] == [
        r.trace.t_ms.size for r in simulated_report.inputs.records
    ]


def test_a_tampered_raw_log_is_not_used(tmp_path: Path) -> None:
    simulated = run_simulated(tmp_path)
    with simulated.log.open("ab") as f:
        f.write(b"\0")
    report = simulated.report()
    assert report.inputs.identification.raw_log_check.startswith("MISMATCH")
    assert all(r.trace is None for r in report.inputs.records)
    assert "cannot be used" in report.inputs.raw_log_note
    simulated.log.unlink()
    assert simulated.report().inputs.identification.raw_log_check == "file not found"


def test_reference_and_compass_heading_are_stated_alike(simulated_report: Report) -> None:
    """The simulator's true heading is the reference (page 1) and is not recorded with the
    observations (the settle point error says the same); the compass's own heading is given."""
    import tomllib

    plan = tomllib.loads(simulated_report.inputs.plan.plan_toml)
    true = plan.get("bus", {}).get("simulator", {}).get("compass", {}).get("heading_deg", 120.0)
    ident = simulated_report.inputs.identification
    assert ident.reference_heading == (
        f"the simulator's true heading {true:g} deg (exact; [bus.simulator.compass] "
        "heading_deg), not recorded with the observations"
    )
    settle = next(
        i for i in simulated_report.compliance.items if i.evidence == "settle_point_error"
    )
    assert settle.detail.startswith("no reference (true) heading is recorded with the campaign")
    means = [t.before.mean_deg for t in simulated_report.analysis.trials]
    assert simulated_report.compass_heading == (
        f"{min(means):.3f} to {max(means):.3f} deg, the means of the {len(means)} still series "
        "(eq 2.1)"
    )
    assert abs(min(means) - true) < 1.0  # the compass reads about the true heading
