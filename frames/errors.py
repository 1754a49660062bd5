"""The raw log's error, in a module of its own: the commands that catch it (`gyrostand report`)
import neither python-can nor the log readers for it."""


class LogFileError(ValueError):
    """A raw log that cannot be read: not a log of its format, or corrupt. The message names the
    file and where it goes wrong."""
