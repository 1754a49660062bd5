"""Plan validation: the shipped paper plan is valid and matches the seed's table; every defect of
a bad plan is reported at once with its field path."""

import math
from pathlib import Path

import pytest

from gyrostand.plan.model import PlanError, StandLimit, load_plan, parse_plan, revised

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "examples" / "paper.toml"


def test_paper_plan_is_the_seed_campaign() -> None:
    plan = load_plan(PAPER)
    rows = [(t.direction_deg, t.amplitude_cm, t.period_s, t.role) for t in plan.trials]
    # seed 000, table of the example (A of trials 4 and 6 is 17.8 cm)
    assert rows == [
        (332, 24, 8, "fit"),
        (18, 24, 6.3, "fit"),
        (316, 23, 5.5, "fit"),
        (346, 17.8, 3.5, "fit"),
        (31, 23.5, 6.2, "control"),
        (346, 17.8, 5.5, "control"),
    ]
    assert plan.n_obs == 5
    assert plan.bus.simulated
    assert (plan.instrument.lp_gcm2s2, plan.instrument.h1_gcm2s) == (6.57e6, 1.55e8)
    assert plan.site.latitude_deg == 46.5
    assert plan.observation.window_ms(None) == 60_000
    assert plan.observation.window_ms(6.3) == 8 * 6300


def _broken(text: str) -> list[str]:
    with pytest.raises(PlanError) as info:
        parse_plan(text)
    return info.value.problems


def test_every_problem_is_reported_with_its_path() -> None:
    text = PAPER.read_text()
    text = text.replace("period_s = 3.5", "period_s = -3.5", 1)
    text = text.replace('role = "control"', 'role = "spare"', 1)
    text = text.replace("n_obs = 5", "n_obs = 1")
    text = text.replace("band_deg = 0.03", "band_deg = 0.03\nbnad = 1")
    text = text.replace('raw_log_format = "blf"', 'raw_log_format = "mf4"')
    text = text.replace("latitude_deg = 46.5", 'latitude_deg = "north"')
    problems = _broken(text)
    assert problems == [
        "[campaign] n_obs: must be >= 2",
        "[campaign] raw_log_format: must be one of 'blf', 'asc', not 'mf4'",
        "[site] latitude_deg: must be a finite number",
        "[[trials]] 4 period_s: must be > 0",
        "[[trials]] 5 role: must be one of 'fit', 'control', not 'spare'",
        "[settle] bnad: unknown key",
    ]


def test_missing_tables_and_keys() -> None:
    problems = _broken('[campaign]\noperator = "x"\n')
    assert "[campaign] n_obs: missing" in problems
    assert "[campaign] database: missing" in problems
    for table in ("[instrument]", "[site]", "[analysis]", "[forecast]", "[[trials]]"):
        assert f"{table}: missing" in problems


def test_syntax_error_is_one_problem() -> None:
    assert _broken("[campaign\n")[0].startswith("TOML syntax:")


def test_bus_consistency() -> None:
    text = PAPER.read_text().replace("simulated = true", 'simulated = true\ninterface = "pcan"')
    assert _broken(text) == ["[bus] interface: must be absent when simulated = true"]
    text = PAPER.read_text().replace("simulated = true", "simulated = false\nspeedup = 5.0")
    text = text.replace('timing = "virtual"', 'timing = "realtime"')
    assert _broken(text) == ["[bus] speedup: only applies when simulated = true"]
    text = PAPER.read_text().replace("simulated = true", "simulated = true\nspeedup = 5.0")
    assert _broken(text) == [
        '[bus] speedup: only applies with timing = "realtime" (virtual time runs at full speed)'
    ]
    text = PAPER.read_text().replace('timing = "virtual"', 'timing = "fast"')
    assert _broken(text) == ["[bus] timing: must be one of 'virtual', 'realtime', not 'fast'"]


def test_timing_defaults_to_virtual_for_the_simulated_stand_only() -> None:
    text = PAPER.read_text().replace('timing = "virtual"', "")
    assert parse_plan(text).bus.timing == "virtual"
    text = text.replace("simulated = true", "simulated = false")
    assert parse_plan(text).bus.timing == "realtime"


def test_control_only_design_is_refused() -> None:
    text = PAPER.read_text().replace('role = "fit"', 'role = "control"')
    assert _broken(text) == ["[[trials]]: at least one trial must have role 'fit'"]


