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

import dataclasses
import math
import re
from pathlib import Path
from unittest.mock import ANY

import numpy as np
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.acquisition.early_settle import (
    KEEP_SEGMENTS,
    MIN_BLOCKS,
    EarlySettle,
    SettleCheck,
    TransientRecord,
    band_settled,
    describe,
    hold_blocks,
    predict_band_settle_s,
)
from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.acquisition.retry import RetriedTrial, retry_trials
from gyrostand.acquisition.runner import resume_store
from gyrostand.acquisition.store import CampaignStore
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.gls import shared_covariance
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.analysis.transient import TransientModel, fit_transient
from gyrostand.db.models import Event, Observation, Series, Trial
from gyrostand.db.queries import load_campaign
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.plan.model import EstimatePlan, Plan, PlanError, load_plan, parse_plan
from gyrostand.report.compliance import load_profile
from gyrostand.report.stored import campaign_report, stored_inputs
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import CompassParams, FaultParams, SimConfig

from .harness import ROOT, NoCommands, Recorder, plan_text

# --- the rule on exact block means ------------------------------------------------------------

T0_S, ZETA, WINDOW_S, N_OBS = 5064.0, 0.7, 60.0, 5  # the simulator's compass, paper windows
SETTLED_DEG, STEP_DEG, TOL_DEG = 0.3, -0.48, 0.015
ESTIMATE = EstimatePlan(T0_S, ZETA, expected_se_deg=TOL_DEG, tolerance_fraction=1.0,
                        stable_estimates=3, transient_fraction=1.0)  # fmt: skip
W0 = 2 * math.pi / T0_S
OMEGA, XI = W0 * math.sqrt(1 - ZETA**2), ZETA * W0


def block_mean_deg(start_s: float, end_s: float, settled: float = SETTLED_DEG,
                   step: float = STEP_DEG) -> float:  # fmt: skip
    """Exact mean of the reading over a block after a step of the equilibrium from rest at
    t = 0 (seed 003 eq 2): the integral of e^(s t), s = -xi + i omega."""
    s = complex(-XI, OMEGA)
    integral = (np.exp(s * end_s) - np.exp(s * start_s)) / s  # of e^(-xi t) e^(i omega t)
    c = complex(1.0, -XI / OMEGA)  # cos + (xi/omega) sin = Re[(1 - i xi/omega) e^(i omega t)]
    return settled + step * (c * integral).real / (end_s - start_s)


def exact_rule(plan: EstimatePlan = ESTIMATE) -> tuple[TransientRecord, EarlySettle]:
    record = TransientRecord()
    return record, EarlySettle(plan, record, 0, WINDOW_S, WINDOW_S, N_OBS)


def feed(record: TransientRecord, early: EarlySettle, k: int) -> None:
    start, end = (k - 1) * WINDOW_S, k * WINDOW_S
    record.add(start, end, block_mean_deg(start, end))
    early.check(round(end * 1000), band=False)


def test_exact_record_gives_the_settle_point_and_the_first_safe_block() -> None:
    record, early = exact_rule()
    k = 0
    while not early.last or not early.last.ready:
        k += 1
        feed(record, early, k)
    check = early.last
    assert check.settle_point_deg == pytest.approx(SETTLED_DEG, abs=1e-9)
    assert check.standard_error_deg < 1e-9
    assert early.stable.t_s == (MIN_BLOCKS + ESTIMATE.stable_estimates - 1) * WINDOW_S

    def transient_over_windows(end: float) -> float:  # the N windows that would follow
        means = [block_mean_deg(end + i * WINDOW_S, end + (i + 1) * WINDOW_S) for i in range(5)]
        return float(np.max(np.abs(np.array(means) - SETTLED_DEG)))

    safe = [e for e in WINDOW_S * np.arange(1, 200) if transient_over_windows(e) <= TOL_DEG]
    assert check.t_s == safe[0] > 2000.0  # ~40 minutes: the reading, not the estimate, decides
    assert check.transient_deg == pytest.approx(transient_over_windows(check.t_s), abs=1e-9)


