"""Resume of a campaign on the simulated CiA 402 stand (virtual time, SYNC in stand time): a
killed run's resume re-runs the simulation from its start (a new drive, at rest and enabled by
the master's setup) and skips what the database holds, so that the campaign ends as the
uninterrupted one, row for row and frame for frame (`killing.kill_and_resume`); a stopped run's
resume goes on at its first incomplete series, the campaign clock going on from its last stored
time."""

from functools import partial
from pathlib import Path

import pytest

from gyrostand.acquisition import bus, cia402_run
from gyrostand.acquisition.cia402_sim import SimulatedCia402

from .killing import kill_and_resume, small_containers
from .test_cia402_campaign import SERVO, STAND

COMPASS = '\n[compass]\nprotocol = "nmea2000"\n'


def test_kill_9_then_resume_equals_the_uninterrupted_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(bus, "raw_log_writer", small_containers)
    # the servo integrated in 5 ms steps: quicker (the forked runs inherit the patches)
    monkeypatch.setattr(cia402_run, "SimulatedCia402", partial(SimulatedCia402, servo=SERVO))
    plan = {"trials": [(45.0, 24.0, 6.0, "fit")], "n_obs": 2, "hold_s": 30.0}
    answers = ("k_trial1=yes",)  # K set by hand
    run = kill_and_resume(tmp_path, 1, 3, compass=STAND + COMPASS, answers=answers, plan=plan)
    assert run.problems == ()
    assert run.kills >= 1
