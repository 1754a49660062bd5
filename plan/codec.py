"""The plan's CAN codec: its DBC (the shipped one unless the plan names a lab DBC), signal map."""

from __future__ import annotations

from gyrostand.plan.model import Plan, PlanError
from gyrostand.stand.protocol import Codec, ProtocolError


def codec_for(plan: Plan) -> Codec:
    """The plan's DBC and signal map as a codec (PlanError naming the problem)."""
    try:
        return Codec.of(plan.dbc_path, plan.signals)
    except ProtocolError as exc:
        raise PlanError([str(exc)]) from None
