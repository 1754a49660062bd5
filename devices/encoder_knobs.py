"""The simulated CiA 406 encoder's knobs (`devices.sim_cia406.simulated_encoder`), apart so that
`gyrostand simulate` lists them without importing the simulator."""

from __future__ import annotations

from typing import Any

# The simulated encoder's knobs (`gyrostand simulate --protocol cia406`, the pytest plugin's
# cia406={...}): name -> (type, default, help)
KNOBS: dict[str, tuple[Any, Any, str]] = {
    "node_id": (int, 5, "cia406: the encoder's CANopen node id (1-127)"),
    "counts_per_revolution": (int, 65536, "cia406: measuring units per revolution (0x6001)"),
    "zero_counts": (int, 0, "cia406: the position value it reads at heading 0"),
    "direction": (str, "clockwise", "cia406: clockwise or counterclockwise (counts vs heading)"),
    "heartbeat_ms": (int, 1000, "cia406: its heartbeat producer time 0x1017, ms (0: none)"),
    "sync_id": (
        int | None,
        None,
        "cia406: TPDO on SYNC, which the encoder produces at this COB-ID (default: on its event "
        "timer, one TPDO per heading sample)",
    ),
    "encoder_silence_at_s": (float | None, None, "cia406 fault: silent from this stand time"),
    "encoder_silence_for_s": (float, 10.0, "cia406 fault: silent for this long, s"),
    "emcy_at_s": (float | None, None, "cia406 fault: an EMCY (generic error) at this stand time"),
}
