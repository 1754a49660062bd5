"""Controller + the plugin's simulated stand in real time on python-can's `virtual` bus (one
channel per test)."""

import errno
import threading
import time
import uuid
from collections.abc import Callable, Iterator

import can
import numpy as np
import pytest
from can.interfaces.virtual import VirtualBus

from gyrostand.simulated_stand import SimulatedStand, StandSpec
from gyrostand.stand.controller import StandController, StandError, StandRefused, StandTimeout
from gyrostand.stand.protocol import Codec, HeadingFrame, Reason
from gyrostand.stand.simulator import CompassParams


class Collector(can.Listener):
    """Keeps the heading frames; lets the test wait for a stand time."""

    def __init__(self, codec: Codec) -> None:
        self.codec = codec
        self.times_ms: list[int] = []
        self.readings: list[float] = []
        self._new = threading.Condition()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == self.codec.heading_arbitration_id:
            frame = self.codec.decode(msg)
            if isinstance(frame, HeadingFrame):
                with self._new:
                    self.times_ms.append(frame.stand_time_ms)
                    self.readings.append(frame.heading_deg)
                    self._new.notify_all()

    @property
    def now_ms(self) -> int:
        return self.times_ms[-1] if self.times_ms else -1

    def wait_until(self, stand_ms: float, timeout_s: float = 30.0) -> None:
        with self._new:
            if not self._new.wait_for(lambda: self.now_ms >= stand_ms, timeout_s):
                raise AssertionError(f"stand time {stand_ms} ms not reached, at {self.now_ms}")

    def mean_between(self, start_ms: float, end_ms: float) -> float:
        t = np.array(self.times_ms)
        return float(np.mean(np.array(self.readings)[(t >= start_ms) & (t < end_ms)]))


