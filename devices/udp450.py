"""The serial heading source on another transport: IEC 61162-450 datagrams (UDP, multicast on a
bridge's LAN). A datagram is the header "UdPbC" NUL, then sentences each behind a TAG block
(`\\s:HE0001,n:12*hh\\$HEHDT,...*hh` <CR><LF>). Each sentence becomes a `framing.Received`
timed by the datagram's reception (a LAN has no baud rate to correct for), for
`Iec61162Source.decode_pieces`: the same decoding, events and raw log as on a serial line.

The group and port are the installation's (IEC 61162-450 assigns them per transmission group):
give them as the bridge is configured."""

from __future__ import annotations

import re
import socket
import struct
import time
from collections.abc import Callable

from gyrostand.devices.framing import BAD_TAG, GARBAGE, Received
from gyrostand.devices.nmea0183 import checksum
from gyrostand.devices.serial_port import ReaderThread

HEADER = b"UdPbC\x00"  # IEC 61162-450 §7.2: sentence datagrams
_TAG = re.compile(rb"\\([^\\*]*)\*([0-9A-Fa-f]{2})\\")
MAX_DATAGRAM = 65_535


class Udp450Error(RuntimeError):
    """A socket that cannot be opened; the message names the group and port."""


def parse_datagram(data: bytes, time_s: float) -> list[Received]:
    """The sentences of one datagram, TAG blocks removed; what is not a 61162-450 sentence
    datagram, or a TAG block with a wrong checksum, is junk with its reason."""
    if not data.startswith(HEADER):
        return [Received(time_s, data[:80], GARBAGE)]
    out = []
    for line in data[len(HEADER) :].split(b"\n"):
        line = line.rstrip(b"\r")
        if not line:
            continue
        tag = _TAG.match(line)
        if tag is not None:
            if int(tag.group(2), 16) != checksum(tag.group(1)):
                out.append(Received(time_s, line, BAD_TAG))
                continue
            line = line[tag.end() :]
        out.append(Received(time_s, line))
    return out


class Udp450Reader(ReaderThread[Received]):
    """Receives 61162-450 datagrams on `port` (joining multicast `group` when given) in a
    thread; `take()` gives their sentences as pieces."""

    def __init__(
        self,
        port: int,
        group: str | None = None,
        interface: str = "0.0.0.0",
        *,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.where = f"UDP {group or interface}:{port}"
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((group or interface, port))
            if group is not None:
                membership = struct.pack(
                    "4s4s", socket.inet_aton(group), socket.inet_aton(interface)
                )
                sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
            sock.settimeout(0.1)
        except OSError as exc:
            raise Udp450Error(f"{self.where}: cannot listen ({exc.strerror or exc})") from exc
        self.port = sock.getsockname()[1]
        self._sock = sock
        self._clock = clock
        self.datagrams = 0
        super().__init__(self.where)

    def _close(self) -> None:  # (a receive waits 0.1 s at most: the stop is seen)
        self._sock.close()

    def take(self, wait_s: float = 0.0) -> list[Received]:
        """The sentences received since the last call; waits up to `wait_s` for the first."""
        return self._drain(wait_s)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._sock.recv(MAX_DATAGRAM)
            except TimeoutError:
                continue
            except OSError:
                return
            self.datagrams += 1
            for piece in parse_datagram(data, self._clock()):
                self._queue.put(piece)