def test_the_fit_per_block_extends_the_last_and_equals_a_fit_anew() -> None:
    """The online fit reuses the last block's windows and design (`TransientRecord.fit`): the
    same numbers to the bit as fitting the kept segments anew, across steps (one dropped empty,
    one beyond the KEEP_SEGMENTS kept), a new model between blocks, and noisy means."""
    rng = np.random.default_rng(3)
    record, plan_model = TransientRecord(), ESTIMATE.model
    other = TransientModel(plan_model.undamped_period_s * 1.1, 0.6)
    steps = {30: "step", 45: "step", 46: "step", 70: "step", 95: "step", 120: "step"}
    fitted = 0
    for k in range(1, 150):
        start, end = (k - 1) * WINDOW_S, k * WINDOW_S
        if steps.get(k):
            record.step(start)
        if k == 46:  # (the step at 45 got no window: dropped, its successor starts free)
            record.step(start)
        record.add(start, end, block_mean_deg(start, end) + rng.normal(0, 0.002))
        for model in (plan_model, other) if k % 7 == 0 else (plan_model,):
            got = record.fit(model)
            seg, data = TransientRecord._data(record._segments[-KEEP_SEGMENTS:])
            try:
                anew = fit_transient(model, seg, data)
            except AnalysisError:
                assert got is None
                continue
            assert got is not None and got[1] == len(seg.step_s) - 1
            assert np.array_equal(got[0].theta, anew.theta)
            assert np.array_equal(got[0].covariance, anew.covariance)
            fitted += 1
    assert fitted > 120


def test_the_bound_is_taken_when_asked_for_if_it_could_not_decide() -> None:
    """A check whose settle point is not yet known (conditions 1-2) does not need the transient
    bound to decide; `last` still states it (the settle timeout message)."""
    record, early = exact_rule()
    for k in range(1, MIN_BLOCKS + 1):  # the first fit: the spread of 3 estimates not known yet
        feed(record, early, k)
    returned = early.check(round(MIN_BLOCKS * WINDOW_S * 1000), band=False)
    assert not returned.stable and not returned.ready
    fit, j = early.fit
    mids = MIN_BLOCKS * WINDOW_S + WINDOW_S / 2 + WINDOW_S * np.arange(N_OBS)
    assert early.last.transient_deg == fit.bound(j, mids, WINDOW_S) > 0


def test_compensated_rule_starts_once_the_settle_point_is_known() -> None:
    """With the state carried over (a settled series before the step) conditions 1-2 decide;
    with the state unknown (the run's first series) the transient bound does, as "estimate"."""
    plan = EstimatePlan(T0_S, ZETA, TOL_DEG, 1.0, 3, transient_fraction=1.0, compensated=True)
    starts = {}
    for chained in (True, False):
        record, early = exact_rule(plan)
        if chained:  # the element at rest at the old equilibrium for ten windows, then the step
            for k in range(-10, 0):
                record.add(k * WINDOW_S, (k + 1) * WINDOW_S, SETTLED_DEG + STEP_DEG)
            record.step(0.0)
        k = 0
        while not early.last or not early.last.ready:
            k += 1
            feed(record, early, k)
        assert early.last.compensates == chained
        assert early.last.settle_point_deg == pytest.approx(SETTLED_DEG, abs=1e-9)
        starts[chained] = early.last
    assert starts[True].t_s == (MIN_BLOCKS + 2) * WINDOW_S  # conditions 1-2 only
    assert starts[True].transient_deg > 0.1  # observed well inside the transient
    assert starts[False].t_s > 2000.0 and starts[False].transient_deg <= TOL_DEG


