"""The standard's procedures on a real bus (issue 35): the campaign's procedure stage on python-
can's `virtual` bus, the simulated compass and stand in a thread of their own in real time (sped
up, as `gyrostand simulate --timing realtime --speedup X` runs them), switched on as it starts
(its run-up from rotor stop, `stand.runup`). The operator's answer starts the run-up; a stop
request part-way keeps the switch-on and the frames heard, and the resumed run goes on with that
run-up. The results are checked against the simulator's truth within their stated
uncertainties; no assertion on wall time (the waits are guards against a hang only).

The operator's switching of the compass for the repeatability's run-ups: its simulator stopped,
a new one started (the run-up from rotor stop, the stand clock going on). And the live path and
the virtual one as one procedure: the simulated compass's frames brought as a bus at 1x brings
them (no thread, no clock) give the virtual path's results to the bit.

~20-25 s of wall time each (2500-3400 s of stand time at 150x): in SLOW_FILES. The readings lie
100 s apart, 5 correlation times of the simulated noise (closer, they are not independent and
the stated uncertainty of their mean is too small)."""

from __future__ import annotations

import math
import sqlite3
import threading
import uuid
from pathlib import Path

import can
import numpy as np
import pytest

from gyrostand.acquisition.bus import Recorder
from gyrostand.acquisition.operator import messages
from gyrostand.acquisition.procedures import run_procedures, stored_progress
from gyrostand.acquisition.procedures_live import BusHeadings, LiveRunUp, ProcedureBusError
from gyrostand.acquisition.store import CampaignStore
from gyrostand.campaign_procedures import run_procedures_of
from gyrostand.db.session import open_database
from gyrostand.frames.logfile import read_raw_frames
from gyrostand.plan.model import parse_plan
from gyrostand.plan.prompts import ANSWER, PROMPT, STOP_REQUEST, keyed, message
from gyrostand.report.compliance import load_profile
from gyrostand.report.stored import stored_procedures
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec
from gyrostand.stand.runup import (
    runup_config,
    switch_on,
    true_settle_point_deg,
    true_settling_time_s,
)
from gyrostand.stand.simconfig import CompassParams, SimConfig
from gyrostand.stand.simulator import Simulator
from tests.acquisition.harness import plan_text
from tests.procedures.test_procedures import PAPER, inputs, manual_on_a_real_bus
from tests.report.test_compliance import A821, lab_verified, profile_file

SPEEDUP = 150.0
STOP_AT_S = 900.0  # stand time of the station's stop request (during the settling record)
GUARD_WALL_S = 300.0  # against a hang only
PROCEDURES = """
[standard]
profile = "imo-a821"
[reference]
heading_deg = 120.0
uncertainty_deg = 0.01
[[procedure]]
kind = "settling"
max_wait_s = 1200.0
power = "manual"
[[procedure]]
kind = "settle_point"
readings = 5
interval_s = 100.0
[[procedure]]
kind = "rolling"
wait_s = 600.0
readings = 3
interval_s = 60.0
points = [{direction_deg = 45, amplitude_cm = 24, period_s = 6}]
"""


def live_plan(tmp_path: Path, channel: str) -> str:
    text = plan_text(
        [(45.0, 24.0, 6.0, "fit")],
        database=str(tmp_path / "p.sqlite"),
        raw_dir=str(tmp_path / "raw"),
    )
    bus = f'simulated = false\ninterface = "virtual"\nchannel = "{channel}"\ntiming = "realtime"'
    text = text.replace("simulated = true", bus).replace("seed = 1\n", "")
    # guards against a hang only, generous: the machine may be loaded (wall seconds)
    guards = {"ack_s = 2.0": "ack_s = 30.0", "bus_silence_s = 5.0": "bus_silence_s = 30.0"}
    for was, now in guards.items():
        assert was in text
        text = text.replace(was, now)
    transient = "max_wait_s = 3600.0\nundamped_period_s = 240.0\ndamping_ratio = 0.8"
    return text.replace("max_wait_s = 3600.0", transient) + PROCEDURES


