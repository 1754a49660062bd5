"""gyrostand: rolling-stand tests of marine gyrocompasses (composition root and CLI)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("gyrostand")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"
SOFTWARE_VERSION = f"gyrostand {__version__}"  # stored with each campaign and analysis run
