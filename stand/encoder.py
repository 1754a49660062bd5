"""A CiA 406 absolute encoder (CANopen encoder profile) as gyrostand reads it: its node id, the
TPDO that maps its position value 0x6004, its resolution 0x6001 and total range 0x6002, its
heartbeat 0x1017, and how it reads the compass (zero, direction). From the plan's keys over the
defaults of the encoder's EDS (canopen's parser). `devices.cia406` decodes its frames,
`devices.sim_cia406` simulates it.

    heading = sign x (counts - zero) x 360 / cpr  mod 360     (cpr: 0x6001; CiA 406 position)
"""

from __future__ import annotations

import configparser
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # imported where used: `plan check` reads an encoder's EDS without it
    import numpy as np

POSITION = (0x6004, 0)  # position value
CPR = 0x6001  # measuring units per revolution
TOTAL_RANGE = 0x6002  # total measuring range in measuring units
HEARTBEAT_TIME = 0x1017  # producer heartbeat time, ms
EMCY_BASE, TPDO1_BASE, HEARTBEAT_BASE = 0x80, 0x180, 0x700
HEARTBEAT_MISSES = 3  # a heartbeat is missing after this many producer periods
OPERATIONAL = 5
SYNC_TYPES = range(0, 241)  # CiA 301 transmission types 0 (acyclic) and 1-240: on SYNC


class EncoderError(ValueError):
    """An encoder description gyrostand cannot use (one line)."""


@dataclass(frozen=True)
class Encoder:
    """What gyrostand needs to know of a CiA 406 encoder and how it reads the compass."""

    node_id: int
    counts_per_revolution: int  # 0x6001
    total_range: int | None = None  # 0x6002 (None: not checked)
    zero_counts: int = 0  # the position at heading 0
    sign: int = 1  # +1: counts increase with the heading (clockwise), -1: they decrease
    cob_id: int | None = None  # of the TPDO with 0x6004 (None: TPDO1, 0x180 + node id)
    offset_bits: int = 0  # where 0x6004 sits in it
    length_bits: int = 32
    on_sync: bool = False  # the TPDO is sent on SYNC (else on its event timer / on change)
    heartbeat_ms: int = 0  # producer heartbeat time 0x1017 (0: not supervised)

    @property
    def tpdo_id(self) -> int:
        return self.cob_id if self.cob_id is not None else TPDO1_BASE + self.node_id

    @property
    def ids(self) -> tuple[int, int, int]:
        """The encoder's COB-IDs: TPDO, EMCY, heartbeat."""
        return self.tpdo_id, EMCY_BASE + self.node_id, HEARTBEAT_BASE + self.node_id

    @property
    def resolution_deg(self) -> float:
        return 360.0 / self.counts_per_revolution

    def heading_deg(self, counts: np.ndarray) -> np.ndarray:
        """Position values -> heading, degrees in [0, 360) (module docstring's equation)."""
        import numpy as np

        steps = self.sign * (counts.astype(np.int64) - self.zero_counts)
        return (steps % self.counts_per_revolution) * self.resolution_deg

    def counts(self, heading_deg: np.ndarray) -> np.ndarray:
        """Heading -> the position value the encoder reads (inverse of `heading_deg`, rounded to
        its resolution; within 0 .. cpr - 1)."""
        import numpy as np

        steps = np.round(np.asarray(heading_deg) / self.resolution_deg).astype(np.int64)
        return (self.sign * steps + self.zero_counts) % self.counts_per_revolution


def encoder_from_eds(path: Path, node_id: int, **plan: int | None) -> Encoder:
    """The encoder an EDS describes at `node_id`: the TPDO mapping 0x6004 (its COB-ID, bit
    offset and length, transmission type), 0x6001, 0x6002 and 0x1017 from the EDS's default
    values; `plan` gives values that override them (counts_per_revolution, total_range,
    heartbeat_ms, zero_counts, sign; None: the EDS's). EncoderError naming the problem."""
    import canopen  # (only to read an EDS: not for every plan check)

    try:
        node = canopen.RemoteNode(node_id, canopen.import_od(str(path), node_id))
        canopen.Network().add_node(node)  # not connected: only to hold the PDO maps
        node.tpdo.read(from_od=True)
    except (OSError, ValueError, KeyError, configparser.Error) as exc:
        raise EncoderError(f"EDS {path}: {exc}") from None
    mapped = [
        (pdo, var)
        for pdo in node.tpdo.map.values()
        for var in pdo.map
        if (var.index, var.subindex) == POSITION
    ]
    if not mapped:
        raise EncoderError(f"EDS {path}: no TPDO maps the position value 0x6004")
    pdo, var = max(mapped, key=lambda m: m[0].enabled)  # (the first valid one, if any)

    def default(index: int) -> int | None:
        entry = node.object_dictionary.get(index)
        value = getattr(entry, "default", None)
        return int(value) if isinstance(value, int) else None

    cpr = plan.pop("counts_per_revolution", None) or default(CPR)
    if cpr is None:
        raise EncoderError(f"EDS {path}: no default for 0x6001 (give counts_per_revolution)")
    given = {k: v for k, v in plan.items() if v is not None}
    encoder = Encoder(
        node_id,
        cpr,
        total_range=default(TOTAL_RANGE),
        cob_id=pdo.cob_id,
        offset_bits=var.offset,
        length_bits=var.length,
        on_sync=pdo.trans_type in SYNC_TYPES,
        heartbeat_ms=default(HEARTBEAT_TIME) or 0,
    )
    return replace(encoder, **given)