class Operator(threading.Thread):
    """The operator at the station: answers each switching prompt, switching the simulated
    compass (off: its simulator stopped; on: a new one, run-up k from rotor stop, its stand
    clock going on from the last). The compass is switched on once the acquisition waits for
    the first frame after the answer (`switching`, a spy on `BusHeadings.next_heard_s`), so that
    the run-up's switch-on is the simulator's start, not a wall-time race: the results do not
    depend on the machine's load."""

    def __init__(self, store: CampaignStore, bus: can.BusABC, base: SimConfig) -> None:
        super().__init__(daemon=True)
        self.store, self.bus, self.base = store, bus, base
        self.simulators: list[Simulator] = []
        self.started = threading.Event()  # run-up 1's simulator is running
        self.done = threading.Event()
        self.switching = threading.Event()

    def spy(self, monkeypatch: pytest.MonkeyPatch) -> None:
        next_heard_s = BusHeadings.next_heard_s

        def spied(heard: BusHeadings) -> float:
            self.switching.set()
            return next_heard_s(heard)

        monkeypatch.setattr(BusHeadings, "next_heard_s", spied)

    def run(self) -> None:
        answered: set[str] = set()
        while not self.done.wait(0.05):
            with self.store.sessions() as session:
                asked = keyed(messages(session, self.store.campaign_id, PROMPT))
            for prompt in sorted(asked.keys() - answered):
                kind, k = prompt.rsplit("_", 1)
                answered.add(prompt)
                if kind == "switch_off":
                    self.simulators[-1].stop()
                    self.answer(prompt)
                    continue
                self.switching.clear()
                self.answer(prompt)
                if not self.switching.wait(GUARD_WALL_S):
                    return
                clock_ms = 0
                if self.simulators:
                    last = self.simulators[-1]
                    clock_ms = last.engine.clock_ms + math.ceil(last.stand_time_s) * 1000
                on = Simulator(self.bus, runup_config(self.base, int(k)), clock_ms=clock_ms)
                on.start()
                self.simulators.append(on)
                self.started.set()

    def answer(self, prompt: str) -> None:
        self.store.run_event(ANSWER, "info", message(prompt, "yes"))

    def stop_all(self) -> None:
        self.done.set()
        self.join(GUARD_WALL_S)
        if self.simulators:
            self.simulators[-1].stop()


def compass_config(seed: int) -> SimConfig:
    return SimConfig(
        compass=CompassParams(undamped_period_s=240.0, damping_ratio=0.8),
        timing="realtime",
        speedup=SPEEDUP,
        seed=seed,
    )


