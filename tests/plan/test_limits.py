"""What a plan may ask of the stand, the database and the analysis, refused before a campaign
starts (each case ran, or was a traceback, before these rules):

1. a trial beyond the stand's limits (amplitude above, period below or above) started a campaign
   whose trial the stand then refused; the limits come from [stand] and, for the simulated stand,
   from the simulator ([bus.simulator.stand] over its defaults 50 cm, 2 to 20 s);
2. N = 10**9 ran (weeks of stand time per series) and N = 10**30 was a traceback in the database;
3. a design with fewer than 3 fit trials was accepted although the analysis can never fit it
   (m + 1 fit trials for the m = 2 parameters C and T), unless it is marked acquisition-only;
4. a simulator knob with a string value is a problem line, not a traceback (pinned).
"""

from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.plan.model import (
    MAX_N_OBS,
    PlanError,
    StandLimit,
    StandLimits,
    parse_plan,
)

ERROR = "gyrostand: error: "  # plan check's problems, one per line on stderr

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "examples" / "paper.toml"
TEXT = PAPER.read_text().replace("spacing_s = 30.0", "spacing_s = 0.0", 1)  # windows end to end
runner = CliRunner()


def _problems(text: str) -> list[str]:
    with pytest.raises(PlanError) as info:
        parse_plan(text)
    return info.value.problems


