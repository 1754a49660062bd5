"""A CiA 402 stand on a real SocketCAN channel: `gyrostand simulate-drive` in its own process.
gyrostand's CiA 402 master in this one rocks the axis, then falls silent as a killed gyrostand
would: the drive's heartbeat consumer must bring the axis to rest (EMCY 0x8130, QUICK STOP
ACTIVE, the position no longer changing), seen from the bus only. And a whole campaign
(`campaign run` in a process of its own, the plan's simulated stand with its inclinometer and
compass in another): the roll measured by the drive's position and the inclinometer."""

from __future__ import annotations

import time

import canopen
import pytest

from gyrostand.devices.cia402 import AxisConfig, Cia402Axis, power_state
from gyrostand.devices.roll_trajectory import RollTrajectory
from gyrostand.devices.sim_drive import EMCY_HEARTBEAT, SIM_DRIVE_EDS
from tests.socketcan.processes import (
    Process,
    cia402_campaign,
    gyrostand_command,
    wait_for_output,
)

pytestmark = pytest.mark.socketcan

TIMEOUT_S = 900.0  # wall seconds for a process start under emulation
NODE = 2


def test_a_silent_master_leaves_the_drive_at_rest(tmp_path, channel):
    args = ["simulate-drive", "--interface", "socketcan", "--channel", channel]
    drive = Process.start([*gyrostand_command(), *args, "--node-id", str(NODE)], tmp_path, "drive")
    network = canopen.Network()
    try:
        wait_for_output(drive, "Ctrl-C ends", TIMEOUT_S)
        network.connect(interface="socketcan", channel=channel)
        axis = Cia402Axis(network, AxisConfig(NODE, SIM_DRIVE_EDS, cycle_ms=10))
        emcy: list[int] = []
        axis.node.emcy.add_callback(lambda e: emcy.append(e.code))
        axis.start()
        roll = RollTrajectory(3.0, 2.0, 1.0)
        for k in range(200):  # 2 s of stand time: rocking at full amplitude from 1 s
            axis.step(0x0F, round(10_000 * float(roll.position_deg(k * 0.01))))
        # gyrostand "dies": no more SYNC, RPDO or heartbeat from here
        deadline = time.monotonic() + 120.0
        while EMCY_HEARTBEAT not in emcy:
            assert time.monotonic() < deadline, f"no EMCY 0x8130 from the drive\n{drive.output()}"
            time.sleep(0.1)
        while power_state(int(axis.node.sdo[0x6041].raw)) != "QUICK STOP ACTIVE":
            assert time.monotonic() < deadline, "the drive is not in QUICK STOP ACTIVE"
            time.sleep(0.1)
        positions = []
        for _ in range(2):
            time.sleep(1.0)
            positions.append(int(axis.node.sdo[0x6064].raw))
        assert positions[0] == positions[1], "the axis still moves"
    finally:
        network.disconnect()
        drive.interrupt()


def test_a_cia402_campaign_on_vcan0_measures_the_roll(tmp_path, channel):
    cia402_campaign(tmp_path, "socketcan", channel)
