"""A simulated stand's unknown knob is named with the valid ones of its table, and with the
spelling meant when only its case differs (the plan's [instrument] lp_gcm2s2 is the simulator's
compass lP_gcm2s2)."""

import dataclasses

import pytest

from gyrostand.simulated_stand import StandSetupError, StandSpec
from gyrostand.stand.simconfig import CompassParams, FaultParams


def test_an_unknown_compass_knob_names_the_one_meant_and_the_valid_ones() -> None:
    with pytest.raises(StandSetupError) as refused:
        StandSpec(simulator={"compass": {"lp_gcm2s2": 6.0e6}}).config()
    valid = ", ".join(f.name for f in dataclasses.fields(CompassParams))
    assert str(refused.value) == (
        "simulated stand: compass.lp_gcm2s2: Extra inputs are not permitted (did you mean "
        f"lP_gcm2s2?); valid: {valid}"
    )


def test_an_unknown_fault_knob_lists_the_valid_ones() -> None:
    with pytest.raises(StandSetupError) as refused:
        StandSpec(simulator={"faults": {"dorp_rate": 0.1}}).config()
    valid = ", ".join(f.name for f in dataclasses.fields(FaultParams))
    assert str(refused.value).endswith(
        f"faults.dorp_rate: Extra inputs are not permitted; valid: {valid}"
    )
