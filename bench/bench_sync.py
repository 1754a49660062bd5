"""SYNC jitter and the cycle's latency on the live CiA 402 path (`acquisition.cia402_live`):
gyrostand's master producing SYNC every cycle_ms (python-can's periodic sender: a thread on the
virtual bus, the kernel's broadcast manager on SocketCAN) against the simulated stand
(`gyrostand simulate-drive --plan`: drive, inclinometer, compass).

Printed: the received SYNCs' period error (|period - cycle_ms| percentiles), the cycle's latency
(a SYNC's reception -> the reception of the drive's TPDO1 answering it), and the cycles the
master was too late to send a set-point for; with the load average (figures from a loaded host
are not final).

Run: .venv/bin/python bench/bench_sync.py [SECONDS] [INTERFACE CHANNEL]
  default: 20 s on python-can's virtual bus, the simulated stand in a thread of this process;
  e.g. `bench/bench_sync.py 20 socketcan vcan0`: the simulated stand in a process of its own."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

from gyrostand.acquisition.cia402_live import LiveCia402
from gyrostand.acquisition.cia402_sim_stand import StandThread
from gyrostand.devices.cia402 import Frame
from gyrostand.plan.model import load_plan, parse_plan

PLAN = Path(__file__).resolve().parents[1] / "docs" / "examples" / "cia402-vcan.toml"
SYNC_ID = 0x080


def _stats(ms: np.ndarray) -> str:
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


def measure(seconds: float, interface: str, channel: str | None) -> None:
    text = PLAN.read_text()
    if interface == "virtual":
        channel = f"bench-sync-{uuid.uuid4().hex}"
    text = text.replace('interface = "socketcan"', f'interface = "{interface}"')
    text = text.replace('channel = "vcan0"', f'channel = "{channel}"')
    plan = parse_plan(text)
    sim, proc = None, None
    if interface == "virtual":
        sim = StandThread(plan)
    else:  # the simulated stand in a process of its own, on the plan's bus
        path = Path(tempfile.mkdtemp()) / "plan.toml"
        path.write_text(text)
        load_plan(path)
        script = Path(sys.executable).with_name("gyrostand")
        proc = subprocess.Popen(
            [str(script), "simulate-drive", "--plan", str(path)],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert proc.stdout is not None
        while "Ctrl-C ends" not in proc.stdout.readline():
            assert proc.poll() is None, "simulate-drive ended"
    latencies: list[float] = []
    try:
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
    finally:
        if sim is not None:
            sim.close()
        if proc is not None:
            proc.send_signal(2)
            proc.wait(30)
    cycle_ms = plan.stand.cycle_ms
    error = np.abs(np.diff(sync_rx) * 1000.0 - cycle_ms)
    print(f"live CiA 402 path on {interface}, cycle {cycle_ms} ms, {seconds:g} s of stand time")
    print(f"  SYNC period error |T - {cycle_ms} ms|: {_stats(error)}")
    print(f"  cycle latency SYNC -> TPDO1: {_stats(np.asarray(latencies))}")
    print(f"  cycles without a set-point of their own (master late): {late}")
    print(f"  load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    interface, channel = (sys.argv[2], sys.argv[3]) if len(sys.argv) > 3 else ("virtual", None)
    started = time.monotonic()
    measure(seconds, interface, channel)
    print(f"  wall time {time.monotonic() - started:.1f} s")