def test_the_state_carries_over_a_step() -> None:
    """Two steps of the equilibrium, exact window means: both settle points come out exact, the
    second from its state carried over the step (12 windows, well inside its transient)."""
    first, second, step_at = 0.1, 0.55, 3000.0

    def reading_mean(start: float, end: float) -> float:
        if end <= step_at:
            return block_mean_deg(start, end, first, -0.2)
        # superposition: the first transient goes on; the new step starts at step_at from
        # wherever the element is (linear system)
        late = block_mean_deg(start, end, first, -0.2) - first
        return second + late + block_mean_deg(start - step_at, end - step_at, 0.0, first - second)

    record = TransientRecord()
    record.step(0.0)
    for k in range(1, 51):
        record.add((k - 1) * WINDOW_S, k * WINDOW_S, reading_mean((k - 1) * WINDOW_S, k * WINDOW_S))
    record.step(step_at)
    for k in range(51, 51 + 12):
        record.add((k - 1) * WINDOW_S, k * WINDOW_S, reading_mean((k - 1) * WINDOW_S, k * WINDOW_S))
    fit, j = record.fit(ESTIMATE.model)
    assert j == 1 and fit.settle_point(j)[0] == pytest.approx(second, abs=1e-9)
    assert fit.settle_point(0)[0] == pytest.approx(first, abs=1e-9)


@pytest.mark.parametrize(
    ("settle_s", "band_s", "ending"),
    [(60.0, 900.0, "band criterion held after 900.0 s: 840.0 s saved"),
     (900.0, 60.0, "band criterion held after 60.0 s: no time saved (settled 840.0 s after it)")],
)  # fmt: skip
def test_the_event_never_reads_a_negative_saving(
    settle_s: float, band_s: float, ending: str
) -> None:
    """Before: a series whose estimate became stable after the band criterion held read
    "-840.0 s saved"."""
    outcome = SettleOutcome("estimate", settle_s, 0.3, 0.002, settle_s, 0.3, band_s=band_s)
    check = SettleCheck(settle_s, 0.3, 0.002, 0.001, 0.004, ESTIMATE, chained=False)
    assert describe(outcome, check).endswith(ending)


def test_band_time_predicted_from_the_fit_is_the_band_criterion_on_the_true_means() -> None:
    settle = load_plan(ROOT / "examples" / "paper.toml").settle  # band 0.03, drift 0.006, 1800 s
    record, early = exact_rule()
    for k in range(1, 31):  # the first half hour
        feed(record, early, k)
    means = [block_mean_deg((k - 1) * WINDOW_S, k * WINDOW_S) for k in range(1, 31)]
    fit, j = early.fit

    def predict(t_s: np.ndarray) -> np.ndarray:
        return fit.settle_point(j)[0] + fit.transient(j, t_s, WINDOW_S)[0]

    predicted = predict_band_settle_s(means, WINDOW_S, 30 * WINDOW_S, predict, settle)
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


def scaled_plan(
    settle: str,
    database: str = "runs/test.sqlite",
    trials: list[tuple[float, float, float, str]] | None = None,
) -> str:
    """Two trials (steps of +0.41 and -0.47 deg) unless told, band 0.03 deg held 420 s (1800 s
    scaled)."""
    text = plan_text(trials, n_obs=4, hold_s=420.0, database=database)
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
    """Series mean (of the compensated observations when compensated) minus the settled
    reading of model 1.1 (seed 000 eq 1.1)."""
    c = config.compass
    plan = parse_plan(scaled_plan(BAND_SETTLE))
    compensation = {(a[0], a[1]): a[2] for a in sink.of("series_completed") if a[2] is not None}
    out = {}
    for t in plan.trials:
        shift = c.settled_shift_deg(t.direction_deg, t.amplitude_cm, t.period_s)
        for j, truth in ((1, c.heading_deg), (2, c.heading_deg + shift)):
            values = [o.value_deg for o in sink.observations if (o.trial, o.j) == (t.index, j)]
            comp = compensation.get((t.index, j))
            subtract = np.zeros(len(values)) if comp is None else np.array(comp.transient_deg)
            out[(t.index, j)] = float(np.mean(np.array(values) - subtract)) - truth
    return out


def rms(errors: dict[tuple[int, int], float]) -> float:
    return math.sqrt(np.mean(np.square(list(errors.values()))))


