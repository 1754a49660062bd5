"""Stand benchmarks: codec cost per frame, simulator throughput, and a 6-trial campaign's worth
of stand time driven live over the virtual bus at 1000x (controller + decoding receiver).

Run: .venv/bin/python bench/bench_stand.py"""

import time
import uuid
from pathlib import Path
from tempfile import TemporaryDirectory

import can

from gyrostand.stand.controller import StandController
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec, HeadingFrame
from gyrostand.stand.schedule import Step, run_schedule
from gyrostand.stand.simulator import SimConfig, Simulator

SETTLE_S = 45 * 60  # per equilibrium change with the default 84-min, 0.7-damped compass
OBSERVE_S = 5 * 30  # 5 observations of ~30 s
TRIALS = [(332, 24, 8), (18, 24, 6.3), (316, 23, 5.5), (346, 11.8, 3.5), (31, 23.5, 6.2), (0, 0, 0)]


def per_call_us(fn, n: int = 20_000) -> float:
    start = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - start) / n * 1e6


def codec_costs() -> None:
    codec = Codec()
    msg = codec.encode_heading(123_456, 201.5, True, 7)
    encode_us = per_call_us(lambda: codec.encode_heading(1, 2.0, True, 3))
    print(f"codec.encode_heading        {encode_us:7.1f} us")
    print(f"codec.decode (heading)      {per_call_us(lambda: codec.decode(msg)):7.1f} us")


def engine_throughput() -> None:
    engine = StandEngine(SimConfig())
    start = time.perf_counter()
    frames = engine.advance_to(3 * 3600.0)
    wall = time.perf_counter() - start
    print(f"engine, 3 h in one batch    {len(frames) / wall:9.0f} frames/s ({wall:.2f} s)")
    engine = StandEngine(SimConfig())
    start = time.perf_counter()
    n = sum(len(engine.advance_to(20.0 * k)) for k in range(1, 541))  # 20-s batches, as at 1000x
    wall = time.perf_counter() - start
    print(f"engine, 3 h in 20-s batches {n / wall:9.0f} frames/s ({wall:.2f} s)")


def standalone_log() -> None:
    steps = [Step("still", 600.0), Step("rock", 3600.0, 31, 23.5, 6.2), Step("still", 600.0)]
    with TemporaryDirectory() as tmp:
        for suffix in (".blf", ".asc"):
            result = run_schedule(SimConfig(), steps, Path(tmp) / f"run{suffix}")
            rate = result.stand_duration_s / result.wall_s
            print(f"standalone {suffix} 80 min      {result.wall_s:7.2f} s wall ({rate:.0f}x)")


def live_campaign(speedup: float = 1000.0) -> None:
    """Stand time of a 6-trial campaign (settle, observe, rock, settle, observe, stop) played live
    against the simulator; reports wall time and the receiver's worst lag behind the stand."""
    channel = f"bench-{uuid.uuid4()}"
    sim_bus = can.Bus(interface="virtual", channel=channel)
    bus = can.Bus(interface="virtual", channel=channel)
    codec = Codec()
    controller = StandController(bus, codec)
    latest = {"ms": -1, "frames": 0}

    class Receiver(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            if msg.arbitration_id == codec.heading_arbitration_id:
                frame = codec.decode(msg)
                if isinstance(frame, HeadingFrame):
                    latest["ms"], latest["frames"] = frame.stand_time_ms, latest["frames"] + 1

    def wait_stand(duration_s: float) -> None:
        target = latest["ms"] + duration_s * 1000
        while latest["ms"] < target:
            time.sleep(0.005)

    simulator = Simulator(sim_bus, SimConfig(timing="realtime", speedup=speedup))
    notifier = can.Notifier(bus, [controller, Receiver()], timeout=0.05)
    worst_lag_s = 0.0
    start = time.perf_counter()
    with simulator:
        for direction, amplitude, period in TRIALS[:-1] + [TRIALS[0]]:
            wait_stand(SETTLE_S + OBSERVE_S)
            controller.set_rocking(direction, amplitude, period)
            controller.start()
            wait_stand(SETTLE_S + OBSERVE_S)
            controller.stop()
            worst_lag_s = max(worst_lag_s, simulator.stand_time_s - latest["ms"] / 1000)
    wall = time.perf_counter() - start
    notifier.stop()
    bus.shutdown()
    sim_bus.shutdown()
    stand_h = latest["ms"] / 3.6e6
    print(
        f"live campaign at {speedup:g}x: {stand_h:.1f} h of stand time, {latest['frames']} heading "
        f"frames decoded, {wall:.1f} s wall, receiver lag <= {worst_lag_s:.0f} stand s"
    )


if __name__ == "__main__":
    codec_costs()
    engine_throughput()
    standalone_log()
    live_campaign()
