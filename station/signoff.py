"""Signing a campaign off at the station (stored in the database, never typed into the PDF):
who tested it and who checked it."""

from __future__ import annotations

from sqlalchemy.orm import Session

from gyrostand.db.models import SIGN_OFF_ROLES, Campaign, SignOff
from gyrostand.db.queries import sign_offs

ROLE_NAMES = {"tested_by": "tested by", "checked_by": "checked by"}


class SignOffRefused(ValueError):
    """A sign-off that cannot be stored (one line why)."""


def sign_off(session: Session, campaign_id: int, role: str, name: str) -> SignOff:
    """Store `name` as who `role` the completed campaign: once per role, tested before
    checked, by someone else."""
    name = " ".join(name.split())
    if role not in SIGN_OFF_ROLES:
        raise SignOffRefused(f"role must be one of {', '.join(SIGN_OFF_ROLES)}, not {role!r}")
    if not name:
        raise SignOffRefused(f"{ROLE_NAMES[role]}: the name is empty")
    if len(name) > 200:
        raise SignOffRefused(f"{ROLE_NAMES[role]}: the name is longer than 200 characters")
    campaign = session.get(Campaign, campaign_id)
    if campaign is None or campaign.status != "completed":
        raise SignOffRefused(f"campaign {campaign_id} is not completed: nothing to sign off")
    signed = sign_offs(session, campaign_id)
    if role in signed:
        raise SignOffRefused(f"{ROLE_NAMES[role]} is already signed by {signed[role].name}")
    if role == "checked_by":
        if "tested_by" not in signed:
            raise SignOffRefused("checked by: sign 'tested by' first")
        if signed["tested_by"].name.casefold() == name.casefold():
            raise SignOffRefused("checked by: the checker must not be the tester")
    signature = SignOff(campaign_id=campaign_id, role=role, name=name)
    session.add(signature)
    return signature
