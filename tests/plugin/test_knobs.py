"""A simulated stand's unknown knob is named with the valid ones of its table, and with the
spelling meant when only its case differs; a knob in its old spelling (C_gcm2s2, lP_gcm2s2) is
read, with a DeprecationWarning naming the one spelling (c_gcm2s2, lp_gcm2s2: as the plan's
[instrument] table and the CLI's --lp-gcm2s2)."""

import dataclasses

import pytest

from gyrostand.simulated_stand import StandSetupError, StandSpec
from gyrostand.stand.simconfig import CompassParams, FaultParams


def test_an_unknown_compass_knob_names_the_one_meant_and_the_valid_ones() -> None:
    with pytest.raises(StandSetupError) as refused:
        StandSpec(simulator={"compass": {"LP_gcm2s2": 6.0e6}}).config()
    valid = ", ".join(f.name for f in dataclasses.fields(CompassParams))
    assert str(refused.value) == (
        "simulated stand: compass.LP_gcm2s2: Extra inputs are not permitted (did you mean "
        f"lp_gcm2s2?); valid: {valid}"
    )


def test_one_spelling_and_the_old_one_still_read_with_a_note() -> None:
    """Before: the simulator's lP_gcm2s2 refused the plan's and the CLI's spelling lp_gcm2s2."""
    knobs = {"c_gcm2s2": 5.0e7, "t_s": 0.9, "lp_gcm2s2": 6.0e6, "h1_gcm2s": 1.5e8}
    compass = StandSpec(simulator={"compass": knobs}).config().compass
    assert dataclasses.asdict(compass).items() >= knobs.items()
    old = {"C_gcm2s2": 5.0e7, "T_s": 0.9, "lP_gcm2s2": 6.0e6, "H1_gcm2s": 1.5e8}
    with pytest.warns(DeprecationWarning) as notes:
        assert StandSpec(simulator={"compass": old}).config().compass == compass
    spelled = [str(n.message) for n in notes if " is spelled " in str(n.message)]
    assert spelled == [  # (not another test's ResourceWarning collected meanwhile)
        f"simulated stand: compass.{o} is spelled {n} now (the old spelling is still read)"
        for o, n in zip(old, knobs, strict=True)
    ]


def test_an_unknown_fault_knob_lists_the_valid_ones() -> None:
    with pytest.raises(StandSetupError) as refused:
        StandSpec(simulator={"faults": {"dorp_rate": 0.1}}).config()
    valid = ", ".join(f.name for f in dataclasses.fields(FaultParams))
    assert str(refused.value).endswith(
        f"faults.dorp_rate: Extra inputs are not permitted; valid: {valid}"
    )
