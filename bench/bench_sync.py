"""SYNC jitter and the cycle's latency on the live CiA 402 path (`acquisition.cia402_live`):
gyrostand's master producing SYNC every cycle_ms (python-can's periodic sender: a thread on the
virtual bus, the kernel's broadcast manager on SocketCAN) against the simulated stand
(`gyrostand simulate-drive --plan`: drive, inclinometer, compass).

Printed: the received SYNCs' period error (|period - cycle_ms| percentiles), the cycle's latency
(a SYNC's reception -> the reception of the drive's TPDO1 answering it), and the cycles the
master was too late to send a set-point for; with the load average (figures from a loaded host
are not final).

Run: .venv/bin/python bench/bench_sync.py [--seconds S] [--cycle-ms MS] [--interface I --channel C]
  default: 20 s at the plan's cycle (10 ms) on python-can's virtual bus, the simulated stand in a
  thread of this process; with --interface (e.g. `--interface socketcan --channel vcan0`) the
  simulated stand in a process of its own (`gyrostand simulate-drive --plan`), started before
  this process's imports; the emulated VM (tools/vcan-vm): `--seconds 20 --cycle-ms 50`."""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # (imported where used: the stand's process starts before these imports)
    import numpy as np

    from gyrostand.devices.cia402 import Frame

PLAN = Path(__file__).resolve().parents[1] / "docs" / "examples" / "cia402-vcan.toml"
SYNC_ID = 0x080
READY = "Ctrl-C ends"  # `gyrostand simulate-drive` says so on stderr once it serves the bus
START_S = 900.0  # wall seconds for the stand's start (its imports under software emulation)


def plan_text(cycle_ms: int | None, interface: str, channel: str | None) -> str:
    """The example plan on `interface` `channel`, at `cycle_ms` (None: the plan's)."""
    text = PLAN.read_text()
    text = text.replace('interface = "socketcan"', f'interface = "{interface}"')
    text = text.replace('channel = "vcan0"', f'channel = "{channel}"')
    if cycle_ms is not None:
        text = re.sub(r"(?m)^cycle_ms = \d+", f"cycle_ms = {cycle_ms}", text)
    return text


def start_stand(text: str) -> tuple[subprocess.Popen, Path]:
    """`gyrostand simulate-drive --plan` in a process of its own; its stderr's file."""
    folder = Path(tempfile.mkdtemp(prefix="bench-sync-"))
    (folder / "plan.toml").write_text(text)
    script = Path(sys.executable).with_name("gyrostand")
    err = folder / "stand.err"
    with err.open("wb") as e:
        proc = subprocess.Popen(
            [str(script), "simulate-drive", "--plan", str(folder / "plan.toml")],
            stdout=subprocess.DEVNULL,
            stderr=e,
        )
    return proc, err


def wait_ready(proc: subprocess.Popen, err: Path) -> None:
    deadline = time.monotonic() + START_S
    while READY not in err.read_text():
        if proc.poll() is not None:
            sys.exit(f"bench_sync: simulate-drive ended: {err.read_text().strip()}")
        if time.monotonic() > deadline:
            sys.exit(f"bench_sync: simulate-drive not ready within {START_S:g} s")
        time.sleep(0.2)


def _stats(ms: np.ndarray) -> str:
    import numpy as np

    if not len(ms):
        return "none"
    p50, p99 = np.percentile(ms, [50, 99])
    return f"median {p50:.3f} ms, p99 {p99:.3f} ms, max {ms.max():.3f} ms (n={len(ms)})"


def _latencies(frames: list[Frame], tpdo_id: int, out: list[float]) -> None:
    """SYNC reception -> the next TPDO1's, for each TPDO1 taken."""
    sync_rx = None
    for f in frames:
        if f.can_id == SYNC_ID:
            sync_rx = f.rx_s
        elif f.can_id == tpdo_id and sync_rx is not None:
            out.append((f.rx_s - sync_rx) * 1000.0)
            sync_rx = None


def measure(seconds: float, text: str) -> None:
    """The master of the plan `text` cycling for `seconds` of stand time; its figures printed."""
    import numpy as np

    from gyrostand.acquisition.cia402_live import LiveCia402
    from gyrostand.plan.model import parse_plan

    plan = parse_plan(text)
    latencies: list[float] = []
    live = LiveCia402(plan)
    try:
        tap = live.axis.on_frames
        tpdo_id = live.axis.node.tpdo[1].cob_id

        def on_frames(frames: list[Frame]) -> None:
            tap(frames)
            _latencies(frames, tpdo_id, latencies)

        live.axis.on_frames = on_frames
        start_s = live.stand.t_s
        t = start_s
        while t < start_s + seconds:
            t += 1.0
            live.advance_to(t)
            live.take_logged()
        late = live.axis.late_cycles
        sync_rx = np.asarray(live.received.sync_rx_s)
    finally:
        live.close()
    cycle_ms = plan.stand.cycle_ms
    error = np.abs(np.diff(sync_rx) * 1000.0 - cycle_ms)
    bus = f"{plan.bus.interface} {plan.bus.channel if plan.bus.interface != 'virtual' else ''}"
    print(f"live CiA 402 path on {bus.strip()}, cycle {cycle_ms} ms, {seconds:g} s of stand time")
    print(f"  SYNC period error |T - {cycle_ms} ms|: {_stats(error)}")
    print(f"  cycle latency SYNC -> TPDO1: {_stats(np.asarray(latencies))}")
    print(f"  cycles without a set-point of their own (master late): {late}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="stand seconds measured")
    parser.add_argument("--cycle-ms", type=int, help="the SYNC cycle (default: the plan's)")
    parser.add_argument("--interface", default="virtual", help="python-can interface")
    parser.add_argument("--channel", help="its channel (with --interface)")
    args = parser.parse_args()
    if args.interface != "virtual" and not args.channel:
        parser.error("--interface needs --channel")
    channel = args.channel if args.interface != "virtual" else f"bench-sync-{uuid.uuid4().hex}"
    text = plan_text(args.cycle_ms, args.interface, channel)
    started = time.monotonic()
    # the stand's process first: its start overlaps this process's imports
    proc, err = start_stand(text) if args.interface != "virtual" else (None, None)
    sim = None
    try:
        if proc is not None and err is not None:
            wait_ready(proc, err)
        else:  # on the virtual bus: the simulated stand in a thread of this process
            from gyrostand.acquisition.cia402_sim_stand import StandThread
            from gyrostand.plan.model import parse_plan

            sim = StandThread(parse_plan(text))
        ready_s = time.monotonic() - started
        measure(args.seconds, text)
    finally:
        if sim is not None:
            sim.close()
        if proc is not None:
            proc.send_signal(signal.SIGINT)
            proc.wait(60)
    print(f"  load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"  wall time {time.monotonic() - started:.1f} s (the stand ready after {ready_s:.1f} s)")


if __name__ == "__main__":
    main()