MINIMAL = """
[campaign]
operator = "o"
n_obs = 2
database = "db.sqlite"
acquisition_only = true
[instrument]
model = "m"
serial = "s"
lp_gcm2s2 = 6.57e6
h1_gcm2s = 1.55e8
[site]
latitude_deg = 46.5
[analysis]
start_c = 7e7
start_t_s = 0.55
[forecast]
roll_deg = 5.0
arm_cm = 750.0
period_s = 7.0
course_deg = 45.0
latitude_deg = 57.0
[[trials]]
direction_deg = 0.0
amplitude_cm = 10.0
period_s = 5.0
"""


def test_defaults_of_a_minimal_plan() -> None:
    plan = parse_plan(MINIMAL)
    assert (plan.raw_log_format, plan.raw_log_dir, plan.on_trial_failure, plan.dbc_path) == (
        "blf",
        "raw",  # beside the database db.sqlite
        "continue",
        None,
    )
    lab = revised(plan, campaign={"database": "/lab/stand-2.sqlite"})
    assert lab.raw_log_dir == "/lab/raw"  # follows the database (campaign run --db)
    assert revised(plan, campaign={"database": "postgresql://lab/gyro"}).raw_log_dir == "runs/raw"
    assert revised(plan, campaign={"raw_log_dir": "logs"}).raw_log_dir == "logs"
    assert (plan.site.earth_rate_rad_s, plan.site.gravity_cm_s2) == (7.292115e-5, 981.0)
    assert (plan.analysis.q, plan.analysis.admissible_c, plan.forecast.motion) == (
        0.05,
        None,
        "roll",
    )
    assert (plan.forecast.amplitude_cm, plan.acceptance, plan.signals) == (None, None, {})
    assert [(t.index, t.role) for t in plan.trials] == [(1, "fit")]  # acquisition only
    assert plan.stand.model_fields_set == set()
    limits = plan.stand_limits  # the simulator's defaults
    assert (limits.max_amplitude_cm, limits.min_period_s, limits.max_period_s) == (
        StandLimit(50.0, "simulator"),
        StandLimit(2.0, "simulator"),
        StandLimit(20.0, "simulator"),
    )
    o, st, tr = plan.observation, plan.settle, plan.tracking
    assert (o.still_window_s, o.rocking_window_periods, o.spacing_s) == (60.0, 10, 0.0)
    assert (st.band_deg, st.drift_deg, st.hold_s, st.max_wait_s) == (0.02, math.inf, 600.0, 14400.0)
    assert (st.method, st.estimate) == ("band", None)
    assert (tr.amplitude_rel, tr.period_rel, tr.direction_deg, tr.confirm_s) == (0.05, 0.05, 2, 120)
    assert (plan.timeouts.ack_s, plan.timeouts.bus_silence_s, plan.checks.max_error_frames) == (
        2.0,
        5.0,
        10,
    )
    bus = plan.bus
    assert (bus.simulated, bus.timing, bus.speedup, bus.seed, bus.queue_size) == (
        True,
        "virtual",
        1.0,
        0,
        200_000,
    )
    assert plan.text == MINIMAL and len(plan.sha256) == 64


def test_cross_field_rules_of_settle() -> None:
    text = MINIMAL + "[settle]\nhold_s = 900.0\nmax_wait_s = 600.0\n"
    assert _broken(text) == ["[settle] max_wait_s: must be >= hold_s"]
    text = MINIMAL + '[settle]\nmethod = "estimate"\n'
    assert _broken(text) == [
        f"[settle] {key}: missing"
        for key in ("undamped_period_s", "damping_ratio", "expected_se_deg")
    ]


def test_revised_plan_is_validated_and_keeps_the_text() -> None:
    plan = parse_plan(MINIMAL)
    changed = revised(plan, bus={"timing": "realtime", "speedup": 4.0}, campaign={"database": "x"})
    assert (changed.bus.speedup, changed.database, changed.text) == (4.0, "x", MINIMAL)
    assert changed.trials == plan.trials and changed.trials[0].index == 1
    with pytest.raises(PlanError) as caught:
        revised(plan, bus={"speedup": 4.0})
    assert caught.value.problems == [
        '[bus] speedup: only applies with timing = "realtime" (virtual time runs at full speed)'
    ]
