"""The plan's CAN codec: its DBC (the shipped one unless the plan names a lab DBC), signal map."""

from __future__ import annotations

from pathlib import Path

from gyrostand.plan.model import Plan, PlanError
from gyrostand.stand.protocol import DBC_PATH, Codec, ProtocolError, SignalMap


def codec_for(plan: Plan) -> Codec:
    """The plan's DBC and signal map as a codec (PlanError naming the problem)."""
    try:
        dbc = Path(plan.dbc_path) if plan.dbc_path else DBC_PATH
        return Codec(dbc, SignalMap.from_mapping(plan.signals))
    except ProtocolError as exc:
        raise PlanError([str(exc)]) from None
