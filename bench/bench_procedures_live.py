"""The standard's procedures on a real bus: what listening costs (`procedures_live`).

On a real stand the procedures listen to the compass for hours in real time (a settling record
of up to 6 h, then readings 20 minutes apart), every frame heard decoded, logged and kept: the
poll runs every DRAIN_WALL_S or as frames come. This feeds the simulated compass's run-up (10 Hz
headings, 2 Hz stand status) into the acquisition's queue as a bus at 1x would, one poll's worth
at a time, through `BusHeadings` and `LiveRunUp.advance` (no bus, no raw log file: the decode and
the record), and prints the CPU seconds per hour of stand time (the share of one core real time
takes), with the load average. Target: a small share of a core (the trials' acquisition runs on
the same machine afterwards; a settling record must not grow costlier as it grows). Wall time
is not printed: the polls without a frame wait for one, as they do live.

Run: .venv/bin/python bench/bench_procedures_live.py"""

from __future__ import annotations

import os
import time
from pathlib import Path
from types import SimpleNamespace

from gyrostand.acquisition.bus import Recorder
from gyrostand.acquisition.procedures_live import BusHeadings, LiveRunUp
from gyrostand.plan.model import parse_plan
from gyrostand.stand.runup import switch_on
from gyrostand.stand.simconfig import SimConfig

ROOT = Path(__file__).resolve().parents[1]
REAL_BUS = 'simulated = false\ninterface = "virtual"\nchannel = "bench"\ntiming = "realtime"'


def cpu_per_hour(minutes: float, poll_s: float) -> float:
    """CPU seconds per stand hour of one settling record (`LiveRunUp.advance` over it, as the
    procedures call it), polls `poll_s` of stand time apart; the frames are built by the
    simulated compass at each poll (`check`), their CPU time left out."""
    text = (ROOT / "examples" / "paper.toml").read_text()
    plan = parse_plan(text.replace("simulated = true", REAL_BUS).replace('timing = "virtual"', ""))
    engine = switch_on(SimConfig(), 1, 0.0)
    live = SimpleNamespace(recorder=Recorder(10**6, None), own_bus=False)
    built = 0.0

    def bus_at_1x() -> None:  # the next poll's frames arrive
        nonlocal built
        start = time.process_time()
        live.recorder.on_messages(engine.advance_to(engine.stand_time_s + poll_s))
        built += time.process_time() - start

    heard = BusHeadings(plan, live, bus_at_1x)  # type: ignore[arg-type]
    runup = LiveRunUp(heard, 1, 0.0)
    start = time.process_time()
    runup.advance(minutes * 60)
    used = time.process_time() - start - built
    assert runup.record().t_s.size >= minutes * 60 * 10  # (every heading recorded)
    return used / minutes * 60


def main() -> int:
    one, five, fifteen = os.getloadavg()
    print(f"before: load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count()} cores")
    # a poll every heading (10 Hz): each poll at 1x hears one (the polls between, waiting
    # DRAIN_WALL_S for a frame, cost no CPU); and a poll every second
    for poll_s in (0.1, 1.0):
        for minutes in (10.0, 30.0):
            cpu = cpu_per_hour(minutes, poll_s)
            print(
                f"listening {minutes:g} min of stand time, a poll every {poll_s:g} s: "
                f"{cpu:.1f} CPU s per stand hour ({cpu / 36:.2f} % of a core in real time)"
            )
    one, five, fifteen = os.getloadavg()
    print(f"after: load average {one:.2f} {five:.2f} {fifteen:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
