"""The campaign engine on a lockstep simulated stand: the sequence of seed 000 §2, the settled
shift of model 1.1, independence of batching, resume, pausing on a failure, bus-off, replay with
another plan. Every fault knob of the simulated stand: test_fault_matrix.py."""

import math

import numpy as np
import pytest

from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.stand.protocol import Codec

from .harness import NoCommands, Recorder, quick_config, small_plan


def run(plan_kwargs: dict | None = None, **faults) -> tuple[Recorder, Lockstep, Engine]:
    plan = small_plan(**(plan_kwargs or {}))
    sink, sim = Recorder(), Lockstep(quick_config(**faults))
    engine = Engine(plan, sink, sim)
    sim.run(engine)
    return sink, sim, engine


def test_sequence_and_settled_shift_of_model_1_1() -> None:
    sink, sim, engine = run({"n_obs": 4})
    assert engine.outcome == "completed"
    obs = sink.observations
    assert [(o.trial, o.j, o.k) for o in obs] == [
        (i, j, k) for i in (1, 2) for j in (1, 2) for k in (1, 2, 3, 4)
    ]
    commands = [args[2] for args in sink.of("event") if args[0] == "command"]
    assert commands == [
        "stop",
        "set K=45 deg, A=24 cm, tau=6 s",
        "start",
        "stop",
        "set K=315 deg, A=20 cm, tau=5 s",
        "start",
        "stop",
    ]
    compass = sim.stand.config.compass
    for index, (k_deg, a_cm, tau_s) in ((1, (45, 24, 6)), (2, (315, 20, 5))):
        before = np.mean([o.value_deg for o in obs if o.trial == index and o.j == 1])
        during = np.mean([o.value_deg for o in obs if o.trial == index and o.j == 2])
        expected = compass.settled_shift_deg(k_deg, a_cm, tau_s)  # seed 000 eq 1.1
        assert abs(expected) > 0.1
        assert during - before == pytest.approx(expected, abs=0.02)
    # windows: 30 s still, 4 rocking periods; consecutive, in stand time
    w = [o for o in obs if o.trial == 1 and o.j == 2]
    assert [o.window_end_ms - o.window_start_ms for o in w] == [24_000] * 4
    assert all(a.window_end_ms == b.window_start_ms for a, b in zip(w, w[1:], strict=False))
    assert all(o.frames_used == 240 and o.frames_lost == 0 and o.flags == "" for o in w)
    measured = sink.measured[0]
    assert measured is not None
    assert (measured.direction_deg, measured.amplitude_cm, measured.period_s) == pytest.approx(
        (45, 24, 6)
    )


def test_result_does_not_depend_on_batching() -> None:
    live, sim, _ = run()
    for size in (7, 977):
        sink = Recorder()
        engine = Engine(small_plan(), sink, NoCommands())
        decoder = BatchDecoder(Codec())
        for start in range(0, len(sim.stream), size):
            chunk = sim.stream[start : start + size]
            engine.feed(decoder.decode(RawFrames.from_messages(start, chunk)))
        assert sink.calls == live.calls
        assert engine.outcome == "completed"


def test_wrap_around_north() -> None:
    from dataclasses import replace

    sink, sim = Recorder(), Lockstep(quick_config())
    compass = replace(sim.stand.config.compass, heading_deg=359.995)
    sim.stand = type(sim.stand)(replace(sim.stand.config, compass=compass), Codec())
    engine = Engine(small_plan(), sink, sim)
    sim.run(engine)
    values = [o.value_deg for o in sink.observations if o.trial == 1]
    # readings straddle 0/360: every mean is next to north (not near 180, the naive mean of
    # 359.99 and 0.01) and all of a trial's values sit on one branch, so differences are plain
    assert all(abs((v - 359.995 + 180) % 360 - 180) < 0.6 for v in values)
    assert max(values) - min(values) < 1.0
    assert any(-0.02 < v < 0 or 359.98 < v < 360 for v in values)


def failure_of(sink: Recorder) -> list[tuple]:
    return [(a[0], a[1], a[2]) for a in sink.of("trial_failed")]


def test_pause_on_failure_stops_the_campaign() -> None:
    sink, sim, engine = run({"on_failure": "pause"}, silence_at_s=150.0, silence_for_s=30.0)
    assert engine.outcome == "paused"
    assert not sink.of("trial_started")[1:]  # trial 2 never started
    assert not sim.stand.rocking


def test_resume_continues_at_the_first_incomplete_series() -> None:
    from gyrostand.acquisition.engine import TrialState

    plan = small_plan()
    progress = {
        1: TrialState(completed=True),
        2: TrialState(series_done=frozenset({1}), committed={1: 3, 2: 1}, reference_deg=120.0),
    }
    sink, sim = Recorder(), Lockstep(quick_config())
    engine = Engine(plan, sink, sim, progress)
    sim.run(engine)
    assert [(o.trial, o.j, o.k) for o in sink.observations] == [(2, 2, 2), (2, 2, 3)]
    commands = [args[2] for args in sink.of("event") if args[0] == "command"]
    assert commands == ["stop", "set K=315 deg, A=20 cm, tau=5 s", "start", "stop"]
    assert math.isclose(sink.observations[0].value_deg, 120.0, abs_tol=1.0)


def test_bus_off_error_frame_fails_the_trial() -> None:
    import can

    class BusOff(Lockstep):
        def run(self, engine: Engine, max_stand_s: float = 200_000.0) -> None:
            advance = self.stand.advance_to

            def with_bus_off(t: float) -> list:
                frames = advance(t)
                if 200.0 < t <= 205.0:  # the controller reports bus-off (SocketCAN class bit)
                    frames.append(can.Message(is_error_frame=True, arbitration_id=0x40))
                return frames

            self.stand.advance_to = with_bus_off  # type: ignore[method-assign]
            super().run(engine, max_stand_s)

    sink, sim = Recorder(), BusOff(quick_config())
    engine = Engine(small_plan(), sink, sim)
    sim.run(engine)
    (trial, _, reason), *_ = failure_of(sink)
    assert trial == 1 and reason == "bus-off reported by the CAN controller"
    assert [a[0] for a in sink.of("event") if a[1] == "error"] == ["bus-off"]


def test_recorder_counts_what_a_full_queue_drops(tmp_path) -> None:
    import can

    from gyrostand.acquisition.bus import Recorder as FrameRecorder

    recorder = FrameRecorder(3, None)
    for i in range(5):
        recorder.on_message_received(can.Message(arbitration_id=i))
    assert recorder.dropped == 2
    assert [m.arbitration_id for m in recorder.drain(2, 0.0)] == [0, 1]
    assert recorder.overflows == []
    recorder.on_message_received(can.Message(arbitration_id=5))  # room again: kept
    assert [m.arbitration_id for m in recorder.drain(10, 0.0)] == [2, 5]
    # where the two went missing: after frame 2, the first of this drain
    assert [(before, o.frames) for before, o in recorder.overflows] == [(1, 2)]
    assert recorder.drain(10, 0.01) == [] and recorder.overflows == []


def test_replay_with_another_plan_is_flagged() -> None:
    _, sim, _ = run()
    sink = Recorder()
    other = small_plan(trials=[(40.0, 24.0, 6.0, "fit"), (315.0, 20.0, 5.0, "control")])
    engine = Engine(other, sink, NoCommands())
    decoder = BatchDecoder(Codec())
    engine.feed(decoder.decode(RawFrames.from_messages(0, sim.stream)))
    foreign = [a for a in sink.of("event") if a[0] == "foreign command"]
    assert foreign and foreign[0][1] == "warning"
