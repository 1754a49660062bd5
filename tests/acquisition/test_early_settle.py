"""Early settle ([settle] method = "estimate", seed 003 in acquisition).

- The rule on exact (noise-free) block means of a damped transient: the estimate is the true
  settle point and observing starts at the first block from which the true transient stays within
  the tolerance over the N windows to come; the band time predicted from the fit is the band
  criterion applied to the true block means.
- On the lockstep simulated stand (the 84-minute compass scaled to a 20-minute period, same
  damping, so the test is fast): early-settle series start earlier than band-settle series of the
  same seed and their observation means lie within the tolerance of the settled reading of model
  1.1; the rocking harmonics, averaged over whole rocking periods, do not move the decision.
- What is stored (series columns, "early settle" event) and what the report shows.
- Plan validation of the new keys: one clear error each, with its field path.
"""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from gyrostand.acquisition.early_settle import (
    MIN_BLOCKS,
    EarlySettle,
    band_settled,
    hold_blocks,
    predict_band_settle_s,
)
from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.store import CampaignStore
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.db.models import Event, Series, Trial
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.plan.model import EstimatePlan, PlanError, load_plan, parse_plan
from gyrostand.report.compliance import load_profile
from gyrostand.report.stored import campaign_report
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import CompassParams, SimConfig

from .harness import ROOT, Lockstep, NoCommands, Recorder, plan_text

# --- the rule on exact block means ------------------------------------------------------------

T0_S, ZETA, WINDOW_S, N_OBS = 5064.0, 0.7, 60.0, 5  # the simulator's compass, paper windows
SETTLED_DEG, STEP_DEG, TOL_DEG = 0.3, -0.48, 0.015
ESTIMATE = EstimatePlan(T0_S, ZETA, expected_se_deg=TOL_DEG, tolerance_fraction=1.0,
                        stable_estimates=3)  # fmt: skip
SPAN_S = N_OBS * WINDOW_S


def transient_deg(t_s: np.ndarray) -> np.ndarray:
    """Reading minus settle point after a step of the equilibrium from rest (seed 003 eq 2)."""
    w, xi = ESTIMATE.omega_rad_s, ESTIMATE.damping_per_s
    return STEP_DEG * np.exp(-xi * t_s) * (np.cos(w * t_s) + xi / w * np.sin(w * t_s))


def block_mean_deg(start_s: float, end_s: float) -> float:
    """Exact mean of the reading over a block: the integral of e^(s t), s = -xi + i omega."""
    w, xi = ESTIMATE.omega_rad_s, ESTIMATE.damping_per_s
    s = complex(-xi, w)
    integral = (np.exp(s * end_s) - np.exp(s * start_s)) / s  # of e^(-xi t) e^(i omega t)
    c = complex(1.0, -xi / w)  # cos + (xi/omega) sin = Re[(1 - i xi/omega) e^(i omega t)]
    return SETTLED_DEG + STEP_DEG * (c * integral).real / (end_s - start_s)


def test_exact_record_gives_the_settle_point_and_the_first_safe_block() -> None:
    early = EarlySettle(ESTIMATE, SPAN_S)
    k = 0
    while not early.last or not early.last.ready:
        k += 1
        start, end = (k - 1) * WINDOW_S, k * WINDOW_S
        early.add_block((start + end) / 2, block_mean_deg(start, end), end, band=False)
    check = early.last
    assert check.estimate.settle_point_deg == pytest.approx(SETTLED_DEG, abs=1e-9)
    assert check.estimate.standard_error_deg < 1e-9
    assert early.stable.t_s == (MIN_BLOCKS + ESTIMATE.stable_estimates - 1) * WINDOW_S
    # independent: the first block end from which the true transient stays within the
    # tolerance over the observation span (fine grid)
    ends = WINDOW_S * np.arange(1, 200)
    safe = [
        e for e in ends if np.abs(transient_deg(np.linspace(e, e + SPAN_S, 2000))).max() <= TOL_DEG
    ]
    assert check.t_s == safe[0] > 2000.0  # ~40 minutes: the reading, not the estimate, decides
    # the fit describes window means (what an observation is): the predicted transient is the
    # true one averaged over a window, on the rule's grid
    grid = np.linspace(check.t_s, check.t_s + SPAN_S, 64)
    window_means = [block_mean_deg(t - WINDOW_S / 2, t + WINDOW_S / 2) for t in grid]
    assert check.transient_deg == pytest.approx(
        np.abs(np.array(window_means) - SETTLED_DEG).max(), abs=1e-12
    )