COMPENSATED_SETTLE = EARLY_SETTLE.replace('method = "estimate"', 'method = "compensated"')
# not compensated: the run's first series (state unknown) and the second, which starts before the
# record determines the period and damping (it spans one period from the third series on)
UNCONFIRMED = {(1, 1), (1, 2)}


@pytest.fixture(scope="module")
def band() -> tuple[Recorder, Lockstep, Engine]:
    return run(BAND_SETTLE, scaled_config())


@pytest.fixture(scope="module")
def early() -> tuple[Recorder, Lockstep, Engine]:
    return run(EARLY_SETTLE, scaled_config())


@pytest.fixture(scope="module")
def compensated() -> tuple[Recorder, Lockstep, Engine]:
    return run(COMPENSATED_SETTLE, scaled_config())


def test_model_criterion_bounds_the_transient_left(band, early) -> None:
    """The band criterion holds on the overshoot (-0.013 and -0.015 deg left in trial 2); the
    model criterion waits until the fitted transient + 2 SE over the windows is within 0.05 S_e
    (0.00075 deg): what is left is the noise of a 4-observation mean (~0.004 deg)."""
    waited, model_s = settle_s(band[0]), settle_s(early[0])
    assert waited.keys() == model_s.keys() and len(waited) == 4
    config = scaled_config()
    model_err, band_err = errors_deg(early[0], config), errors_deg(band[0], config)
    assert min(band_err[(2, 1)], band_err[(2, 2)]) < -0.012
    assert max(abs(e) for e in model_err.values()) < 0.008
    assert rms(model_err) < 0.5 * rms(band_err)
    for a in early[0].of("series_settled"):
        assert a[3].criterion == "estimate"


def test_compensated_series_start_early_and_compensate_the_transient(band, compensated) -> None:
    """Every series once the record determines the period and damping starts inside its
    transient and is compensated; the ones before wait for the transient bound."""
    waited, comp_s = settle_s(band[0]), settle_s(compensated[0])
    transients = [key for key in waited if key not in UNCONFIRMED]
    assert all(comp_s[key] < 0.3 * waited[key] for key in transients)
    # 0.80 (below 0.6 when the second series was compensated on the plan's word): half of this
    # short run's series wait for the record to confirm the plan's period and damping
    assert compensated[1].stand.stand_time_s < 0.85 * band[1].stand.stand_time_s
    config = scaled_config()
    raw = {
        key: np.mean([o.value_deg for o in compensated[0].observations if (o.trial, o.j) == key])
        for key in waited
    }
    c = config.compass
    assert abs(raw[(2, 1)] - c.heading_deg) > 0.1  # observed inside the transient after the stop
    # within their SE (below), which carries the period and damping this short record gives
    # (issue 34): on its 2 trials no more accurate than the band criterion's (rms 0.013 vs
    # 0.010 deg; 0.0096 with the plan's period and damping taken as exact)
    comp_err = errors_deg(compensated[0], config)
    done = {(a[0], a[1]): a[2] for a in compensated[0].of("series_completed")}
    assert done[(1, 1)] is None and done[(1, 2)] is None
    for key in transients:
        comp = done[key]
        assert comp.first_k == 1 and len(comp.transient_deg) == 4
        assert abs(comp_err[key]) < 3 * comp.standard_error_deg + 0.004  # its SE + the noise


def test_a_compensation_states_its_share_in_the_period_and_damping_error(compensated) -> None:
    """Issue 34 (`analysis.gls`): each compensation carries d(mean) / d(period, ratio) and the
    covariance of the two its record gave: one run's record, later and later; the covariance
    positive definite, and its own part g Sigma g^T within the settle point's SE^2, where the
    analysis takes it out again (it is in var_mean through that SE). Shifting the period by
    its SE moves the compensated mean by g_P SE_P: the same order as the settle point's SE."""
    done = [a[2] for a in compensated[0].of("series_completed") if a[2] is not None]
    assert len(done) == 2
    shared = [c.shared for c in done]
    assert len({e.record_ms for e in shared}) == 1
    assert [e.at_ms for e in shared] == sorted(e.at_ms for e in shared)
    for comp, e in zip(done, shared, strict=True):
        cov, g = np.array(e.covariance), np.array(e.sensitivity)
        assert np.all(np.linalg.eigvalsh(cov) > 0)
        own = float(g @ cov @ g)
        assert 0.05 * comp.standard_error_deg**2 < own < comp.standard_error_deg**2


