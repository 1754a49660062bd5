"""The [inclinometer] table: what each protocol needs, its own bus refused for now, the arm it
needs to turn a roll angle into A, and the simulated stand carrying it as the plan mounts it."""

from __future__ import annotations

from pathlib import Path

import pytest

from gyrostand.plan.codec import prepare, stand_config
from gyrostand.plan.model import PlanError, parse_plan

PAPER = (Path(__file__).resolve().parents[2] / "examples" / "paper.toml").read_text()
ARM = "\n[stand]\narm_length_cm = 120.0\n"


def problems(extra: str) -> list[str]:
    with pytest.raises(PlanError) as caught:
        parse_plan(PAPER + extra)
    return caught.value.problems


def test_each_protocol_names_its_device() -> None:
    assert problems(ARM + '[inclinometer]\nprotocol = "cia410"\n') == [
        '[inclinometer] node_id: missing (protocol = "cia410")'
    ]
    assert problems(ARM + '[inclinometer]\nprotocol = "j1939"\nnode_id = 3\nscale = 0.01\n') == [
        '[inclinometer] source_address: missing (protocol = "j1939")',
        '[inclinometer] node_id: not with protocol = "j1939" (cia410\'s)',
        "[inclinometer] scale: j1939: +1 or -1 (the slope's unit is the standard's)",
    ]


def test_its_own_bus_is_refused_and_the_arm_is_needed() -> None:
    own = '[inclinometer]\nprotocol = "cia410"\nnode_id = 4\ninterface = "socketcan"\n'
    assert problems(ARM + own) == [
        "[inclinometer] interface: an inclinometer on a bus of its own is not supported yet: "
        "put it on the stand's bus"
    ]
    assert problems('[inclinometer]\nprotocol = "cia410"\nnode_id = 4\n') == [
        "[stand] arm_length_cm: missing: the inclinometer measures the roll angle; A is arm x "
        "angle (rad)"
    ]


def test_the_simulated_stand_carries_it_as_mounted() -> None:
    plan = parse_plan(
        ARM.join(
            [
                PAPER,
                '[inclinometer]\nprotocol = "cia410"\nnode_id = 9\naxis = "y"\nscale = -0.001\n',
            ]
        )
    )
    assert plan.inclinometer_mount == ("cia410", 9, "y", -0.001)
    incl = stand_config(plan).inclinometer
    assert (incl.node_id, incl.axis, incl.step_deg, incl.arm_length_cm) == (9, "y", -0.001, 120.0)
    assert stand_config(parse_plan(PAPER)).inclinometer.node_id is None
    j1939 = parse_plan(PAPER + ARM + '[inclinometer]\nprotocol = "j1939"\nsource_address = 226\n')
    assert j1939.inclinometer_mount == ("j1939", 226, "x", 1.0)
    with pytest.raises(PlanError, match='simulated stand carries a "cia410" inclinometer only'):
        prepare(j1939)
