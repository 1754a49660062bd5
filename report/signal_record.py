"""The stationary reading record of the signal analysis (report section 10) from a raw CAN log:
valid heading frames by stand time, read with the vectorised log reader and batch decoder.

    still_series_record(logs, codec, records) -> (ReadingRecord | None, note)   # a campaign
    log_record(log, codec, start_s=None, end_s=None) -> ReadingRecord           # a log alone
    log_signal(log, plan=None, start_s=None, end_s=None) -> SignalSection       # its section 10

A campaign's natural stationary record is a still series (j = 1) from its first to its last
observation window: the compass has settled and the stand is still. The longest one is the
record; the correlation function (seed 004 eq 8.92) pools the other still series with it, each a
realisation of the same reading (one 420 s record of a reading with a 20 s correlation time gave
the inflation of a still series' variance with an SD of 0.13 for 1.08). A log without a campaign
gives its longest still stretch by the stand's status frames (or a stand-time span asked for).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gyrostand.analysis.errors import AnalysisError
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import Plan
from gyrostand.report.model import ExcursionCriterion, ReadingRecord, TrialRecord
from gyrostand.report.signal import SignalSection, signal_section, uniform_record
from gyrostand.stand.protocol import Codec, SignalMap

if TYPE_CHECKING:  # the log readers and decoders are imported where a log is read: a report
    # rebuilt from its recorded analysis reads none (python-can, cantools, the device modules)
    from gyrostand.devices.decoder import SourceDecoder
    from gyrostand.devices.serial_decoder import SerialSourceDecoder
    from gyrostand.frames.batch import BatchDecoder
    from gyrostand.stand.encoder import Encoder

Span = tuple[float, float]  # stand ms, [start, end)
SerialLine = tuple[int, bool]  # an IEC 61162 compass's baud rate; virtual time
Drive = tuple[int, int]  # a CiA 402 stand's drive and master node ids (`devices.cia402_log`)
# `Plan.heading_source`, for a serial compass its line (its sentences in the serial logs),
# whether the compass is on a CAN bus of its own, and a CiA 402 stand's drive
HeadingSource = tuple[
    str, str | None, tuple[str, str], "Encoder | None", SerialLine | None, bool, Drive | None
]
GYROSTAND: HeadingSource = ("gyrostand", None, ("", ""), None, None, False, None)


def heading_source(plan: Plan) -> HeadingSource:
    """The plan's heading source as its raw logs are read back."""
    line = drive = None
    if plan.compass.protocol == "iec61162":
        line = (plan.compass.baud, plan.bus.timing == "virtual")
    if plan.stand.protocol == "cia402" and plan.stand.node_id is not None:
        from gyrostand.devices.cia402 import MASTER_NODE_ID

        drive = (plan.stand.node_id, MASTER_NODE_ID)
    return (*plan.heading_source, line, plan.compass.own_bus, drive)