def test_a_compensation_names_the_uncompensated_series_it_covaries_with(compensated) -> None:
    """Issue 34: each compensation stores its covariance with the plain mean of each
    uncompensated series whose observations are in its record, naming it (trial, j): trial 1's
    two (the run's first, and the one before the record determined the period), not (2, 1),
    compensated itself."""
    done = {(a[0], a[1]): a[2] for a in compensated[0].of("series_completed")}
    for key in ((2, 1), (2, 2)):
        earlier = done[key].shared.earlier_deg2
        assert [name for name, _ in earlier] == [(1, 1), (1, 2)]
        assert all(value != 0.0 for _, value in earlier)


def test_a_control_trial_between_fit_trials_is_named_and_left_out_of_v(tmp_path: Path) -> None:
    """Fit, control, fit as stored: trial 3's compensations name trial 1's series (the control's
    are compensated themselves), and, were trial 1 left uncompensated, V's term between trials
    1 and 3 would be the named covariances with the trial means' signs, by hand: <delta> = m2 -
    m1, so +C(m32, m12) - C(m32, m11) - C(m31, m12) + C(m31, m11); nothing else of V moves.
    Trial 1's series are in fact compensated late, by the campaign's last fit of the record
    (issue 34): they then share its period and damping error like any compensated series."""
    path = tmp_path / "control.sqlite"
    trials = [(45.0, 24.0, 6.0, "fit"), (315.0, 20.0, 5.0, "control"), (135.0, 22.0, 5.5, "fit")]
    sessions = open_database(sqlite_url(path))
    plan = parse_plan(scaled_plan(COMPENSATED_SETTLE, str(path), trials))
    store = CampaignStore.create(sessions, plan)
    sim = Lockstep(scaled_config())
    engine = Engine(plan, store, sim, store.progress())
    sim.run(engine)
    with sessions() as session:
        inputs = stored_inputs(load_campaign(session, store.campaign_id))
    late = {key: e for key, e in inputs.shared.items() if key[0] == 1}
    shared = {key: e for key, e in inputs.shared.items() if key[0] != 1}
    assert shared.keys() == {(2, 1), (2, 2), (3, 1), (3, 2)}
    # trial 1's series compensated by the last fit: its time, its period and damping error
    assert late.keys() == {(1, 1), (1, 2)}
    assert all(
        e.at_ms == shared[3, 2].at_ms and e.covariance == shared[3, 2].covariance
        for e in late.values()
    )
    (first,) = [t for t in inputs.trials if t.index == 1]
    assert first.before.var_mean_deg2 is not None and first.under.var_mean_deg2 is not None
    named = {key: dict(e.earlier_deg2) for key, e in shared.items()}
    assert all(list(n) == [(1, 1), (1, 2)] for n in named.values())
    sign = {1: -1.0, 2: 1.0}
    by_hand = sum(sign[j] * sign[m] * named[3, j][1, m] for j in (1, 2) for m in (1, 2))
    bare = {key: dataclasses.replace(e, earlier_deg2=()) for key, e in shared.items()}
    term = shared_covariance(shared, [1, 3]) - shared_covariance(bare, [1, 3])
    np.testing.assert_allclose(term, [[0.0, by_hand], [by_hand, 0.0]], rtol=1e-12, atol=0.0)
    assert by_hand != 0.0


