"""Raw logs of a serial heading source: one line per received piece in IEC 61162-450 TAG-block
form, `\\c:<time>*hh\\<sentence>`, and the reader that gives the pieces back exactly.

`c:` is the reception time of the piece's first byte as UNIX time in MILLISECONDS (the TAG-block
`c:` parameter is UNIX time; whole seconds cannot time a 10-50 Hz heading, and readers such as
gpsd take `c:` "in seconds or milliseconds"). The serial source rounds reception times to the
millisecond before using them (`reception_ms`), so a replay from this log is exactly the live run.

Bytes that are no sentence are logged too, so a replay counts them as live did: a `t:` (text)
parameter names them (garbage, truncated, overlong). Bytes outside printable ASCII, and the
backslash, are written as `\\xHH` in the payload; a well-formed sentence is written as received."""

from __future__ import annotations

import io
import re
from collections.abc import Iterator
from pathlib import Path

from gyrostand.devices.framing import BAD_TAG, GARBAGE, OVERLONG, TRUNCATED, Received
from gyrostand.devices.nmea0183 import checksum
from gyrostand.frames.logfile import LogFileError

SUFFIX = ".nmea"
_JUNK_KINDS = (GARBAGE, TRUNCATED, OVERLONG, BAD_TAG)
_UNSAFE = re.compile(rb"[^\x20-\x5b\x5d-\x7e]")  # outside printable ASCII, or a backslash
_ESCAPED = re.compile(rb"\\x([0-9A-F]{2})")
_LINE = re.compile(rb"\\([^\\*]*)\*([0-9A-F]{2})\\(.*)")


def reception_ms(time_s: float) -> int:
    """A reception time as the whole milliseconds the log keeps."""
    return round(time_s * 1000.0)


def _escape(data: bytes) -> bytes:
    return _UNSAFE.sub(lambda m: b"\\x%02X" % m.group()[0], data)


def _unescape(data: bytes) -> bytes:
    return _ESCAPED.sub(lambda m: bytes([int(m.group(1), 16)]), data)


def tag_line(piece: Received) -> bytes:
    """One piece as a TAG-block line (with <CR><LF>)."""
    params = f"c:{reception_ms(piece.time_s)}"
    if piece.junk is not None:
        params += f",t:{piece.junk}"
    block = params.encode("ascii")
    return b"\\%s*%02X\\%s\r\n" % (block, checksum(block), _escape(piece.data))


class TagBlockWriter:
    """Appends pieces to a TAG-block log; every `write` reaches the operating system. `skip`:
    the first pieces given are not written (earlier logs of the same line hold them)."""

    def __init__(self, path: Path, skip: int = 0) -> None:
        self.path = path
        self._file: io.BufferedWriter = path.open("ab")
        self.lines = 0
        self._skip = skip

    def write(self, pieces: list[Received]) -> None:
        if self._skip:
            skipped, self._skip = min(self._skip, len(pieces)), max(self._skip - len(pieces), 0)
            pieces = pieces[skipped:]
        if not pieces:
            return
        self._file.write(b"".join(tag_line(p) for p in pieces))
        self._file.flush()
        self.lines += len(pieces)

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> TagBlockWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_tag_log(path: Path) -> Iterator[Received]:
    """The pieces of a TAG-block log in order, times in seconds (whole milliseconds). A line
    that is not one of ours (no TAG block, a wrong TAG checksum, no `c:`) is a `LogFileError`
    naming the file and the line; a last line with no line end (the writer killed) is left out."""
    with path.open("rb") as f:
        lines = f.read().split(b"\n")
    lines.pop()  # after the last line end: nothing, or a line the writer did not finish
    for number, raw in enumerate(lines, 1):
        line = raw[:-1] if raw.endswith(b"\r") else raw
        m = _LINE.fullmatch(line)
        if m is None or int(m.group(2), 16) != checksum(m.group(1)):
            what = "no TAG block" if m is None else "TAG block checksum mismatch"
            raise LogFileError(f"{path}: line {number}: {what}")
        params = dict(p.split(b":", 1) for p in m.group(1).split(b",") if b":" in p)
        junk = params.get(b"t", b"").decode("ascii") or None
        stamp = params.get(b"c", b"")
        if not stamp.isdigit() or (junk is not None and junk not in _JUNK_KINDS):
            raise LogFileError(f"{path}: line {number}: no c: time or an unknown t: {junk!r}")
        yield Received(int(stamp) / 1000.0, _unescape(m.group(3)), junk)
