"""A simulated CiA 410 inclinometer on the roll platform (canopen LocalNode, object dictionary
devices/data/sim-inclinometer.eds): on every SYNC, TPDO1 with the slope 0x6010 (INTEGER16, in the
resolution 0x6000, 0.001 deg units: 10 = 0.01 deg) of the platform's roll at that SYNC, plus the
sensor's bias and white noise. It shares the simulated drive's network (and notifier), so it
answers each SYNC after the drive has sampled its position: deterministic in virtual time."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

import canopen
import numpy as np

from gyrostand.devices.sim_drive import SimDrive

SIM_INCLINOMETER_EDS = Path(str(files("gyrostand.devices") / "data" / "sim-inclinometer.eds"))


class SimInclinometer:
    def __init__(
        self,
        drive: SimDrive,
        node_id: int,
        counts_per_degree: float,
        *,
        bias_deg: float = 0.0,
        noise_deg: float = 0.0,
        seed: int = 0,
    ):
        self.node = canopen.LocalNode(node_id, str(SIM_INCLINOMETER_EDS))
        drive.network.add_node(self.node)
        self.node.tpdo.read(from_od=True)
        drive.network.subscribe(0x80, self._on_sync)  # after the drive's: its SYNC sample
        self.drive = drive
        self.counts_per_degree = counts_per_degree
        self.bias_deg = bias_deg
        self.noise_deg = noise_deg
        self._rng = np.random.default_rng(seed)

    def boot(self) -> None:
        self.drive.network.send_message(0x700 + self.node.id, bytes([0]))
        self.node.nmt.on_command(0, bytes([0x80, self.node.id]), 0.0)

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        if self.node.nmt.state != "OPERATIONAL":
            return
        step_deg = self.node.sdo[0x6000].raw / 1000.0
        angle = self.drive.platform_deg(self.counts_per_degree) + self.bias_deg
        angle += self.noise_deg * self._rng.standard_normal()
        self.node.tpdo[1]["Slope long16"].raw = round(angle / step_deg)
        self.node.tpdo[1].transmit()
