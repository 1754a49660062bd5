"""Heading arithmetic on the circle: the one definition of the +-180 deg wrap."""

from typing import TypeVar

import numpy as np

Angle = TypeVar("Angle", float, np.ndarray)


def wrap180(angle_deg: Angle) -> Angle:
    """An angle (or array) in degrees brought to [-180, 180): the signed difference of headings."""
    return (angle_deg + 180.0) % 360.0 - 180.0


def about(reference_deg: float, headings_deg: Angle) -> Angle:
    """Headings on the branch of `reference_deg` (within 180 deg of it), so that means and
    differences of readings near north (359.9 deg, 0.1 deg) are those of the readings."""
    return reference_deg + wrap180(headings_deg - reference_deg)
