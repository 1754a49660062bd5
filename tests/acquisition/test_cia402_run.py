"""`campaign run` on the simulated CiA 402 stand (`run_live` -> `run_cia402`): the operator
confirms each new direction K at a prompt; a stop (Ctrl-C, SIGTERM, the station's request)
mid-roll brings the axis to rest by the stop ramp, then disables it."""

from __future__ import annotations

import threading

from sqlalchemy import select

from gyrostand.acquisition import cia402_sim
from gyrostand.acquisition.runner import run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.models import Event
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.devices import sim_drive
from gyrostand.plan.model import parse_plan
from tests.acquisition.test_cia402_campaign import INCLINOMETER, TRIALS, cia402_plan

STOP_AT_S = 120.0  # stand time: trial 1 rocks (from about 100 s)


def test_a_stop_mid_roll_ramps_the_axis_to_rest_after_the_k_prompt(tmp_path, monkeypatch):
    plan = cia402_plan(database=str(tmp_path / "c.sqlite"), raw_dir=str(tmp_path / "raw"))
    assert [p.id for p in plan.prompt] == ["k_trial1", "k_trial2", "k_trial3"]
    stop = threading.Event()
    drives = []
    advance = cia402_sim.SimulatedCia402.advance_to

    def advance_then_stop(self, t_s):  # the signal's handler sets `stop`, at a stand time
        drives.append(self.drive)
        if t_s >= STOP_AT_S:
            stop.set()
        return advance(self, t_s)

    monkeypatch.setattr(cia402_sim.SimulatedCia402, "advance_to", advance_then_stop)
    sessions = open_database(sqlite_url(tmp_path / "c.sqlite"))
    store = CampaignStore.create(sessions, plan)
    result = run_live(plan, store, quiet=True, stop=stop, answers={"k_trial1": "yes"})
    assert result.outcome == "stopped" and result.trials_completed == 0
    with sessions() as session:
        events = session.execute(select(Event.kind, Event.message).order_by(Event.id)).all()
    kinds = [k for k, _ in events]
    assert ("prompt", "k_trial1: " + plan.prompt[0].text) in events
    assert ("answer", "k_trial1: yes") in events
    assert kinds.index("answer") < kinds.index("interrupted")
    (rest,) = [m for k, m in events if k == "stand"]
    assert rest.startswith("the axis at rest and disabled at stand time")
    # the stop ramp (5 s) after the stop (within a 5 s step), then the servo settled (the
    # master waits at most 200 cycles): at rest, the power stage off
    at_s = float(rest.split()[-2])
    assert STOP_AT_S + 5.0 < at_s <= STOP_AT_S + 5.0 + 5.0 + 200 * 0.1
    drive = drives[-1]
    assert drive.at_rest and drive.status == sim_drive.SWITCH_ON_DISABLED


def test_a_campaign_whose_last_roll_fails_brings_the_axis_to_rest(tmp_path):
    """The engine ends on its last trial failed mid-roll (the inclinometer sees 20 % more roll
    than commanded: mis-tracking) without a stop of its own: the run begins the stop ramp and
    the axis is at rest within the ramp and the servo's settling, not left rocking until a
    guard's limit."""
    extra = INCLINOMETER.replace("amplitude_factor = 1.03", "amplitude_factor = 1.2")
    plan = cia402_plan(
        [TRIALS[0]], database=str(tmp_path / "c.sqlite"), raw_dir=str(tmp_path / "raw")
    )
    plan = parse_plan(plan.text.replace("[stand]", extra + "[stand]", 1))
    sessions = open_database(sqlite_url(tmp_path / "c.sqlite"))
    store = CampaignStore.create(sessions, plan)
    result = run_live(plan, store, quiet=True, answers={"k_trial1": "yes"})
    assert result.trials_completed == 0
    with sessions() as session:
        events = session.execute(
            select(Event.kind, Event.message, Event.stand_time_ms).order_by(Event.id)
        ).all()
    (failed_ms,) = [t for k, m, t in events if k == "mis-tracking"]
    (rest,) = [m for k, m, _ in events if k == "stand"]
    assert rest.startswith("the axis at rest and disabled at stand time"), rest
    # the stop ramp (5 s) from the end of the batch the failure was in (5 s steps), then the
    # servo settled (at most 200 cycles of 0.1 s)
    at_s = float(rest.split()[-2])
    assert failed_ms / 1000 + 5.0 < at_s <= failed_ms / 1000 + 5.0 + 5.0 + 200 * 0.1
