"""The report as one JSON document: every number the report prints, for machines and for diffing
two reports. Deterministic: the same database gives the same text except ``generated_at``.

Schema ``gyrostand.report/5`` (plain JSON types; absent values are null). Version 2 added
``signal``; version 3 the laboratory items of ``identification`` (the plan's [report] table),
``plan.settle_criterion`` (text, in place of the band's three numbers), ``signatures``
{recorded_operator}, the parameters' ``fit.confidence_intervals`` and ``conformity``; version 4
``draft``; version 5 one decision per requirement under a stated decision rule (``compliance``
``decision``, ``decision_rule``, ``predictions``; per item ``uncertainty_deg``,
``acceptance_limit_deg``, ``verified_by``), ``conformity.decision_rule``; ``title``,
``missing``, ``end_of_report``, ``compass_heading`` (the still-series means, in words),
``identification.manufacturer`` and ``.test_dates``; the
extrapolation of every forecast beyond the trials' motion (``forecast.tested``, ...).

- ``schema``, ``title`` (instrument, serial, report number), ``generated_at`` (the only
  wall-clock field: the date of issue), ``draft`` (true: not for issue), ``missing`` (the items
  of ISO/IEC 17025 7.8.2 the report lacks: when any, it is a draft), ``end_of_report``;
- ``conformity``: verdict (the overall decision: PASS, FAIL, INCONCLUSIVE or NOT ASSESSED),
  statement (what it covers; the word not repeated), decision_rule (the rule in words), reasons
  (`report.build.Conformity`);
- ``identification``: the fields of `report.model.Identification`;
- ``plan``: `PlanSummary` (n_obs, trials [index, role, direction_deg, amplitude_cm, period_s],
  windows, settle criterion, notes, plan_toml);
- ``acquisition``: ``trials`` (`TrialAcquisition` each, the latest attempt of each trial:
  commanded and measured K/A/tau, motion_source and meas_amplitude_se_cm, meas_period_se_s
  (whose measured A and tau the analysis applies: inclinometer, drive position, stand report,
  stated or commanded), status, observations per series, frames used/lost, flagged
  observations, analysed, attempt), ``events`` (`EventRecord` each, trial_attempt set when the
  trial was retried), ``raw_log_note``, ``left_out`` (every trial attempt the analysis does not
  use: index, attempt, role, status, reason, superseded_by), ``records`` (per trial: series with
  settle start/end ms, settle estimate, observations k/value/window, ``settle``: how it settled
  {criterion, standard_error_deg, band_s, band_measured, saved_s} or null; ``trace``: {frames,
  bins, t_first_ms, t_last_ms} or null: the binned heading itself is only plotted);
- ``trial_table``: `report.build.TrialRow` each;
- ``checks``: the method's checks as every page states them (`report.build.MethodCheck`: name,
  verdict, caveat when an assumption they rest on fails); Fisher's on the trial means
  (``analysis.adequacy.basis``, ``.decision``);
- ``degrees_of_freedom``: `report.build.DegreesOfFreedom` (nu_trial, n_obs, k, n_fit, m, dof_r,
  dof_e, q, t_prediction, t_s_e_bound, text) or null;
- ``analysis``: `CampaignAnalysis.to_dict()` (schema gyrostand.analysis/1, keys documented in
  `analysis.campaign`), or null with ``analysis_error`` saying why the campaign could not be
  analysed;
- ``forecast``: null, or {tested (the trials' motion: amplitude_cm, period_s,
  acceleration_m_s2 as [smallest, largest]), point_extrapolation ({factor, text} when the plan's
  forecast lies beyond it, else null), fit_dof (nu_r of the fit), point (forecast at the plan's
  conditions, as in analysis.forecasts[0]),
  amplitude_note, grid {course_deg, roll_deg, period_s, latitude_deg, arm_cm, motion, q,
  alpha_deg and half_width_deg as nested lists indexed [course][roll][period][latitude]}, table,
  worst_by_period, worst (grid points: course_deg, direction_deg, roll_deg, period_s,
  latitude_deg, alpha_deg, half_width_deg, bound_deg, extrapolation: {factor, text} or null)};
- ``compliance``: profile_id, profile_name, edition, source, caution, envelope,
  envelope_source, envelope_verified, site_latitude_deg, decision_rule ("simple" or "guarded",
  ILAC-G8:09/2019 4.2.1-4.2.2) and decision_rule_text, decision (PASS, FAIL, INCONCLUSIVE or NOT
  ASSESSED: `Compliance.decision`), summary (counts, the decision word not repeated), items (one
  decision per measured requirement: id, clause, requirement, evidence, source, verified,
  verified_by (who at the laboratory, when, against which edition; null: nobody), stated_limit_deg,
  secant_latitude, limit_deg, limit_text, value_deg, uncertainty_deg (expanded, about 95 %),
  uncertainty_text, acceptance_limit_deg (limit - guard band), unit (of those values and limits,
  whatever their keys say: "h" for the settling time, else "deg"), verdict (PASS, FAIL, UNVERIFIED
  or NOT ASSESSED), detail, exceeds, worst: null), predictions (the forecasts, the same keys,
  verdict PREDICTION, exceeds: the predicted bound beyond the limit, worst: the forecast's worst
  case over the envelope {course_deg, direction_deg, angle_deg, period_s, acceleration_m_s2,
  latitude_deg, amplitude_cm, alpha_deg, half_width_deg, ratio, motion, arm_cm, q},
  extrapolation: {factor, text} when the worst case lies beyond the trials' motion);
- ``signal`` (section 10, `report.signal.SignalSection.to_dict`): ``record`` {source,
  start_ms, dt_s, n, duration_s, frames, filled} or null, record_note, trend_deg_per_h,
  ``noise`` (`analysis.noise.NoiseCharacterisation.to_dict`: correlation {lag_s, covariance,
  dt_s, n}, exponential and smooth models {variance, decay_per_s, frequency_rad_s,
  white_variance, correlation_time_s, derivative_variance}, harmonics {frequency_hz, psd,
  background, threshold, dof, false_alarm, harmonics [frequency_hz, amplitude,
  amplitude_from_correlation, peak_to_background, false_alarm_probability]}, allan {tau_s,
  deviation, n_terms}, sampling {interval_s, factor, ...}) or null with noise_error,
  reading_interval_ok, ``observations`` (trial, j, window_s, step_s, correlation,
  max_correlation, correlated), correlated_observations, ``settle`` (trial, j, started_ms,
  done_ms, settle_s, estimate_deg, observed_mean_deg, offset_deg, criterion,
  standard_error_deg, band_s, band_measured, saved_s), time_saved_s (sum of the known savings),
  ``acceptance`` {criterion {tolerance_deg, duration_s, max_risk}, excursions
  (`analysis.excursions.ExcursionAcceptance.to_dict`: lower, upper, mean, duration_s, sigma,
  p_start_inside, p_no_excursion, method ("kolmogorov": exact; "vanmarcke": approximation
  within 10 % of simulation; "poisson": the same within 10 %, or a lower bound when is_bound;
  "poisson-estimate": best estimate within 17 %; "rice": lower bound), is_bound, risk, method_note,
  ``rice`` {sigma_dot, upcrossings_upper, downcrossings_lower, mean_excursions, bandwidth,
  p_poisson, p_vanmarcke} or null), risk (an upper bound when is_bound),
  tolerance_for_max_risk_deg, verdict, detail} or null, acceptance_note;
- ``signatures``: recorded_operator; tested_by, checked_by: [name, date] signed off at the
  operator station, or null (the signatures themselves are by hand).
"""