def test_band_time_predicted_from_the_fit_is_the_band_criterion_on_the_true_means() -> None:
    settle = load_plan(ROOT / "examples" / "paper.toml").settle  # band 0.03, drift 0.006, 1800 s
    early = EarlySettle(ESTIMATE, SPAN_S)
    means = []
    for k in range(1, 31):  # the first half hour
        start, end = (k - 1) * WINDOW_S, k * WINDOW_S
        means.append(block_mean_deg(start, end))
        early.add_block((start + end) / 2, means[-1], end, band=False)
    predicted = predict_band_settle_s(means, WINDOW_S, 30 * WINDOW_S, early.last.estimate, settle)
    need = hold_blocks(settle, WINDOW_S)
    true_means = [block_mean_deg((k - 1) * WINDOW_S, k * WINDOW_S) for k in range(1, 361)]
    direct = next(
        k * WINDOW_S for k in range(need, 361) if band_settled(true_means[k - need : k], settle)
    )
    assert predicted == direct
    assert 3000.0 < direct < 5000.0  # it holds on the overshoot (4.6 % of the step), not later


# --- on the simulated stand -------------------------------------------------------------------

SCALED_T0_S = 1200.0  # the 84-minute compass at 1/4.2 scale, same damping: a fast test
EARLY_SETTLE = f"""[settle]
method = "estimate"
undamped_period_s = {SCALED_T0_S}
damping_ratio = {ZETA}
expected_se_deg = 0.015
tolerance_fraction = 1.0
drift_deg = 0.006
"""
BAND_SETTLE = "[settle]\ndrift_deg = 0.006\n"


def scaled_plan(settle: str, database: str = "runs/test.sqlite") -> str:
    """Two trials (steps of +0.41 and -0.47 deg), band 0.03 deg held 420 s (1800 s scaled)."""
    text = plan_text(n_obs=4, hold_s=420.0, database=database)
    return text.replace("band_deg = 0.05", "band_deg = 0.03").replace("[settle]\n", settle)


def scaled_config(seed: int = 1, harmonic_deg_per_g: float = 1.0) -> SimConfig:
    compass = CompassParams(
        undamped_period_s=SCALED_T0_S,
        damping_ratio=ZETA,
        harmonic_p_deg_per_g=harmonic_deg_per_g,
        harmonic_2p_deg_per_g=harmonic_deg_per_g / 2,
    )
    return SimConfig(compass=compass, seed=seed)


def run(settle: str, config: SimConfig) -> tuple[Recorder, Lockstep, Engine]:
    sink, sim = Recorder(), Lockstep(config)
    engine = Engine(parse_plan(scaled_plan(settle)), sink, sim)
    sim.run(engine)
    assert engine.outcome == "completed"
    return sink, sim, engine


def settle_s(sink: Recorder) -> dict[tuple[int, int], float]:
    started = {(a[0], a[1]): a[2] for a in sink.of("series_settling")}
    return {(a[0], a[1]): (a[2] - started[(a[0], a[1])]) / 1000 for a in sink.of("series_settled")}


def errors_deg(sink: Recorder, config: SimConfig) -> dict[tuple[int, int], float]:
    """Series mean minus the settled reading of model 1.1 (seed 000 eq 1.1)."""
    c = config.compass
    plan = parse_plan(scaled_plan(BAND_SETTLE))
    out = {}
    for t in plan.trials:
        shift = c.settled_shift_deg(t.direction_deg, t.amplitude_cm, t.period_s)
        for j, truth in ((1, c.heading_deg), (2, c.heading_deg + shift)):
            values = [o.value_deg for o in sink.observations if (o.trial, o.j) == (t.index, j)]
            out[(t.index, j)] = float(np.mean(values)) - truth
    return out


@pytest.fixture(scope="module")
def band() -> tuple[Recorder, Lockstep, Engine]:
    return run(BAND_SETTLE, scaled_config())


@pytest.fixture(scope="module")
def early() -> tuple[Recorder, Lockstep, Engine]:
    return run(EARLY_SETTLE, scaled_config())


