"""The CiA 402 master with a periodic SYNC producer (as on a real bus) against a simulated drive
that lags: on python-can's virtual bus, SYNC from a bus handle of its own (python-can's
thread-timed sender), the drive answering every other SYNC late, together with the next one.
Each set-point the master sends must reach the drive before the SYNC it applies to and alone:
an RPDO followed by another before a SYNC is overwritten (a lost fault reset's edge, a lost step
of the power state machine)."""

from __future__ import annotations

import threading

import canopen

from gyrostand.devices.cia402 import AxisConfig, Cia402Axis, power_state
from gyrostand.devices.sim_drive import SIM_DRIVE_EDS, SimDrive

NODE = 3
CYCLE_MS = 50
LAG_S = 0.015  # the late answer's own answer follows it this much later (same SYNC period)


def _lag_every_other_answer(drive: SimDrive, net: canopen.Network) -> list[threading.Timer]:
    """The drive's TPDO1 of every odd SYNC held and sent at the next SYNC, that SYNC's own
    LAG_S later (a drive, or its process, stalled for a moment)."""
    tpdo = drive.node.tpdo[1]
    held: list[bytes] = []
    timers: list[threading.Timer] = []

    def transmit() -> None:  # (in the drive's SYNC handler, after it applied the RPDO)
        data = bytes(tpdo.data)
        if drive.syncs % 2 == 1:
            held.append(data)
            return
        for old in held:
            net.send_message(tpdo.cob_id, old)
        held.clear()
        timers.append(threading.Timer(LAG_S, net.send_message, (tpdo.cob_id, data)))
        timers[-1].start()

    tpdo.transmit = transmit  # type: ignore[method-assign]
    return timers


def test_a_lagging_drives_old_answer_does_not_advance_the_set_points():
    channel = "cia402-periodic-lag"
    nets = [canopen.Network() for _ in range(3)]  # the drive's, the master's, the SYNC's
    for net in nets:
        net.NOTIFIER_CYCLE = 0.05
        net.connect(interface="virtual", channel=channel)
    drive_net, master_net, sync_net = nets
    timers: list[threading.Timer] = []
    try:
        drive = SimDrive(drive_net, NODE)
        timers = _lag_every_other_answer(drive, drive_net)
        # what reaches the drive, in order: each RPDO1's target, and SYNC (None)
        seen: list[int | None] = []
        rpdo = drive.node.rpdo[1]
        drive_net.subscribe(rpdo.cob_id, lambda *a: seen.append(int(rpdo["Target position"].raw)))
        drive_net.subscribe(0x80, lambda *a: seen.append(None))
        master_net.sync = canopen.sync.SyncProducer(sync_net)
        axis = Cia402Axis(master_net, AxisConfig(NODE, SIM_DRIVE_EDS, CYCLE_MS, sync="periodic"))
        drive.boot()
        axis.start()
        assert power_state(axis.statusword) == "OPERATION ENABLED"
        targets = [10 * k for k in range(1, 31)]  # distinct set-points, a slow ramp
        for target in targets:
            axis.step(0x0F, target)
        axis.close()
    finally:
        for timer in timers:
            timer.cancel()
        for net in nets:
            net.disconnect()
    # RPDOs between two SYNCs: only the last is applied, the others are lost
    lost, since = [], []
    for item in seen:
        if item is None:
            lost += since[:-1]
            since = []
        else:
            since.append(item)
    assert lost == []
    assert [t for t in seen if t in targets] == targets  # each once, in order
    assert axis.late_cycles >= len(targets) // 2  # (the drive did lag: cycles without a set-point)