def _silent_in(sink: Recorder, trial: int, j: int, k: int) -> SimConfig:
    """The scaled stand of `compensated` with the bus silent for 20 s from 5 s into its
    observation window (trial, j, k): that trial fails there (the same frames before it)."""
    (obs,) = [o for o in sink.observations if (o.trial, o.j, o.k) == (trial, j, k)]
    silence = FaultParams(silence_at_s=obs.window_start_ms / 1000 + 5.0, silence_for_s=20.0)
    return dataclasses.replace(scaled_config(), faults=silence)


def _resume(sessions: sessionmaker[Session], plan: Plan, campaign_id: int) -> Engine:
    """`campaign resume` of a stored campaign on the scaled stand, run to its end."""
    _, resumed = resume_store(sessions, campaign_id)
    resumed.complete_acquired()
    sim = Lockstep(scaled_config())
    engine = Engine(plan, resumed, sim, resumed.progress())
    sim.run(engine)
    return engine


def test_a_failed_trial_s_series_are_not_named_nor_its_retry_s(tmp_path: Path, compensated):
    """Trial 1 fails in its rocking series after its still series ended uncompensated; trial 2
    is compensated in the same run. Its compensations name nothing of trial 1: the analysis
    never uses that attempt (a retry, acquired in another run, is the trial 1 it uses, and its
    windows are not in trial 2's record). Then `campaign retry` and a resume: the analysis gets
    trial 1's new attempt and no covariance of it with trial 2 (by position it would have taken
    the failed attempt's still series for the new one)."""
    path = tmp_path / "retry.sqlite"
    sessions = open_database(sqlite_url(path))
    plan = parse_plan(scaled_plan(COMPENSATED_SETTLE, database=str(path)))
    store = CampaignStore.create(sessions, plan)
    sim = Lockstep(_silent_in(compensated[0], 1, 2, 2))
    engine = Engine(plan, store, sim, store.progress())
    sim.run(engine)
    store.set_status(engine.outcome)
    assert retry_trials(sessions, store.campaign_id, [1]) == (RetriedTrial(1, 2, ANY),)
    _resume(sessions, plan, store.campaign_id)
    with sessions() as session:
        campaign = load_campaign(session, store.campaign_id)
        attempts = sorted((t.index, t.attempt, t.status) for t in campaign.trials)
        shared = stored_inputs(campaign).shared
    assert attempts == [(1, 1, "failed"), (1, 2, "completed"), (2, 1, "completed")]
    assert shared.keys() == {(2, 1), (2, 2)}
    assert all(e.earlier_deg2 == () for e in shared.values())
    bare = {key: dataclasses.replace(e, earlier_deg2=()) for key, e in shared.items()}
    assert np.array_equal(shared_covariance(shared, [1, 2]), shared_covariance(bare, [1, 2]))


def test_a_resumed_series_is_named_with_its_windows_of_this_run(tmp_path: Path, compensated):
    """A run stopped in trial 1's rocking series after 2 of its 4 observations; the resume
    observes 3 and 4 in a new record. Trial 2's compensations there name (1, 2) alone ((1, 1)
    is in the first run's record: independent) and through those two windows only (the
    analysis' mean is over all 4: each 1/4), not the segment's last 4 (settle blocks too)."""
    path = tmp_path / "resume.sqlite"
    sessions = open_database(sqlite_url(path))
    plan = parse_plan(scaled_plan(COMPENSATED_SETTLE, database=str(path)))
    store = CampaignStore.create(sessions, plan)
    sim = Lockstep(scaled_config())
    engine = Engine(plan, store, sim, store.progress())
    (second,) = [o for o in compensated[0].observations if (o.trial, o.j, o.k) == (1, 2, 2)]
    for _ in sim.steps(engine):
        if sim.stand.stand_time_s * 1000 >= second.window_end_ms + 5000:
            engine.interrupt("test: stopped after observation 2")
    store.set_status(engine.outcome)
    engine = _resume(sessions, plan, store.campaign_id)
    with sessions() as session:
        campaign = load_campaign(session, store.campaign_id)
        (t1,) = [t for t in campaign.trials if t.index == 1]
        (s12,) = [s for s in t1.series if s.j == 2]
        windows = {o.k: (o.window_start_ms, o.window_end_ms) for o in s12.observations}
        shared = stored_inputs(campaign).shared
    assert s12.compensation_shared is None and sorted(windows) == [1, 2, 3, 4]
    # the record labels (1, 2) with the windows of its observations 3 and 4, of this run
    mids = np.array([windows[3], windows[4]], dtype=float).mean(axis=1) / 1000
    np.testing.assert_array_equal(engine._record._observed[1, 2].mean(axis=1), mids)
    assert shared and (1, 1) not in shared and (1, 2) not in shared  # not compensated late:
    for e in shared.values():  # (1, 2) partly in another run's record, (1, 1) wholly
        assert [name for name, _ in e.earlier_deg2] == [(1, 2)]