import json
from dataclasses import asdict
from typing import Any

from gyrostand.analysis.campaign import json_safe
from gyrostand.report.build import GridPoint, Report
from gyrostand.report.model import TrialRecord


def _point(p: GridPoint) -> dict[str, Any]:
    return {**asdict(p), "bound_deg": p.bound_deg}


def _record(record: TrialRecord) -> dict[str, Any]:
    trace = record.trace
    return {
        "trial": record.index,
        "series": [asdict(s) for s in record.series],
        "trace": None
        if trace is None
        else {
            "frames": trace.frames,
            "bins": int(trace.t_ms.size),
            "t_first_ms": float(trace.t_ms[0]) if trace.t_ms.size else None,
            "t_last_ms": float(trace.t_ms[-1]) if trace.t_ms.size else None,
        },
    }


def report_document(report: Report) -> dict[str, Any]:
    """The report as plain JSON types (see the module docstring for the keys)."""
    inputs, f = report.inputs, report.forecast
    forecast = None
    if f is not None:
        g = f.grid
        forecast = {
            "tested": asdict(f.tested),
            "point_extrapolation": None
            if f.point_extrapolation is None
            else asdict(f.point_extrapolation),
            "fit_dof": f.fit_dof,
            "point": {
                **asdict(f.point),
                "lower_deg": f.point.interval_deg[0],
                "upper_deg": f.point.interval_deg[1],
            },
            "amplitude_note": f.amplitude_note,
            "grid": {
                "course_deg": g.course_deg,
                "roll_deg": g.roll_deg,
                "period_s": g.period_s,
                "latitude_deg": g.latitude_deg,
                "arm_cm": g.arm_cm,
                "motion": g.motion,
                "q": g.q,
                "alpha_deg": g.alpha_deg,
                "half_width_deg": g.half_width_deg,
            },
            "table": [_point(p) for p in f.table],
            "worst_by_period": [_point(p) for p in f.worst_by_period],
            "worst": _point(f.worst),
        }
    return json_safe(
        {
            "schema": report.schema,
            "title": report.title,
            "generated_at": report.generated_at,
            "draft": report.draft,
            "missing": list(report.missing),
            "end_of_report": report.end_of_report,
            "compass_heading": report.compass_heading,
            "conformity": asdict(report.conformity),
            "identification": asdict(inputs.identification),
            "plan": asdict(inputs.plan),
            "acquisition": {
                "trials": [asdict(t) for t in inputs.acquisition],
                "events": [asdict(e) for e in inputs.events],
                "raw_log_note": inputs.raw_log_note,
                "left_out": [asdict(t) for t in inputs.left_out],
                "records": [_record(r) for r in inputs.records],
            },
            "trial_table": [asdict(t) for t in report.trials],
            "checks": [asdict(c) for c in report.checks],
            "degrees_of_freedom": None if report.dof is None else asdict(report.dof),
            "analysis": None if report.analysis is None else report.analysis.to_dict(),
            "analysis_error": report.analysis_error,
            "forecast": forecast,
            "compliance": {
                **asdict(report.compliance),
                "decision": report.compliance.decision,
                "decision_rule_text": report.compliance.decision_rule_text,
                "summary": report.compliance.summary,
            },
            "signal": report.signal.to_dict(),
            "signatures": asdict(inputs.signatures),
        }
    )


def report_json(report: Report) -> str:
    """The JSON document as text (indented, UTF-8, no NaN)."""
    return json.dumps(report_document(report), indent=2, ensure_ascii=False, allow_nan=False) + "\n"
