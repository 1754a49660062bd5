"""gyrostand: rolling-stand tests of marine gyrocompasses (composition root and CLI).

`__version__` and `SOFTWARE_VERSION` (stored with each campaign and analysis run) are read from
the installed package's metadata when first used: a command that needs neither does not load
importlib.metadata."""

from __future__ import annotations

from functools import cache


@cache
def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("gyrostand")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "0+unknown"


def __getattr__(name: str) -> str:
    if name == "__version__":
        return _version()
    if name == "SOFTWARE_VERSION":
        return f"gyrostand {_version()}"
    raise AttributeError(f"module 'gyrostand' has no attribute {name!r}")
