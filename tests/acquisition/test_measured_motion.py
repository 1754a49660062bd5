"""The rocking series' measured motion in the engine (lockstep simulated stand with a CiA 410
inclinometer, virtual time): the inclinometer's A and tau are what the trial applies, the
stand's own reports kept beside them; a stand that rocks outside the [tracking] tolerance while
reporting the command fails the trial with the measured amplitude named."""

from __future__ import annotations

import dataclasses
import math
import re

from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.devices.decoder import frame_decoder
from gyrostand.plan.model import parse_plan
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import InclinometerParams
from tests.acquisition.harness import Recorder, plan_text, quick_config

ARM_CM = 100.0
TEXT = (
    plan_text([(45.0, 24.0, 6.0, "fit")], n_obs=2).replace(
        "[tracking]\n", f"[stand]\narm_length_cm = {ARM_CM}\n\n[tracking]\n"
    )
    + '\n[inclinometer]\nprotocol = "cia410"\nnode_id = 4\n'
)
PLAN = parse_plan(TEXT)


def run(amplitude_factor: float) -> Recorder:
    """One trial; the stand reports the commanded amplitude whatever it makes."""
    config = dataclasses.replace(
        quick_config(seed=2, amplitude_factor=amplitude_factor, amplitude_unreported=True),
        heading_rate_hz=2.0,
        status_rate_hz=0.5,
        inclinometer=InclinometerParams(node_id=4, arm_length_cm=ARM_CM, rate_hz=5.0),
    )
    codec = Codec()
    decoder = lambda: frame_decoder(codec, *PLAN.heading_source, PLAN.inclinometer_mount)  # noqa: E731
    stand = Lockstep(config, 5.0, codec, (None, decoder))  # type: ignore[arg-type]
    sink = Recorder()
    stand.run(Engine(PLAN, sink, stand))
    return sink


def test_the_trial_applies_the_inclinometers_amplitude() -> None:
    sink = run(1.03)
    (completed,) = sink.of("trial_completed")
    (rocking,) = [args for args in sink.of("series_completed") if args[1] == 2]
    incl, report = rocking[3]
    assert (incl.source, report.source) == ("inclinometer", "stand report")
    # the platform rolls at 1.03 x 24 cm: the angle 24.72 / 100 rad the inclinometer sees
    assert abs(incl.amplitude_cm - 1.03 * 24.0) < 4 * incl.amplitude_se_cm + 1e-3
    assert abs(incl.period_s - 6.0) < 4 * incl.period_se_s + 1e-5
    assert incl.n_cycles == 7 and incl.direction_deg is None
    assert report.amplitude_cm == 24.0 and report.direction_deg == 45.0
    measured = completed[1]
    assert (measured.amplitude_cm, measured.period_s) == (incl.amplitude_cm, incl.period_s)
    assert measured.direction_deg == 45.0  # K: the stand's (the inclinometer knows none)
    assert not [a for a in sink.of("event") if a[1] != "info"]


def test_motion_outside_the_tracking_tolerance_fails_the_trial() -> None:
    sink = run(1.08)  # [tracking] amplitude_rel 0.05 by default
    (failed,) = sink.of("trial_failed")
    assert failed[:2] == (1, 2)
    found = re.fullmatch(
        r"measured amplitude (\S+) cm \(inclinometer\), commanded 24 cm: outside \[tracking\] "
        r"amplitude_rel 0.05",
        failed[2],
    )
    assert found is not None and math.isclose(float(found[1]), 1.08 * 24.0, abs_tol=0.005)
    assert not sink.of("trial_completed")
