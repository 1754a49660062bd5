"""A CiA 410 inclinometer as gyrostand reads it: NMT start, the resolution 0x6000 (0.001 deg
units) by SDO, and the slope 0x6010 of its TPDO1 on every SYNC (the same SYNC as the roll axis,
so sample k is at the axis's stand time of SYNC k)."""

from __future__ import annotations

import queue
from pathlib import Path

import canopen

from gyrostand.devices.cia402 import ANSWER_TIMEOUT_S, SDO_ERRORS, DriveError


class Cia410Inclinometer:
    def __init__(self, network: canopen.Network, node_id: int, eds: Path):
        self.node = canopen.RemoteNode(node_id, str(eds))
        network.add_node(self.node)
        self._slopes: queue.Queue[int] = queue.Queue()
        self.step_deg = 0.0

    def start(self) -> None:
        self.node.nmt.state = "PRE-OPERATIONAL"
        try:
            self.step_deg = self.node.sdo[0x6000].raw / 1000.0
            self.node.tpdo.read()
        except SDO_ERRORS as exc:
            raise DriveError(f"inclinometer {self.node.id}: {exc}") from None
        self.node.tpdo[1].add_callback(self._on_tpdo)
        self.node.nmt.state = "OPERATIONAL"

    def _on_tpdo(self, pdo: canopen.pdo.PdoMap) -> None:
        self._slopes.put(int(pdo["Slope long16"].raw))

    def take(self) -> float:
        """The slope (deg) of the next SYNC's TPDO, in order."""
        try:
            return self._slopes.get(timeout=ANSWER_TIMEOUT_S) * self.step_deg
        except queue.Empty:
            raise DriveError(
                f"inclinometer {self.node.id} sent no slope within {ANSWER_TIMEOUT_S:g} s of a SYNC"
            ) from None
