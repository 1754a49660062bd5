"""The identity of the code that computes an analysis and draws its figures: what a recorded
analysis (`report.stored`) and a cached figure (`report.figure_cache`) are reused by, and only
by (the version string stays the same between a checkout's commits)."""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path


@functools.cache
def analysis_code_sha256() -> str:
    """SHA-256 of the sources of the analysis and report packages."""
    digest = hashlib.sha256()
    for package in ("analysis", "report"):
        folder = Path(__file__).parent.parent / package  # (this module is gyrostand.report's)
        for path in sorted(folder.glob("*.py")):
            digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()
