"""The report's rendered figures kept in a per-user cache folder, keyed by what they are drawn
from: a report made again from the same stored analysis (a DRAFT re-issued once signed, the
other formats, the station's button pressed again) takes its figures from here and neither
imports matplotlib nor draws (about 1.8 s of CPU of the paper campaign's report).

The key is the SHA-256 of the figure builder's name, its arguments (`canonical`: the same
numbers give the same key whether the analysis was computed or rebuilt from its record), the
report's plot style, matplotlib's version and the analysis and report code
(`code_digest`): any change to one of them draws the figure anew. An entry is written whole
(a temporary file renamed) and an unreadable one is drawn again; the folder keeps the
`KEEP` newest entries. ``GYROSTAND_FIGURE_CACHE``: another folder, or "off" for none.

    cached(name, args, kwargs, style, draw) -> str
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from collections.abc import Callable
from dataclasses import fields, is_dataclass
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np

from gyrostand.report.code_digest import analysis_code_sha256

ENV = "GYROSTAND_FIGURE_CACHE"
KEEP = 400  # entries (about 100 kB each: the figures of some 30 reports)


def folder() -> Path | None:
    """The cache folder (None: caching off): ``$GYROSTAND_FIGURE_CACHE``, else the user's cache
    folder (``$XDG_CACHE_HOME`` or ``~/.cache``) / gyrostand / figures."""
    chosen = os.environ.get(ENV, "")
    if chosen.lower() == "off":
        return None
    if chosen:
        return Path(chosen)
    try:
        base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    except RuntimeError:  # no home folder: no cache
        return None
    return Path(base) / "gyrostand" / "figures"


@functools.cache
def _code_digest() -> bytes:
    """The plotting code's identity: matplotlib's version and the analysis and report code."""
    return hashlib.sha256((version("matplotlib") + analysis_code_sha256()).encode()).digest()


def canonical(value: Any) -> Any:
    """`value` as plain tuples, strings and floats: a dataclass by its name and fields, a dict
    by its sorted items, any real number (Python or numpy) as a float, an array by its shape
    and float64 bytes. Not `json_safe`: that one maps NaN and infinities alike to null and
    passes unknown objects through. TypeError for anything else."""
    if is_dataclass(value) and not isinstance(value, type):
        return (type(value).__qualname__,) + tuple(
            (f.name, canonical(getattr(value, f.name))) for f in fields(value)
        )
    if isinstance(value, dict):
        return ("dict",) + tuple(sorted((repr(k), canonical(v)) for k, v in value.items()))
    if isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
        return ("array", value.shape, value.astype(np.float64).tobytes())
    if isinstance(value, list | tuple | np.ndarray):
        return tuple(canonical(v) for v in value)
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | float | np.integer | np.floating):
        return float(value)
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"no cache key for a {type(value).__name__}")


def key(name: str, args: tuple[Any, ...], kwargs: dict[str, Any], style: dict[str, Any]) -> str:
    """The cache key of one figure (TypeError for an argument `canonical` cannot take)."""
    # repr, not pickle: pickle's output depends on which equal objects are one object
    document = repr(canonical((name, args, kwargs, style))).encode()
    return hashlib.sha256(_code_digest() + document).hexdigest()


def cached(
    name: str,
    args: tuple[Any, ...],
    kwargs: dict[str, Any],
    style: dict[str, Any],
    draw: Callable[[], str],
) -> str:
    """The figure `name(*args, **kwargs)` from the cache, else `draw()`n and stored."""
    where = folder()
    if where is None:
        return draw()
    try:
        path = where / f"{key(name, args, kwargs, style)}.html"
    except TypeError:  # not keyable: drawn every time
        return draw()
    try:
        figure = path.read_text(encoding="utf-8")
        if figure.startswith("<img ") and figure.endswith(">"):  # else damaged: drawn again
            os.utime(path)  # recently used: kept by `_prune`
            return figure
    except (OSError, UnicodeDecodeError):
        pass
    figure = draw()
    try:
        where.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(
            "w", encoding="utf-8", dir=where, suffix=".tmp", delete=False
        ) as file:
            file.write(figure)
        os.replace(file.name, path)
        _prune(where)
    except OSError:  # a read-only or full disk: the report is made all the same
        pass
    return figure


def _prune(where: Path) -> None:
    """Keep the `KEEP` newest entries."""
    entries = sorted(where.glob("*.html"), key=lambda p: p.stat().st_mtime, reverse=True)
    for old in entries[KEEP:]:
        old.unlink(missing_ok=True)