class Rig:
    """The plugin's simulated stand in real time (virtual time is tested with the acquisition
    that drives it); a controller + collector on their own node of its bus."""

    def __init__(self, stand: SimulatedStand, ack_timeout_s: float = 2.0) -> None:
        self.stand = stand
        self.simulator = stand.simulator
        self.bus = stand.open_bus()
        self.codec = Codec()
        self.controller = StandController(self.bus, self.codec, ack_timeout_s=ack_timeout_s)
        self.collector = Collector(self.codec)

    def __enter__(self) -> "Rig":
        self.notifier = can.Notifier(self.bus, [self.controller, self.collector], timeout=0.05)
        return self

    def __exit__(self, *exc: object) -> None:
        self.notifier.stop()
        self.stand.close()

    def wait_status(self, predicate, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            status = self.controller.last_status
            if status is not None and predicate(status):
                return
            time.sleep(0.01)
        raise AssertionError(f"status never matched; last {self.controller.last_status}")


@pytest.fixture
def realtime(gyro_stand_factory) -> Callable[..., Rig]:
    """`realtime(ack_timeout_s=..., **knobs)`: a Rig on a stand paced by the wall clock."""

    def make(ack_timeout_s: float = 2.0, **knobs) -> Rig:
        return Rig(gyro_stand_factory(timing="realtime", **knobs), ack_timeout_s)

    return make


@pytest.fixture
def rig(realtime) -> Iterator[Rig]:
    with realtime(speedup=200) as r:
        yield r


def test_command_ack_status_cycle(rig: Rig) -> None:
    rig.wait_status(lambda s: not s.rocking)
    rig.controller.set_rocking(31.0, 23.5, 6.2)
    rig.controller.start()
    rig.wait_status(lambda s: s.rocking)
    error = rig.controller.tracking_error(31.0, 23.5, 6.2)
    assert (error.direction_error_deg, error.amplitude_rel_error, error.period_rel_error) == (
        0.0,
        0.0,
        0.0,
    )
    assert error.within(0.01, 0.1)
    rig.controller.stop()
    rig.wait_status(lambda s: not s.rocking and s.amplitude_cm == 0.0)
    with pytest.raises(StandError, match="no status of a rocking stand"):
        rig.controller.tracking_error(31.0, 23.5, 6.2)


def test_refusal_is_a_typed_error(rig: Rig) -> None:
    with pytest.raises(StandRefused) as refused:
        rig.controller.set_rocking(31.0, 80.0, 6.2)
    assert refused.value.reason == Reason.AMPLITUDE and refused.value.command == "set"
    with pytest.raises(StandRefused, match="not configured"):
        rig.controller.start()


def test_silent_stand_times_out(realtime) -> None:
    with realtime(ack_timeout_s=0.3, speedup=200, faults={"no_ack": True}) as rig:
        started = time.monotonic()
        with pytest.raises(StandTimeout, match="did not acknowledge 'set' within 0.3 s"):
            rig.controller.set_rocking(31.0, 23.5, 6.2)
        assert 0.3 <= time.monotonic() - started < 2.0


def test_wrong_amplitude_shows_in_tracking(realtime) -> None:
    with realtime(speedup=200, faults={"amplitude_factor": 0.8}) as rig:
        rig.controller.set_rocking(45.0, 30.0, 5.0)
        rig.controller.start()
        rig.wait_status(lambda s: s.rocking)
        error = rig.controller.tracking_error(45.0, 30.0, 5.0)
        assert error.amplitude_rel_error == pytest.approx(-0.2)
        assert not error.within(0.05, 1.0)


def test_start_stop_rocking_cycle_settles_at_model_1_1(realtime) -> None:
    # a compass with a 10-minute precession period so the cycle takes ~1.5 h of stand time
    compass = {"undamped_period_s": 600.0}
    knobs = {"heading_rate_hz": 2.0, "status_rate_hz": 0.5, "compass": compass, "seed": 5}
    with realtime(speedup=2000, **knobs) as rig:
        rig.collector.wait_until(600_000)
        at_rest = rig.collector.mean_between(0, 600_000)
        rig.controller.set_rocking(45.0, 40.0, 4.0)
        rig.controller.start()
        started_ms = rig.collector.now_ms
        rig.collector.wait_until(started_ms + 40 * 60_000)
        rocking = rig.collector.mean_between(started_ms + 25 * 60_000, started_ms + 40 * 60_000)
        rig.controller.stop()
        stopped_ms = rig.collector.now_ms
        rig.collector.wait_until(stopped_ms + 35 * 60_000)
        back = rig.collector.mean_between(stopped_ms + 25 * 60_000, stopped_ms + 35 * 60_000)
    shift = CompassParams().settled_shift_deg(45.0, 40.0, 4.0)  # seed 000 eq 1.1: 3.36 deg
    assert at_rest == pytest.approx(120.0, abs=0.01)
    assert rocking - at_rest == pytest.approx(shift, abs=0.01)
    assert back == pytest.approx(120.0, abs=0.01)
    assert shift == pytest.approx(3.36, abs=0.01)


def test_stopping_the_notifier_does_not_command_the_stand(rig: Rig) -> None:
    rig.controller.set_rocking(31.0, 23.5, 6.2)
    rig.controller.start()
    started = time.monotonic()
    rig.notifier.stop()  # python-can calls Listener.stop() here: it must not wait for an ack
    assert time.monotonic() - started < 1.0
    assert rig.simulator.engine.rocking


class LinkDownOnce(VirtualBus):
    """A virtual bus whose first receive and first send fail as python-can's SocketCAN bus does
    on a downed link (ENETDOWN)."""

    def __init__(self, channel: str) -> None:
        super().__init__(channel=channel)
        self.recv_failures = self.send_failures = 1

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.recv_failures:
            self.recv_failures -= 1
            raise can.CanOperationError("Error receiving: Network is down", errno.ENETDOWN)
        return super()._recv_internal(timeout)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.send_failures:
            self.send_failures -= 1
            raise can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)
        super().send(msg, timeout)


def test_stand_keeps_running_through_a_link_down() -> None:
    """ENETDOWN on receive is counted, not fatal; a frame that meets ENETDOWN is dropped at once
    (only a full transmit queue is retried); commands are answered afterwards."""
    channel = f"gyrostand-test-{uuid.uuid4()}-link"
    spec = StandSpec({"timing": "realtime", "speedup": 200}, channel=channel)
    with Rig(SimulatedStand(spec, sim_bus=LinkDownOnce(channel))) as rig:
        rig.controller.set_rocking(31.0, 23.5, 6.2)
        rig.controller.start()
        rig.wait_status(lambda s: s.rocking)
        assert (rig.simulator.receive_errors, rig.simulator.frames_failed) == (1, 1)
        assert rig.simulator.error is None


@pytest.mark.socketcan
def test_command_cycle_over_socketcan(realtime, socketcan_channel: str) -> None:
    with realtime(interface="socketcan", channel=socketcan_channel, speedup=100) as rig:
        rig.controller.set_rocking(31.0, 23.5, 6.2)
        rig.controller.start()
        rig.wait_status(lambda s: s.rocking and s.amplitude_cm == 23.5)
        rig.controller.stop()
        rig.wait_status(lambda s: not s.rocking)
        assert rig.collector.now_ms > 0