def headings_in(
    logs: Sequence[Path],
    codec: Codec,
    spans: dict[int, Span],
    source: HeadingSource = GYROSTAND,
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Valid heading frames (stand ms, deg) inside each span of the logs read in order as one
    stream (a campaign's raw log segments), in stream order, from the plan's heading source."""
    stats = [(str(p), p.stat()) for p in logs]
    stamps = tuple((path, stat.st_size, stat.st_mtime_ns) for path, stat in stats)
    t, h = _valid_headings(stamps, codec.dbc_path, codec.signal_map, source)
    found = {}
    for key, (start, end) in spans.items():
        inside = (t >= start) & (t < end)
        found[key] = (t[inside], h[inside])
    return found


@functools.lru_cache(maxsize=1)
def _valid_headings(
    stamps: tuple[tuple[str, int, int], ...],
    dbc_path: Path,
    signal_map: SignalMap,
    source: HeadingSource,
) -> tuple[np.ndarray, np.ndarray]:
    """Every valid heading frame of the logs (path, size, mtime) read in order as one stream.
    Kept for the next call with the same files: the analysis and the report's plots of one
    campaign read its log once (a changed file has another size or mtime; the report verifies
    each log's SHA-256 before reading it)."""
    from gyrostand.devices.cia402_log import compass_frames
    from gyrostand.devices.decoder import SourceDecoder, frame_decoder
    from gyrostand.devices.iec61162 import Iec61162Source
    from gyrostand.devices.serial_replay import check_serial_logs, serial_replay
    from gyrostand.frames.logfile import read_segments

    protocol, name, product, encoder, line, own_bus, drive = source
    codec, paths = Codec(dbc_path, signal_map), [Path(path) for path, _, _ in stamps]
    decoder: BatchDecoder | SourceDecoder | SerialSourceDecoder
    if line is None:
        decoder = frame_decoder(codec, protocol, name, product, encoder, own_bus=own_bus)
        stream = read_segments(paths)
        if drive is not None and isinstance(decoder, SourceDecoder):  # no stand frames
            stream = compass_frames(paths, *drive, decoder.clock)
    else:  # LogFileError for serial logs missing or unreadable
        check_serial_logs(paths, line[1])
        decoder, stream = serial_replay(codec, Iec61162Source(line[0]), paths, line[1])
    times, values = [np.empty(0)], [np.empty(0)]
    for raw in stream:
        headings = decoder.decode(raw).headings
        times.append(headings.t_ms[headings.valid])
        values.append(headings.heading_deg[headings.valid])
    t, h = np.concatenate(times), np.concatenate(values)
    t.setflags(write=False)
    h.setflags(write=False)
    return t, h


def _still_spans(records: tuple[TrialRecord, ...]) -> dict[int, Span]:
    """Per trial, its still series from the first window start to the last window end."""
    spans = {}
    for record in records:
        for s in record.series:
            timed = [o for o in s.observations if o.window_start_ms is not None]
            ends = [o.window_end_ms for o in timed if o.window_end_ms is not None]
            if s.j == 1 and timed and ends:
                spans[record.index] = (min(o.window_start_ms for o in timed), max(ends))
    return spans


def still_series_record(
    logs: Sequence[Path],
    codec: Codec,
    records: tuple[TrialRecord, ...],
    source: HeadingSource = GYROSTAND,
) -> tuple[ReadingRecord | None, str]:
    """The longest still-series record of a campaign in its raw log segments (by heading
    frames), and a note saying what it is, or why there is none."""
    spans = _still_spans(records)
    if not spans:
        return None, "No still series with timed observation windows: no stationary record."
    frames = headings_in(logs, codec, spans, source)
    index = max(sorted(frames), key=lambda i: frames[i][0].size)  # ties: the first trial
    t, h = frames[index]
    if t.size < 3:
        return None, "The raw CAN log has no heading frames within the still series."
    start, end = spans[index]
    record = uniform_record(
        t,
        h,
        f"trial {index}, still series (j = 1), stand time {start / 1000:.1f}-{end / 1000:.1f} s",
    )
    others = [
        uniform_record(*frames[i], f"trial {i}")
        for i in sorted(frames)
        if i != index and frames[i][0].size >= 3
    ]
    pooled = tuple(o.reading_deg for o in others if o.dt_s == record.dt_s)  # one grid interval
    note = (
        f"The longest stationary record of the campaign: trial {index}'s still series (j = 1) "
        "from its first to its last observation window, from the raw CAN log. Linear trend "
        "removed before the analysis"
        + (
            f"; the correlation function and its models pool the {len(pooled)} other still "
            "series, each less its own line (a correlation function is an average over "
            "realisations; the spectrum, harmonics and Allan deviation are of this record alone)"
            if pooled
            else ""
        )
        + "."
    )
    return replace(record, others=pooled), note


def still_stretch(log: Path, codec: Codec) -> Span | None:
    """The longest run of stand status frames reporting no rocking, as a stand-time span
    [first, last]; None when the log has no status frame at all."""
    from gyrostand.frames.batch import BatchDecoder
    from gyrostand.frames.logfile import read_segments

    decoder = BatchDecoder(codec)
    times, rocking = [], []
    for raw in read_segments([log]):
        statuses = decoder.decode(raw).statuses
        times.append(statuses.t_ms)
        rocking.append(statuses.rocking.astype(bool))
    t = np.concatenate(times) if times else np.empty(0)
    if not t.size:
        return None
    still = ~np.concatenate(rocking)
    if not still.any():
        raise AnalysisError(f"{log.name}: the stand rocks throughout: give a stand-time span")
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    longest = int(np.argmax(t[stops] - t[starts]))
    return float(t[starts[longest]]), float(t[stops[longest]])


def log_record(
    log: Path,
    codec: Codec,
    start_s: float | None = None,
    end_s: float | None = None,
    source: HeadingSource = GYROSTAND,
) -> ReadingRecord:
    """The record of a raw log alone: the stand-time span asked for (seconds), else the
    longest still stretch by the stand's status frames (the whole log when it has none).
    AnalysisError when the span holds too few heading frames."""
    if start_s is not None or end_s is not None:
        span = (
            -np.inf if start_s is None else start_s * 1000.0,
            np.inf if end_s is None else end_s * 1000.0,
        )
        if not span[0] < span[1]:
            raise AnalysisError(f"empty stand-time span {start_s} to {end_s} s")
        what = "the stand-time span asked for"
    elif (stretch := still_stretch(log, codec)) is not None:
        span, what = (stretch[0], stretch[1] + 1.0), "the longest still stretch"
    else:
        span, what = (-np.inf, np.inf), "the whole log (no stand status frames)"
    t, h = headings_in([log], codec, {0: span}, source)[0]
    if t.size < 3:
        raise AnalysisError(f"{log.name}: {t.size} valid heading frames in {what}")
    source = f"raw log {log.name}, {what}: stand time {t[0] / 1000:.1f}-{t[-1] / 1000:.1f} s"
    return uniform_record(t, h, source)


def log_signal(
    log: Path, plan: Plan | None = None, start_s: float | None = None, end_s: float | None = None
) -> SignalSection:
    """Section 10 for a raw log alone: its record (`log_record`), decoded with the plan's
    protocol and judged by the plan's [acceptance] when a plan is given."""
    codec = Codec() if plan is None else codec_for(plan)
    record = log_record(
        log, codec, start_s, end_s, GYROSTAND if plan is None else heading_source(plan)
    )
    note = "A raw log without its campaign: no series, no settle points."
    return signal_section(record, note, (), acceptance_of(plan))


def acceptance_of(plan: Plan | None) -> ExcursionCriterion | None:
    """The plan's [acceptance] table as the report's criterion (None: not asked for)."""
    if plan is None or plan.acceptance is None:
        return None
    a = plan.acceptance
    return ExcursionCriterion(a.tolerance_deg, a.duration_s, a.max_risk)
