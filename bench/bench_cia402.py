"""CiA 402 stand benchmarks on python-can's virtual bus (in-process; SocketCAN numbers need the
VM suite): the lockstep cycle's latency (RPDO + SYNC -> the drive's TPDO, wall time per cycle),
and with the periodic SYNC producer (python-can's thread-timed sender here; kernel timed on
SocketCAN) the SYNC period's jitter as the drive receives it.

Run: .venv/bin/python bench/bench_cia402.py [INTERFACE CHANNEL]   (default: virtual)
e.g. bench/bench_cia402.py socketcan vcan0 (the drive and the master in this process, each with
its own socket)."""

import sys
import time

import canopen
import numpy as np

from gyrostand.devices.cia402 import AxisConfig, Cia402Axis
from gyrostand.devices.roll_trajectory import RollTrajectory
from gyrostand.devices.sim_drive import SIM_DRIVE_EDS, SimDrive

CPD = 10_000.0


INTERFACE, CHANNEL = (sys.argv[1], sys.argv[2]) if len(sys.argv) > 2 else ("virtual", None)


def _stand(channel: str, sync: str) -> tuple[Cia402Axis, SimDrive, list[canopen.Network]]:
    nets = [canopen.Network(), canopen.Network()]
    for net in nets:
        net.NOTIFIER_CYCLE = 0.05
        net.connect(interface=INTERFACE, channel=CHANNEL or channel)
    drive = SimDrive(nets[0], 2)
    axis = Cia402Axis(nets[1], AxisConfig(2, SIM_DRIVE_EDS, cycle_ms=10, sync=sync))
    drive.boot()
    return axis, drive, nets


def _stats(ms: np.ndarray) -> str:
    p50, p99 = np.percentile(ms, [50, 99])
    return f"median {p50:.3f} ms, p99 {p99:.3f} ms, max {ms.max():.3f} ms (n={len(ms)})"


def lockstep(cycles: int = 2000) -> None:
    axis, _, nets = _stand("bench-lockstep", "lockstep")
    try:
        axis.start()
        roll = RollTrajectory(3.0, 2.0, 1.0)
        wall = np.empty(cycles)
        for k in range(cycles):
            start = time.perf_counter()
            axis.step(0x0F, round(CPD * float(roll.position_deg(k * 0.01))))
            wall[k] = (time.perf_counter() - start) * 1e3
        print(f"lockstep cycle latency (RPDO, SYNC -> TPDO): {_stats(wall)}")
        print(f"  stand time per wall second: {cycles * 0.01 / (wall.sum() / 1e3):.1f}x")
    finally:
        for net in nets:
            net.disconnect()


def periodic(cycles: int = 300) -> None:
    axis, _, nets = _stand("bench-periodic", "periodic")
    arrivals: list[float] = []
    nets[0].subscribe(0x80, lambda can_id, data, ts: arrivals.append(ts))
    try:
        axis.start()
        roll = RollTrajectory(3.0, 2.0, 1.0)
        for k in range(cycles):
            axis.step(0x0F, round(CPD * float(roll.position_deg(k * 0.01))))
        period = np.diff(arrivals) * 1e3
        print(f"periodic SYNC at 10 ms, period seen by the drive: {_stats(period)}")
        print(f"  jitter (period - 10 ms): sd {period.std():.3f} ms")
    finally:
        axis.close()
        for net in nets:
            net.disconnect()


if __name__ == "__main__":
    lockstep()
    periodic()
