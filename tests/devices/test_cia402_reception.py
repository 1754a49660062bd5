"""The live CiA 402 path's reception timing (`acquisition.cia402_live.Received`): the SYNCs are
the stand clock's ticks (SYNC k at k x cycle_ms), the other devices' frames are put on it by
their reception times; the drive's own traffic is not theirs."""

from __future__ import annotations

import can
import numpy as np
import pytest

from gyrostand.acquisition.cia402_live import Received

CYCLE_MS = 10
T0 = 1_700_000_000.0  # the host clock at the first SYNC (epoch seconds, as SocketCAN stamps)


def _sync(rx: float) -> can.Message:
    return can.Message(timestamp=rx, arbitration_id=0x080, is_extended_id=False, data=b"")


def _heading(rx: float) -> can.Message:
    return can.Message(timestamp=rx, arbitration_id=0x09F11223, data=bytes(8))


def test_frames_are_put_on_the_sync_clock_by_reception():
    rng = np.random.default_rng(7)
    latency_s = rng.uniform(0.0002, 0.0009, 300)  # each SYNC received a little late
    received = Received(node_id=2, master_id=127, cycle_ms=CYCLE_MS)
    received.on_message_received(_heading(T0 - 0.5))  # before the first SYNC: no stand time
    expected = []
    for k in range(300):
        received.on_message_received(_sync(T0 + k * CYCLE_MS / 1000 + latency_s[k]))
        if k % 10 == 5:  # a compass frame half-way between two SYNCs
            at = T0 + (k + 0.5) * CYCLE_MS / 1000
            received.on_message_received(_heading(at))
            # independent: reception minus the first SYNC's time, less the least latency so far
            expected.append(round((at - T0 - latency_s[: k + 1].min()) * 1000) / 1000)
        received.on_message_received(
            can.Message(timestamp=T0, arbitration_id=0x182, is_extended_id=False, data=bytes(6))
        )  # the drive's TPDO1: the master's, not another device's
    frames = received.take(10.0, wait_s=0.0)
    assert [m.timestamp for m in frames] == pytest.approx(expected, abs=1e-3)
    assert all(m.is_extended_id for m in frames) and received.syncs == 300


def test_take_cuts_at_the_stand_time():
    received = Received(node_id=2, master_id=127, cycle_ms=CYCLE_MS)
    for k in range(100):
        received.on_message_received(_sync(T0 + k / 100))
        received.on_message_received(_heading(T0 + k / 100 + 0.001))
    first = received.take(0.5, wait_s=0.0)
    rest = received.take(1.0, wait_s=0.0)
    assert len(first) == 50 and first[-1].timestamp <= 0.5
    assert len(rest) == 50 and rest[0].timestamp > 0.5
