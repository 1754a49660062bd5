"""A serial compass's raw logs read back: the TAG-block log beside each CAN log (its name with
`.nmea`), merged with the CAN log's frames exactly as the live run merged them (`replay`, the
report's reading record).

The serial log's times are the live run's reception times (Unix time; virtual time: stand
time); a BLF file's frames count from its start, which its header keeps (to the ms, as the
writer counted from it). In virtual time the frames are timed by the stand time they carry, as
live, and the header is not needed."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

from gyrostand.devices.framing import Received
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.serial_decoder import SerialSourceDecoder
from gyrostand.devices.tagblock import SUFFIX, read_tag_log
from gyrostand.frames.batch import RawFrames
from gyrostand.frames.logfile import LogFileError, blf_start_s, read_raw_frames
from gyrostand.stand.protocol import Codec


def serial_log_path(can_log: Path | str) -> Path:
    """The serial raw log beside a CAN raw log."""
    return Path(can_log).with_suffix(SUFFIX)


def logged_pieces(can_logs: Sequence[str | Path]) -> int:
    """The pieces of the serial logs beside these CAN logs (complete lines)."""
    paths = [serial_log_path(log) for log in can_logs]
    return sum(sum(1 for _ in read_tag_log(p)) for p in paths if p.is_file())


def check_serial_logs(can_logs: Sequence[Path], virtual: bool) -> int:
    """The serial logs beside a replay's CAN logs, read whole (`LogFileError` naming what is
    wrong); their pieces. Out of virtual time each CAN log must give its start time."""
    for log in can_logs:
        path = serial_log_path(log)
        if not path.is_file():
            raise LogFileError(f"{path}: no serial log beside {log.name} (the compass's sentences)")
        if not virtual and blf_start_s(log) is None:
            raise LogFileError(
                f"{log}: no start time in its header (its writer was killed): its frames "
                "cannot be put on the serial log's clock"
            )
    try:
        return logged_pieces(can_logs)
    except OSError as exc:
        raise LogFileError(f"{exc.filename}: {exc.strerror or exc}") from exc


class ReplayedLine:
    """The serial logs read in order as one line: `until(us)` gives the pieces whose first
    byte came before that time (`SerialSourceDecoder`'s `replayed`: it holds those still on
    the wire after its batch's frames)."""

    def __init__(self, paths: Sequence[Path]) -> None:
        self._pieces: Iterator[Received] = (p for path in paths for p in read_tag_log(path))
        self._next: Received | None = next(self._pieces, None)

    def until(self, horizon_us: int) -> list[Received]:
        out: list[Received] = []
        while self._next is not None and self._next.time_s * 1e6 < horizon_us:
            out.append(self._next)
            self._next = next(self._pieces, None)
        return out


def serial_replay(
    codec: Codec, source: Iec61162Source, can_logs: Sequence[Path], virtual: bool
) -> tuple[SerialSourceDecoder, Iterator[RawFrames]]:
    """The merged stream's decoder and the CAN logs' frames, on the serial log's clock."""
    line = ReplayedLine([serial_log_path(p) for p in can_logs])
    decoder = SerialSourceDecoder(codec, source, replayed=line.until, stand_time=virtual)

    def frames() -> Iterator[RawFrames]:
        for log in can_logs:
            start = 0.0 if virtual else blf_start_s(log) or 0.0
            for raw in read_raw_frames(log):
                raw.timestamp[:] += start
                yield raw

    return decoder, frames()