def _with(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def _after_bus(table: str, text: str = TEXT) -> str:
    """`table` (TOML) right after the plan's [bus] keys."""
    return _with(text, "seed = 1\n", "seed = 1\n" + table)


# ------------------------------------------------------------------ 1. the stand's limits


def test_amplitude_beyond_the_simulated_stands_limit() -> None:
    text = _after_bus("[bus.simulator.stand]\nmax_amplitude_cm = 35.0\n")
    text = _with(text, "amplitude_cm = 23.0", "amplitude_cm = 40.0")
    assert _problems(text) == ["[[trials]] 3 amplitude_cm: 40 exceeds the stand's limit 35 cm"]


def test_periods_outside_the_simulators_default_limits() -> None:
    text = _with(TEXT, "period_s = 3.5", "period_s = 1.5")
    text = _with(text, "period_s = 6.2", "period_s = 25.0")
    text = _with(text, "amplitude_cm = 23.0", "amplitude_cm = 60.0")
    assert _problems(text) == [
        "[[trials]] 3 amplitude_cm: 60 exceeds the stand's limit 50 cm",
        "[[trials]] 4 period_s: 1.5 is below the stand's limit 2 s",
        "[[trials]] 5 period_s: 25 exceeds the stand's limit 20 s",
    ]


def test_limits_are_inclusive() -> None:
    text = _after_bus("[bus.simulator.stand]\nmax_amplitude_cm = 24.0\nmin_period_s = 3.5\n")
    assert parse_plan(_with(text, "period_s = 8.0", "period_s = 20.0")).trials[0].period_s == 20


def test_real_stand_is_checked_against_its_stand_table() -> None:
    real = _with(TEXT, "simulated = true", "simulated = false")
    real = _with(real, 'timing = "virtual"', 'timing = "realtime"')
    assert parse_plan(real).stand_limits == StandLimits(None, None, None)  # unknown: unchecked
    text = real + "\n[stand]\nmax_amplitude_cm = 20.0\nmin_period_s = 4.0\nmax_period_s = 30.0\n"
    assert _problems(text) == [
        "[[trials]] 1 amplitude_cm: 24 exceeds the stand's limit 20 cm",
        "[[trials]] 2 amplitude_cm: 24 exceeds the stand's limit 20 cm",
        "[[trials]] 3 amplitude_cm: 23 exceeds the stand's limit 20 cm",
        "[[trials]] 4 period_s: 3.5 is below the stand's limit 4 s",
        "[[trials]] 5 amplitude_cm: 23.5 exceeds the stand's limit 20 cm",
    ]


def test_stand_limits_of_a_simulated_and_a_real_stand() -> None:
    assert parse_plan(TEXT).stand_limits == StandLimits(
        StandLimit(50.0, "simulator"), StandLimit(2.0, "simulator"), StandLimit(20.0, "simulator")
    )
    text = _after_bus("[bus.simulator.stand]\nmax_amplitude_cm = 35.0\n")
    assert parse_plan(text).stand_limits.max_amplitude_cm == StandLimit(35.0, "simulator")
    real = _with(TEXT, "simulated = true", "simulated = false")
    real = _with(real, 'timing = "virtual"', 'timing = "realtime"')
    assert parse_plan(real).stand_limits == StandLimits(None, None, None)  # unknown
    real += "\n[stand]\nmax_amplitude_cm = 30.0\nmin_period_s = 3.0\nmax_period_s = 30.0\n"
    assert parse_plan(real).stand_limits == StandLimits(
        StandLimit(30.0, "stand"), StandLimit(3.0, "stand"), StandLimit(30.0, "stand")
    )


def test_simulated_plan_with_a_stand_table_takes_the_tighter_limit() -> None:
    looser = TEXT + "\n[stand]\nmax_amplitude_cm = 60.0\nmin_period_s = 4.0\n"
    looser = _with(looser, "amplitude_cm = 23.0", "amplitude_cm = 55.0")
    assert _problems(looser) == [
        "[[trials]] 3 amplitude_cm: 55 exceeds the simulated stand's limit 50 cm",
        "[[trials]] 4 period_s: 3.5 is below the stand's limit 4 s",
    ]
    limits = parse_plan(TEXT + "\n[stand]\nmax_amplitude_cm = 60.0\nmin_period_s = 3.0\n")
    assert limits.stand_limits == StandLimits(
        StandLimit(50.0, "simulator"), StandLimit(3.0, "stand"), StandLimit(20.0, "simulator")
    )


def test_stand_table_problems() -> None:
    text = TEXT + "\n[stand]\nmin_period_s = 10.0\nmax_period_s = 5.0\n"
    assert _problems(text) == ["[stand] max_period_s: must be >= min_period_s"]
    text = TEXT + "\n[stand]\nmax_amplitude_cm = 0.0\nmax_amplitude = 1.0\n"
    assert _problems(text) == [
        "[stand] max_amplitude_cm: must be > 0",
        "[stand] max_amplitude: unknown key",
    ]


# ------------------------------------------------------------------ 2. the bounds of N


def test_n_beyond_the_database_column_is_a_problem_not_a_traceback() -> None:
    text = _with(TEXT, "n_obs = 5 ", f"n_obs = {10**30} ")
    assert _problems(text) == [
        "[campaign] n_obs: must be <= 2147483647 "
        "(observation k is a 32-bit integer column of the database)"
    ]
    assert MAX_N_OBS == 2**31 - 1


def test_n_beyond_seven_days_of_stand_time_per_series() -> None:
    text = _with(TEXT, "n_obs = 5 ", "n_obs = 1000000000 ")
    assert _problems(text) == [
        "[campaign] n_obs: 1000000000 x (64 s window + 0 s spacing) = 740740.7 days of stand time "
        "in the longest series; a series may take at most 7 days"
    ]


def test_seven_days_exactly_is_allowed() -> None:
    # the longest window of the paper plan: 8 periods of 8 s; 9450 x 64 s = 7 days
    assert parse_plan(_with(TEXT, "n_obs = 5 ", "n_obs = 9450 ")).n_obs == 9450
    text = _with(TEXT, "n_obs = 5 ", "n_obs = 9000 ")
    text = _with(text, "spacing_s = 0.0", "spacing_s = 3.5")
    assert _problems(text) == [
        "[campaign] n_obs: 9000 x (64 s window + 3.5 s spacing) = 7.0 days of stand time in the "
        "longest series; a series may take at most 7 days"
    ]


def test_plan_check_shows_the_bounds_of_n(tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text(_with(TEXT, "n_obs = 5 ", f"n_obs = {10**30} "))
    result = runner.invoke(app, ["plan", "check", str(plan)])
    assert result.exit_code == 1
    assert result.output == (
        f"{ERROR}{plan}: [campaign] n_obs: must be <= 2147483647 "
        "(observation k is a 32-bit integer column of the database)\n"
    )
    plan.write_text(_with(TEXT, "n_obs = 5 ", "n_obs = 1000000000 "))
    result = runner.invoke(app, ["plan", "check", str(plan)])
    assert result.exit_code == 1
    assert result.output == (
        f"{ERROR}{plan}: [campaign] n_obs: 1000000000 x (64 s window + 0 s spacing) = "
        "740740.7 days of "
        "stand time in the longest series; a series may take at most 7 days\n"
    )


# ------------------------------------------------------------------ 3. an analysable design


def _fit_trials(count: int, text: str = TEXT) -> str:
    """The paper plan with only its first `count` trials of role fit (the others control)."""
    head, *trials = text.split("[[trials]]")
    roles = [
        t.replace('role = "fit"', 'role = "control"') if i >= count else t
        for i, t in enumerate(trials)
    ]
    return "[[trials]]".join([head, *roles])


def test_fewer_than_three_fit_trials_are_refused() -> None:
    assert _problems(_fit_trials(2)) == [
        "[[trials]]: 2 fit trials, but the analysis needs at least 3 (m + 1 for the m = 2 "
        "parameters C and T: the adequacy test needs n - m >= 1 degrees of freedom); add fit "
        "trials, or set [campaign] acquisition_only = true to acquire without analysing"
    ]
    assert _problems(_fit_trials(1))[0].startswith("[[trials]]: 1 fit trial, but the analysis")
    assert len(parse_plan(_fit_trials(3)).trials) == 6
    assert parse_plan(TEXT).campaign.acquisition_only is False


def test_acquisition_only_plan_may_have_fewer_fit_trials() -> None:
    text = _with(_fit_trials(1), 'on_trial_failure = "continue"', "acquisition_only = true")
    plan = parse_plan(text)
    assert plan.campaign.acquisition_only and sum(t.role == "fit" for t in plan.trials) == 1
    # still at least one fit trial
    assert _problems(_fit_trials(0, text)) == [
        "[[trials]]: at least one trial must have role 'fit'"
    ]


def test_rules_across_tables_wait_for_valid_tables() -> None:
    """They need every table they read: a plan gets them once its tables are valid."""
    text = _with(_fit_trials(2), "n_obs = 5 ", "n_obs = 1 ")
    assert _problems(text) == ["[campaign] n_obs: must be >= 2"]


def test_acquisition_only_is_a_campaign_key() -> None:
    assert parse_plan(TEXT).campaign.acquisition_only is False
    text = _with(TEXT, 'on_trial_failure = "continue"', "acquisition_only = true")
    assert parse_plan(text).campaign.acquisition_only is True
    assert _problems(_with(TEXT, 'on_trial_failure = "continue"', "acquisition_only = 1")) == [
        "[campaign] acquisition_only: must be true or false"
    ]


# ------------------------------------------------------------------ 4. simulator knobs


def test_string_simulator_knob_is_a_problem_line() -> None:
    text = _after_bus('[bus.simulator.noise]\nwhite_sigma_deg = "x"\nwhite_deg = "x"\n')
    assert _problems(text) == [
        "[bus.simulator.noise] white_sigma_deg: must be a finite number",
        "[bus.simulator.noise] white_deg: unknown key",
    ]
    text = _after_bus('[bus.simulator.stand]\nmax_amplitude_cm = "35"\n')
    assert _problems(text) == ["[bus.simulator.stand] max_amplitude_cm: must be a finite number"]


# ------------------------------------------------------------------ plan check shows them


def test_plan_check_shows_every_problem(tmp_path: Path) -> None:
    text = _with(_fit_trials(2), "n_obs = 5 ", "n_obs = 1000000000 ")
    text = _with(text, "amplitude_cm = 23.0", "amplitude_cm = 60.0")
    plan = tmp_path / "plan.toml"
    plan.write_text(text)
    result = runner.invoke(app, ["plan", "check", str(plan)])
    assert result.exit_code == 1
    lines = result.output.splitlines()
    assert lines[0].startswith(f"{ERROR}{plan}: [[trials]]: 2 fit trials, but the analysis needs")
    assert lines[1:] == [
        f"{ERROR}{plan}: [[trials]] 3 amplitude_cm: 60 exceeds the stand's limit 50 cm",
        f"{ERROR}{plan}: [campaign] n_obs: 1000000000 x (64 s window + 0 s spacing) = "
        "740740.7 days of "
        "stand time in the longest series; a series may take at most 7 days",
    ]
    plan.write_text(_with(TEXT, "n_obs = 5 ", f"n_obs = {10**30} "))
    result = runner.invoke(app, ["plan", "check", str(plan)])
    assert result.exit_code == 1
    assert result.output == (
        f"{ERROR}{plan}: [campaign] n_obs: must be <= 2147483647 "
        "(observation k is a 32-bit integer column of the database)\n"
    )


def test_a_trial_the_stand_command_cannot_carry_is_a_plan_problem(tmp_path: Path) -> None:
    """The plan allows directions below 360 deg, the DBC's STAND_COMMAND.DIRECTION up to 359.99:
    refused before the campaign starts, not a ProtocolError in the middle of it."""
    plan = tmp_path / "plan.toml"
    plan.write_text(PAPER.read_text().replace("direction_deg = 332.0", "direction_deg = 359.999"))
    result = CliRunner().invoke(app, ["plan", "check", str(plan)])
    assert result.exit_code == 1
    assert result.output == (
        f"{ERROR}{plan}: [[trials]] 1: the stand command cannot carry it: "
        "STAND_COMMAND.DIRECTION = "
        "359.999 is outside the allowed range [0, 359.99] deg\n"
    )