def test_procedures_on_a_real_bus_recover_the_simulated_compass_truth(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    channel = f"gyrostand-procbus-{uuid.uuid4().hex}"
    plan = parse_plan(live_plan(tmp_path, channel))
    base = compass_config(2)
    compass = runup_config(base, 1)
    sessions = open_database(f"sqlite:///{tmp_path / 'p.sqlite'}")
    store = CampaignStore.create(sessions, plan)

    def stop_request() -> None:  # the station's, during the settling record
        if not operator.started.wait(GUARD_WALL_S):
            return
        try:
            operator.simulators[0].wait_until(STOP_AT_S, GUARD_WALL_S)
        except TimeoutError:
            return
        store.run_event(STOP_REQUEST, "info", "stop requested at the station")

    with can.Bus(interface="virtual", channel=channel) as bus:
        operator = Operator(store, bus, base)
        operator.spy(monkeypatch)
        operator.start()
        requester = threading.Thread(target=stop_request, daemon=True)
        requester.start()
        try:
            assert run_procedures_of(plan, store, True, threading.Event()) is False
            requester.join(GUARD_WALL_S)
            complete, done = stored_progress(sessions, store.campaign_id)
            assert not complete and set(done) == {"switch_on_s"}  # the settling under way
            store.run_event("resume", "info", "resumed")  # the stop request before it is spent
            assert run_procedures_of(plan, store, True, threading.Event()) is True
            assert not operator.simulators[0].engine.rocking  # the point's stop acknowledged
        finally:
            operator.stop_all()
    with sessions() as session:
        out = stored_procedures(session, store.campaign_id)
        events = messages(session, store.campaign_id, "procedures")
        asked = messages(session, store.campaign_id, PROMPT)
    assert out is not None
    on = "switch_on_1: switch the compass on: run-up 1 (settling from switch-on) starts"
    assert asked == [on]
    assert (
        "run-up 1 switched on at stand time 0 s (the first frame heard after the operator's answer)"
    ) in events
    assert done["switch_on_s"] == {"1": 0.0}
    assert events[-2] == "the standard's procedures resumed: kept the switch-on of run-up 1"
    # settling (a gap in its record where the run was stopped and resumed)
    s = out.settling
    truth = true_settling_time_s(compass, s.half_band_deg, 1200.0)
    assert s.settled and abs(s.value_s - truth) <= s.expanded_s
    assert 0 < s.expanded_s < 60
    p = out.settle_point
    true_error = true_settle_point_deg(base, 1) - 120.0
    assert abs(p.error_deg - true_error) <= p.error_expanded_deg
    noise = base.noise
    sigma = math.hypot(noise.white_sigma_deg, noise.corr_sigma_deg)
    assert abs(p.rms_deg - sigma) <= p.rms_expanded_deg
    (rolled,) = out.rolling
    shift = base.compass.settled_shift_deg(45.0, 24.0, 6.0)
    assert not rolled.forecast and abs(rolled.error_deg - shift) <= rolled.expanded_deg
    assert abs(shift) > 5 * rolled.expanded_deg  # the rolling error is there, and resolved
    # the raw logs: the stopped run's and the resumed run's, stamped by reception
    first = tmp_path / "raw" / "p-campaign-1.procedures.blf"
    resumed = first.with_name("p-campaign-1.procedures-resume1.blf")
    assert sorted((tmp_path / "raw").glob("*.procedures*.blf")) == [resumed, first]
    stamps = np.concatenate([raw.timestamp for raw in read_raw_frames(first)])
    # in wall seconds: STOP_AT_S of stand time took ~STOP_AT_S / SPEEDUP
    assert np.ptp(stamps) < STOP_AT_S / 5
    with sqlite3.connect(tmp_path / "p.sqlite") as conn:
        raw = [m for (m,) in conn.execute("SELECT message FROM event WHERE kind = 'raw log'")]
    assert f"the standard's procedures' earlier frames in {first}" in raw
    assert any(m.startswith(f"the standard's procedures' frames in {resumed}") for m in raw)


REPEATABILITY = """
[standard]
profile = "imo-a821"
[[procedure]]
kind = "settling"
max_wait_s = 1200.0
power = "manual"
[[procedure]]
kind = "repeatability"
runups = 2
off_s = 60.0
readings = 5
interval_s = 100.0
power = "manual"
"""


def test_repeatability_on_a_real_bus_the_operator_switching_the_compass(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    channel = f"gyrostand-procbus-{uuid.uuid4().hex}"
    text = live_plan(tmp_path, channel)
    plan = parse_plan(text[: text.index("[standard]")] + REPEATABILITY)
    base = compass_config(3)
    sessions = open_database(f"sqlite:///{tmp_path / 'p.sqlite'}")
    store = CampaignStore.create(sessions, plan)
    with can.Bus(interface="virtual", channel=channel) as bus:
        operator = Operator(store, bus, base)
        operator.spy(monkeypatch)
        operator.start()
        try:
            assert run_procedures_of(plan, store, True, threading.Event()) is True
        finally:
            operator.stop_all()
    assert len(operator.simulators) == 2
    second = operator.simulators[1].engine.clock_ms / 1000.0
    with sessions() as session:
        out = stored_procedures(session, store.campaign_id)
        events = messages(session, store.campaign_id, "procedures")
        asked = [m.split(":")[0] for m in messages(session, store.campaign_id, PROMPT)]
    assert asked == ["switch_on_1", "switch_off_2", "switch_on_2"]
    assert f"run-up 2 switched on at stand time {second:g} s" in events[1]
    assert out is not None and out.repeatability is not None
    r = out.repeatability
    truth = [true_settle_point_deg(base, k) for k in (1, 2)]
    assert abs(r.range_deg - (max(truth) - min(truth))) <= r.expanded_deg
    assert 0 < r.expanded_deg < 0.05  # a real uncertainty, not a blanket one


SHORT = """
[bus.simulator]
heading_rate_hz = 2.0
[bus.simulator.compass]
undamped_period_s = 1200.0
[reference]
heading_deg = 120.0
uncertainty_deg = 0.01
[[procedure]]
kind = "settling"
max_wait_s = 2400.0
[[procedure]]
kind = "settle_point"
readings = 3
interval_s = 300.0
[[procedure]]
kind = "repeatability"
runups = 2
readings = 3
interval_s = 300.0
[[procedure]]
kind = "rolling"
wait_s = 600.0
readings = 2
interval_s = 100.0
points = [{direction_deg = 45, amplitude_cm = 24, period_s = 6}]
"""


class CompassAt1x:
    """The simulated compass's frames as a real bus brings them: the next second of stand time
    once the acquisition has taken what came (`arrive`, its poll's `check`), and its stand
    answering commands (`post`, as the stand controller sends them); `procedures_live` without
    a bus or a wall clock."""

    def __init__(self, config: SimConfig) -> None:
        self.config, self.codec = config, Codec()
        self.recorder = Recorder(10**7, None)
        self.own_bus, self.controller = False, self
        self.engine: StandEngine | None = None
        self.heard: BusHeadings
        self.sent = 0

    def switch_on(self, k: int, at_s: float) -> None:
        self.engine = switch_on(self.config, k, at_s)

    def arrive(self) -> None:
        assert self.engine is not None
        if self.heard.position == self.sent:  # (all taken: an ack before the next second)
            self.send(self.engine.advance_to(self.engine.stand_time_s + 1.0))

    def post(self, name: str, *motion: float) -> int:
        assert self.engine is not None
        self.send(self.engine.receive(self.codec.encode_command(name, *motion)))
        return 0

    def send(self, frames: list[can.Message]) -> None:
        self.recorder.on_messages(frames)
        self.sent += len(frames)


def test_on_a_real_bus_the_same_procedures_give_the_virtual_results_to_the_bit(
    tmp_path: Path,
) -> None:
    """The live path (`LiveRunUp` on the frames as they arrive, every one recorded, the stand
    commanded through its controller and its acks awaited) and the virtual one (`RunUp`, nobody
    listening between readings) are one procedure: on the same compass, the same results."""
    profile = load_profile(profile_file(tmp_path, lab_verified(A821)))
    fast = PAPER.replace("undamped_period_s = 5064.0", "undamped_period_s = 1200.0")
    virtual_plan = parse_plan(fast + SHORT)
    plan_inputs = inputs(virtual_plan, profile)
    virtual = run_procedures(*plan_inputs)
    compass = CompassAt1x(plan_inputs[0])
    real = virtual_plan.model_copy(update={"bus": manual_on_a_real_bus().bus})
    heard = compass.heard = BusHeadings(real, compass, compass.arrive)  # type: ignore[arg-type]

    def runup(k: int, at_s: float) -> LiveRunUp:
        compass.switch_on(k, at_s)  # (at the virtual path's switch-on: the same compass)
        return LiveRunUp(heard, k, at_s)

    live = run_procedures(*plan_inputs, runups=runup)
    assert live.to_dict() == virtual.to_dict()
    assert live.rolling[0].error_deg is not None and live.repeatability is not None
    assert heard.position > 4 * 2400  # every frame heard (2 Hz headings, 2 Hz status)


class SilentCompass(CompassAt1x):
    """The compass falls silent (its heading frames no longer sent) from `silent_s` of stand
    time on, the stand's statuses going on."""

    def __init__(self, config: SimConfig, silent_s: float) -> None:
        super().__init__(config)
        self.silent_s = silent_s
        self.heading_id = self.codec.heading_arbitration_id

    def send(self, frames: list[can.Message]) -> None:
        assert self.engine is not None
        if self.engine.stand_time_s >= self.silent_s:
            frames = [f for f in frames if f.arbitration_id != self.heading_id]
        super().send(frames)


def test_on_a_real_bus_a_compass_that_falls_silent_stops_the_procedures_in_one_line(
    tmp_path: Path,
) -> None:
    """No heading for the plan's silence timeout of stand time, while the stand's statuses go
    on: the procedures stop with one line naming the silent compass (the campaign's "bus error"
    event, `cmd_campaign`), not a wait without end."""
    profile = load_profile(profile_file(tmp_path, lab_verified(A821)))
    fast = PAPER.replace("undamped_period_s = 5064.0", "undamped_period_s = 1200.0")
    plan = parse_plan(fast + SHORT)
    plan_inputs = inputs(plan, profile)
    compass = SilentCompass(plan_inputs[0], silent_s=300.0)
    real = plan.model_copy(update={"bus": manual_on_a_real_bus().bus})
    heard = compass.heard = BusHeadings(real, compass, compass.arrive)  # type: ignore[arg-type]

    def runup(k: int, at_s: float) -> LiveRunUp:
        compass.switch_on(k, at_s)
        return LiveRunUp(heard, k, at_s)

    with pytest.raises(ProcedureBusError) as raised:
        run_procedures(*plan_inputs, runups=runup)
    silence_s = real.timeouts.bus_silence_s
    assert str(raised.value).startswith("the compass is silent: no heading for ")
    quiet_s = float(str(raised.value).split("no heading for ")[1].split(" s")[0])
    assert silence_s < quiet_s <= silence_s + 1.0  # (the stand's next second)
    assert heard.now_ms / 1000.0 == pytest.approx(300.0 + quiet_s, abs=1.0)