def test_early_series_start_earlier_and_stay_within_the_tolerance(band, early) -> None:
    waited, early_s = settle_s(band[0]), settle_s(early[0])
    assert waited.keys() == early_s.keys() and len(waited) == 4
    assert all(early_s[key] < waited[key] for key in waited)
    transients = [key for key in waited if key != (1, 1)]  # (1, 1): the compass starts settled
    assert all(early_s[key] < 0.7 * waited[key] for key in transients)
    assert early[1].stand.stand_time_s < 0.75 * band[1].stand.stand_time_s
    config = scaled_config()
    early_err, band_err = errors_deg(early[0], config), errors_deg(band[0], config)
    tol = 0.015  # tolerance_fraction x expected_se_deg
    assert max(abs(e) for e in early_err.values()) <= tol
    rms = {k: math.sqrt(np.mean(np.square(list(e.values())))) for k, e in
           (("early", early_err), ("band", band_err))}  # fmt: skip
    assert rms["early"] <= rms["band"]  # the band criterion settles on the overshoot


def test_the_outcome_records_estimate_and_time_saved(band, early) -> None:
    sink = early[0]
    events = {(a[3], a[4]): a for a in sink.of("event") if a[0] == "early settle"}
    settled = {(a[0], a[1]): a for a in sink.of("series_settled")}
    waited, early_s = settle_s(band[0]), settle_s(sink)
    c = scaled_config().compass
    truth = {1: c.heading_deg, 2: None}
    assert all(a[3].criterion == "band" for a in band[0].of("series_settled"))
    for key, event in events.items():
        outcome = settled[key][3]
        assert event[5] == settled[key][2]  # the event tells the decision at its stand time
        assert f"settle point {outcome.estimate_deg:.5f} deg" in event[2]
        assert outcome.criterion == "estimate"
        assert outcome.settle_s == early_s[key]
        assert outcome.standard_error_deg <= 0.015
        assert outcome.stable_since_s <= outcome.settle_s
        if key[1] == 1:
            assert outcome.estimate_deg == pytest.approx(truth[1], abs=0.015)
        # the band time predicted from the fit vs the band criterion on the same seed's readings
        assert not outcome.band_measured
        assert outcome.band_s == pytest.approx(waited[key], rel=0.15)
        assert outcome.saved_s == pytest.approx(outcome.band_s - outcome.settle_s)
        assert outcome.saved_s > 0
    assert len(events) == 4


def test_rocking_harmonics_are_averaged_out_by_whole_period_blocks(early) -> None:
    """Ten times the reading oscillation at p and 2p (0.27 deg at p for trial 1) changes
    neither when the series start nor, beyond quantisation, what they estimate."""
    loud, _, _ = run(EARLY_SETTLE, scaled_config(harmonic_deg_per_g=10.0))
    assert settle_s(loud) == settle_s(early[0])
    quiet_est = {(a[0], a[1]): a[3].estimate_deg for a in early[0].of("series_settled")}
    loud_est = {(a[0], a[1]): a[3].estimate_deg for a in loud.of("series_settled")}
    assert all(abs(loud_est[k] - quiet_est[k]) < 2e-3 for k in quiet_est)


def test_stored_and_reported(tmp_path: Path) -> None:
    path = tmp_path / "early.sqlite"
    sessions = open_database(sqlite_url(path))
    plan = parse_plan(scaled_plan(EARLY_SETTLE, database=str(path)))
    store = CampaignStore.create(sessions, plan)
    sim = Lockstep(scaled_config())
    engine = Engine(plan, store, sim, store.progress())
    sim.run(engine)
    store.set_status(engine.outcome)
    with sessions() as session:
        series = session.execute(
            select(Trial.index, Series).join(Series).where(Trial.campaign_id == store.campaign_id)
        ).all()
        events = session.scalars(select(Event).where(Event.kind == "early settle")).all()
        assert {e.series_id for e in events} == {s.id for _, s in series}
        stored = {}
        for index, s in series:
            outcome = SettleOutcome.from_dict(s.settle_outcome)
            assert outcome.criterion == "estimate" and outcome.standard_error_deg <= 0.015
            assert s.settle_estimate_deg == outcome.estimate_deg
            assert (s.settle_done_ms - s.settle_started_ms) / 1000 == outcome.settle_s
            assert outcome.saved_s > 0
            stored[(index, s.j)] = (s.settle_estimate_deg, outcome.saved_s)
    assert len(stored) == 4
    with sessions.begin() as session:
        report = campaign_report(
            session,
            store.campaign_id,
            database=str(path),
            profile=load_profile(),
            generated_at="now",
        )
    rows = {(r.trial, r.j): r for r in report.signal.settle}
    assert rows.keys() == stored.keys()
    for key, (estimate, saved) in stored.items():
        assert rows[key].criterion == "estimate"
        assert rows[key].estimate_deg == estimate and rows[key].saved_s == saved