def test_the_outcome_records_estimate_and_time_saved(band, compensated) -> None:
    sink = compensated[0]
    events = {(a[3], a[4]): a for a in sink.of("event") if a[0] == "early settle"}
    settled = {(a[0], a[1]): a for a in sink.of("series_settled")}
    waited, comp_s = settle_s(band[0]), settle_s(sink)
    assert all(a[3].criterion == "band" for a in band[0].of("series_settled"))
    for key, event in events.items():
        outcome = settled[key][3]
        assert event[5] == settled[key][2]  # the event tells the decision at its stand time
        assert f"settle point {outcome.estimate_deg:.5f} deg" in event[2]
        assert outcome.criterion == ("estimate" if key in UNCONFIRMED else "compensated")
        assert outcome.settle_s == comp_s[key]
        assert outcome.standard_error_deg <= 0.015
        assert outcome.stable_since_s <= outcome.settle_s
        assert outcome.blocks and outcome.blocks[-1][1] == settled[key][2]  # the settle record
        assert outcome.step_ms is not None and outcome.step_ms <= outcome.blocks[0][0]
        # the band time predicted from the fit vs the band criterion on the same seed's readings
        if key not in UNCONFIRMED:
            assert not outcome.band_measured
            assert outcome.band_s == pytest.approx(waited[key], rel=0.15)
        assert outcome.saved_s == pytest.approx(outcome.band_s - outcome.settle_s)
    assert len(events) == 4


def test_rocking_harmonics_are_averaged_out_by_whole_period_blocks(early) -> None:
    """Ten times the reading oscillation at p and 2p (0.27 deg at p for trial 1) changes
    neither when the series start nor, beyond quantisation, what they estimate."""
    loud, _, _ = run(EARLY_SETTLE, scaled_config(harmonic_deg_per_g=10.0))
    assert settle_s(loud) == settle_s(early[0])
    quiet_est = {(a[0], a[1]): a[3].estimate_deg for a in early[0].of("series_settled")}
    loud_est = {(a[0], a[1]): a[3].estimate_deg for a in loud.of("series_settled")}
    assert all(abs(loud_est[k] - quiet_est[k]) < 2e-3 for k in quiet_est)


