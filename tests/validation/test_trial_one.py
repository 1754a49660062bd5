"""validation/trial_one.py (issue 34): trial 1 of the shipped plan through the whole chain, its
series errors split into the reading's noise and the rest. The split is exact where the physics
says it must be: the compass a campaign starts with is at rest at its settle point, so the still
series' error is its readings' noise to round-off; the rocking series' rest is what the transient
bound leaves (the fitted transient + 2 SE within 0.05 S_e = 0.00075 deg) plus the reading's grid
(a 16-bit step is 0.0055 deg). One draw (~4 s of CPU): in the slow stage."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load_script():
    sys.path.insert(0, str(ROOT / "validation"))
    spec = importlib.util.spec_from_file_location("trial_one", ROOT / "validation/trial_one.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


def test_trial_one_splits_into_noise_and_a_bounded_rest() -> None:
    script = load_script()
    draw = script.draws(1, 1)[0]
    still, rocking = script.split(draw)
    assert (still.j, rocking.j) == (1, 2)
    assert abs(still.error_deg - still.noise_deg) < 1e-9  # at rest: the noise, nothing else
    assert abs(still.noise_deg) > 1e-4  # (and the noise is there)
    rest = rocking.error_deg - rocking.noise_deg
    assert -0.0015 < rest < 0  # the overshoot left and the grid, both below the 0.05 S_e bound
    text = script.table([[still, rocking], [still, rocking]], first=34)
    assert f"rest {rest:+.5f} +- 0.00000" in text