# --- plan validation --------------------------------------------------------------------------


def test_estimate_plan_derives_the_transient() -> None:
    plan = parse_plan(scaled_plan(EARLY_SETTLE)).settle
    assert plan.method == "estimate" and plan.estimate is not None
    w0 = 2 * math.pi / SCALED_T0_S
    assert plan.estimate.omega_rad_s == pytest.approx(w0 * math.sqrt(1 - ZETA**2))  # eq 2
    assert plan.estimate.damping_per_s == pytest.approx(ZETA * w0)
    assert plan.estimate.tolerance_deg == pytest.approx(0.015)
    assert plan.estimate.stable_estimates == 3
    band = parse_plan(scaled_plan(BAND_SETTLE)).settle
    assert band.method == "band" and band.estimate is None
    paper_early = load_plan(ROOT / "examples" / "paper-early.toml")
    paper = load_plan(ROOT / "examples" / "paper.toml")
    assert paper_early.trials == paper.trials
    shared = {"band_deg", "drift_deg", "hold_s", "max_wait_s"}
    assert paper_early.settle.model_dump(include=shared) == paper.settle.model_dump(include=shared)
    assert paper.settle.method == "band" and paper.settle.estimate is None


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (("method = \"estimate\"", "method = \"fast\""),
         "[settle] method: must be one of 'band', 'estimate', not 'fast'"),
        ((f"undamped_period_s = {SCALED_T0_S}\n", ""), "[settle] undamped_period_s: missing"),
        ((f"undamped_period_s = {SCALED_T0_S}", "undamped_period_s = -5"),
         "[settle] undamped_period_s: must be > 0"),
        ((f"damping_ratio = {ZETA}", "damping_ratio = 1.0"), "[settle] damping_ratio: must be < 1"),
        (("expected_se_deg = 0.015", "expected_se_deg = \"small\""),
         "[settle] expected_se_deg: must be a finite number"),
        (("tolerance_fraction = 1.0", "tolerance_fraction = 1.5"),
         "[settle] tolerance_fraction: must be <= 1"),
        (("drift_deg", "stable_estimates = 1\ndrift_deg"),
         "[settle] stable_estimates: must be >= 2"),
        (("drift_deg", "stable_estimate = 3\ndrift_deg"), "[settle] stable_estimate: unknown key"),
        (("method = \"estimate\"\n", ""),
         "[settle] undamped_period_s: only applies when method = 'estimate'"),
    ],
)  # fmt: skip
def test_bad_early_settle_keys_are_one_clear_error(edit: tuple[str, str], expected: str) -> None:
    old, new = edit
    text = scaled_plan(EARLY_SETTLE)
    assert old in text
    with pytest.raises(PlanError) as info:
        parse_plan(text.replace(old, new, 1))
    problems = info.value.problems
    if expected.endswith("only applies when method = 'estimate'"):  # one per key
        assert problems[0] == expected and len(problems) == 4
        assert all(re.fullmatch(r"\[settle\] \w+: only applies .*", p) for p in problems)
    else:
        assert problems == [expected]


def test_replay_in_other_batches_takes_the_same_decisions(early) -> None:
    live, sim, _ = early
    sink = Recorder()
    engine = Engine(parse_plan(scaled_plan(EARLY_SETTLE)), sink, NoCommands())
    decoder = BatchDecoder(Codec())
    for start in range(0, len(sim.stream), 977):
        chunk = sim.stream[start : start + 977]
        engine.feed(decoder.decode(RawFrames.from_messages(start, chunk)))
    assert engine.outcome == "completed"
    assert sink.calls == live.calls


def test_timeout_says_what_the_estimate_last_saw() -> None:
    """A plan claiming a transient four times slower than the compass's never trusts the
    estimate within the wait: the trial fails with the rule's last figures."""
    settle = EARLY_SETTLE.replace(f"undamped_period_s = {SCALED_T0_S}", "undamped_period_s = 4800")
    text = scaled_plan(settle).replace("max_wait_s = 3600.0", "max_wait_s = 1500.0")
    sink, sim = Recorder(), Lockstep(scaled_config())
    engine = Engine(parse_plan(text), sink, sim)
    sim.run(engine)
    failures = [a[2] for a in sink.of("event") if a[0] == "settle timeout"]
    assert failures and all(
        re.fullmatch(r"not settled within 1500 s \(estimate: SE [\d.]+ deg, .*tolerance "
                     r"0\.01500 deg\)", f)
        for f in failures
    )  # fmt: skip