def test_stored_and_reported(tmp_path: Path, compensated) -> None:
    path = tmp_path / "early.sqlite"
    sessions = open_database(sqlite_url(path))
    plan = parse_plan(scaled_plan(COMPENSATED_SETTLE, database=str(path)))
    store = CampaignStore.create(sessions, plan)
    sim = Lockstep(scaled_config())
    engine = Engine(plan, store, sim, store.progress())
    sim.run(engine)
    store.set_status(engine.outcome)
    done = {(a[0], a[1]): a[2] for a in compensated[0].of("series_completed")}
    late = {(a[0], a[1]): a[2] for a in compensated[0].of("series_compensated")}  # the last
    with sessions() as session:
        series = session.execute(
            select(Trial.index, Series).join(Series).where(Trial.campaign_id == store.campaign_id)
        ).all()
        events = session.scalars(select(Event).where(Event.kind == "early settle")).all()
        assert {e.series_id for e in events} == {s.id for _, s in series}
        stored = {}
        for index, s in series:
            outcome = SettleOutcome.from_dict(s.settle_outcome)
            first = (index, s.j) in UNCONFIRMED  # not compensated
            assert outcome.criterion == ("estimate" if first else "compensated")
            assert outcome.standard_error_deg <= 0.015
            assert s.settle_estimate_deg == outcome.estimate_deg
            assert (s.settle_done_ms - s.settle_started_ms) / 1000 == outcome.settle_s
            stored[(index, s.j)] = (s.settle_estimate_deg, outcome.saved_s)
            # the raw readings and the compensation, as the engine computed them
            comp = done[(index, s.j)]
            rows = session.scalars(select(Observation).where(Observation.series_id == s.id))
            if first:  # not at its end: late, by the last fit of the record (issue 34)
                assert comp is None
                comp = late[index, s.j]
            assert s.compensation_se_deg == comp.standard_error_deg
            assert tuple(o.compensation_deg for o in rows) == comp.transient_deg
            assert s.compensation_shared == comp.shared.to_dict()  # issue 34's GLS
    assert len(stored) == 4
    report = campaign_report(
        sessions,
        store.campaign_id,
        database=str(path),
        profile=load_profile(),
        generated_at="now",
    )
    rows = {(r.trial, r.j): r for r in report.signal.settle}
    assert rows.keys() == stored.keys()
    for key, (estimate, saved) in stored.items():
        assert rows[key].criterion == ("estimate" if key in UNCONFIRMED else "compensated")
        assert rows[key].estimate_deg == estimate and rows[key].saved_s == saved


# --- plan validation --------------------------------------------------------------------------


def test_estimate_plan_derives_the_transient() -> None:
    plan = parse_plan(scaled_plan(EARLY_SETTLE)).settle
    assert plan.method == "estimate" and plan.estimate is not None
    w0 = 2 * math.pi / SCALED_T0_S
    assert plan.estimate.model.w == pytest.approx(w0 * math.sqrt(1 - ZETA**2))  # eq 2
    assert plan.estimate.model.xi == pytest.approx(ZETA * w0)
    assert plan.estimate.tolerance_deg == pytest.approx(0.015)
    assert plan.estimate.stable_estimates == 3
    band = parse_plan(scaled_plan(BAND_SETTLE)).settle
    assert band.method == "band" and band.estimate is None
    compensated = load_plan(ROOT / "examples" / "paper-compensated.toml")
    paper = load_plan(ROOT / "examples" / "paper.toml")
    assert compensated.trials == paper.trials
    shared = set(type(paper.settle).model_fields) - {"method", "tolerance_fraction"}
    assert compensated.settle.model_dump(include=shared) == paper.settle.model_dump(include=shared)
    assert paper.settle.method == "estimate" and compensated.settle.method == "compensated"
    assert compensated.settle.estimate.compensated and not paper.settle.estimate.compensated


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (("method = \"estimate\"", "method = \"fast\""),
         "[settle] method: must be one of 'band', 'estimate', 'compensated', not 'fast'"),
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
         "[settle] expected_se_deg: does not apply when method = 'band'"),
    ],
)  # fmt: skip
def test_bad_early_settle_keys_are_one_clear_error(edit: tuple[str, str], expected: str) -> None:
    old, new = edit
    text = scaled_plan(EARLY_SETTLE)
    assert old in text
    with pytest.raises(PlanError) as info:
        parse_plan(text.replace(old, new, 1))
    problems = info.value.problems
    if expected.endswith("does not apply when method = 'band'"):  # one per key
        assert problems[0] == expected and len(problems) == 2  # the instrument's data apply
        assert all(re.fullmatch(r"\[settle\] \w+: does not apply .*", p) for p in problems)
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
        re.fullmatch(r"not settled within 1500 s \(transient model: SE [\d.]+ deg, .*tolerance "
                     r"0\.01500 deg; transient over the observations [\d.]+ deg, bound "
                     r"0\.00075 deg\)", f)
        for f in failures
    )  # fmt: skip
