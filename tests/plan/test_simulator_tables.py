"""[bus.simulator]: the simulated stand's overrides are part of the plan model (generated from
the stand's parameter dataclasses): unknown keys and inconsistent values with their paths."""

from pathlib import Path

import pytest

from gyrostand.plan.codec import sim_config
from gyrostand.plan.model import PlanError, parse_plan, schema
from gyrostand.stand.simconfig import SimConfig, SimConfigError

PAPER = Path(__file__).resolve().parents[2] / "examples" / "paper.toml"


def problems(extra: str) -> list[str]:
    with pytest.raises(PlanError) as caught:
        parse_plan(PAPER.read_text() + "\n" + extra)
    return caught.value.problems


def test_overrides_reach_the_simulated_stand_with_the_plans_seed() -> None:
    extra = "[bus.simulator]\nheading_rate_hz = 2.0\n[bus.simulator.faults]\ndrop_rate = 0.1\n"
    config = sim_config(parse_plan(PAPER.read_text() + extra).bus)
    assert (config.heading_rate_hz, config.faults.drop_rate, config.seed) == (2.0, 0.1, 1)
    assert config.timing == "virtual" and config.compass == SimConfig().compass


def test_unknown_and_mistyped_keys_have_their_paths() -> None:
    assert problems("[bus.simulator]\nrate = 1\n[bus.simulator.faults]\ndrop = 1\n") == [
        "[bus.simulator.faults] drop: unknown key",
        "[bus.simulator] rate: unknown key",
    ]
    assert problems("[bus.simulator.compass]\ntransient = 1\n") == [
        "[bus.simulator.compass] transient: must be true or false"
    ]


def test_every_inconsistency_is_reported() -> None:
    extra = (
        "[bus.simulator]\nheading_rate_hz = 0.001\n[bus.simulator.compass]\ndamping_ratio = -1.0\n"
        "[bus.simulator.faults]\ndrop_rate = 2.0\n"
    )
    assert problems(extra) == [
        "[bus.simulator.compass] damping_ratio: must be >= 0",
        "[bus.simulator.compass] undamped_period_s: must span at least 20 heading intervals",
        "[bus.simulator.faults] drop_rate: must be a probability in [0, 1]",
    ]


def test_direct_construction_names_every_option() -> None:
    with pytest.raises(SimConfigError) as caught:
        SimConfig(speedup=0.0, timing="realtime", heading_rate_hz=-1.0)
    assert str(caught.value) == (
        "speedup must be a positive number, got 0.0; "
        "heading_rate_hz must be a positive number, got -1.0; "
        "undamped_period_s must span at least 20 heading intervals"
    )


def test_schema_describes_the_simulator() -> None:
    faults = schema()["$defs"]["SimulatorFaults"]
    assert faults["additionalProperties"] is False
    assert "probability" in faults["properties"]["drop_rate"]["description"]
