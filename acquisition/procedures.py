"""The standard's procedures on the simulated compass: run-ups from switch-on, recorded from the
compass's own CAN frames (the simulated compass's `StandEngine` frames, decoded by the
acquisition's `BatchDecoder`), in stand time (virtual: as fast as the machine allows,
deterministic).

Each stage is saved as it ends (`Progress`: `campaign resume` keeps the stages done); a compass
powered by hand is switched by the operator, prompted (`before_switch_on`). Every frame heard
goes into the procedures' raw log (`RunUp(log=...)`, BLF, in campaign stand time), from which
`LoggedRunUp` re-derives the results offline (`gyrostand replay`), to the bit. On a real bus the
same procedures run on `procedures_live.LiveRunUp`, in real time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from itertools import count, takewhile
from pathlib import Path
from typing import Any

import can
import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand import SOFTWARE_VERSION
from gyrostand.analysis.procedures import (
    PROGRESS,
    ProcedureResults,
    RollingError,
    SettlePoint,
    SettlingTime,
    repeatability,
    rolling_error,
    settle_point,
    settling_time,
)
from gyrostand.analysis.transient import TransientModel
from gyrostand.db.models import PROCEDURES_RAW_LOG, ProcedureRun
from gyrostand.db.session import writer
from gyrostand.frames.batch import BatchDecoder, Headings, RawFrames
from gyrostand.frames.logfile import BatchBLFWriter, read_raw_frames
from gyrostand.plan.model import StandLimits
from gyrostand.plan.procedures import ProcedurePlan, ReferencePlan, ResolvedProcedure
from gyrostand.stand.protocol import Codec
from gyrostand.stand.runup import switch_on
from gyrostand.stand.simconfig import SimConfig

CHUNK_S = 1800.0  # stand seconds of frames decoded at once (bounds the memory)
# Between a procedure's readings nobody listens: the simulated compass runs on (`pass_to`) but
# builds and decodes no frames (the type-approval example's 32 h of stand time: 3 s of CPU
# before, most of it frames nobody read)
LISTEN_S = 1.0  # stand seconds listened for at a reading (more while none valid arrives)
LISTEN_EPS_S = 1e-6  # a wait ends this short of the reading time: its sample is heard


@dataclass(frozen=True)
class RunUpRecord:
    """One run-up: its number, the stand time of switch-on, and the valid heading readings
    (stand seconds from switch-on, deg, unwrapped) the compass sent."""

    runup: int
    switch_on_s: float
    t_s: np.ndarray
    heading_deg: np.ndarray

    def readings(self, start_s: float, n: int, interval_s: float) -> tuple[np.ndarray, np.ndarray]:
        """n readings `interval_s` apart from `start_s` (seconds from switch-on): each the
        first valid heading at or after its time (the heading indicated then)."""
        wanted = start_s + interval_s * np.arange(n)
        i = np.searchsorted(self.t_s, wanted - 1e-9)
        if i.size and i[-1] >= self.t_s.size:
            raise ValueError(
                f"run-up {self.runup}: a reading at {wanted[-1]:g} s lies after the record's "
                f"end at {self.t_s[-1]:g} s"
            )
        return self.t_s[i], self.heading_deg[i]


class RunUp:
    """Run-up k of the simulated compass, switched on at stand time `at_s` and recorded from its
    frames as stand time advances; the stand under it can be rocked (`rock`). `log`: where the
    frames heard are written (the procedures' raw log), stamped in stand time from the first
    switch-on."""

    def __init__(
        self, config: SimConfig, k: int, at_s: float, log: BatchBLFWriter | None = None
    ) -> None:
        self.k, self.at_s = k, at_s
        self.codec = Codec()
        self.engine = switch_on(config, k, at_s)
        self._log = log
        self._decoder = BatchDecoder(self.codec)
        self._t: list[np.ndarray] = []
        self._heading: list[np.ndarray] = []

    @property
    def now_s(self) -> float:
        """Stand seconds since switch-on."""
        return self.engine.stand_time_s

    @property
    def exhausted(self) -> bool:
        """Whether nothing more can be heard (a log read to its end; never a live compass)."""
        return False

    @property
    def rehears(self) -> bool:
        """Whether the stages kept from an interrupted run are gone through again (the
        simulated compass re-simulated, its log replayed: the same frames); not a real
        compass's (`LiveRunUp`): its run goes on."""
        return True

    def advance(self, until_s: float) -> None:
        """Record the compass's heading frames up to `until_s` seconds after switch-on."""
        while self.now_s < until_s:
            frames = self.engine.advance_to(min(self.now_s + CHUNK_S, until_s), compass_only=True)
            if not frames:
                continue
            raw = RawFrames.from_messages(0, frames)
            self._heard(self._decoder.decode(raw).headings)
            if self._log is not None:
                raw.timestamp[:] += self.at_s  # (the stand time the frames' STAND_TIME counts)
                self._log.write_frames(raw)

    def _heard(self, headings: Headings) -> None:
        ok = headings.valid.astype(bool)
        self._t.append((headings.t_ms[ok] - round(self.at_s * 1000.0)) / 1000.0)
        self._heading.append(headings.heading_deg[ok])

    def listen(self, from_s: float, until_s: float) -> None:
        """Record from `from_s` to `until_s` after switch-on, the time before it passed unheard
        (the compass's physics and noise run on: only the frames are not built and decoded)."""
        self._not_exhausted(from_s)
        if from_s > self.now_s:
            self.pass_to(from_s - LISTEN_EPS_S)
        self.advance(until_s)

    def _not_exhausted(self, at_s: float) -> None:
        if self.exhausted:
            raise ProcedureLogError(
                f"run-up {self.k}: the log ends before {at_s:g} s from switch-on"
            )

    def listen_for_reading(self, at_s: float) -> None:
        """Record from `at_s` until the compass has sent a valid heading at or after it (the
        reading indicated then; `RunUpRecord.readings` picks it)."""
        self.listen(at_s, at_s + LISTEN_S)
        while not any(t.size and t[-1] >= at_s - 1e-9 for t in self._t[-1:]):
            self._not_exhausted(at_s)
            self.advance(self.now_s + LISTEN_S)

    def pass_to(self, until_s: float) -> None:
        """Let stand time run to `until_s` after switch-on with nobody listening."""
        self.engine.pass_to(until_s)

    def command(self, message: can.Message) -> None:
        """A stand command at the current stand time; an error unless the stand accepts it."""
        (ack,) = self.engine.receive(message)
        frame = self.codec.decode(ack)
        if not getattr(frame, "accepted", False):
            raise ValueError(f"the stand refused {message}: {frame}")

    def record(self) -> RunUpRecord:
        """Everything recorded so far."""
        heading = np.unwrap(np.concatenate(self._heading), period=360.0)
        return RunUpRecord(self.k, self.at_s, np.concatenate(self._t), heading)


class ProcedureLogError(ValueError):
    """A procedures' raw log that does not hold what the plan's procedures heard."""


class LoggedHeadings:
    """The heading frames of a procedures' raw log, decoded once, taken in stream order by the
    run-ups replayed (`LoggedRunUp`)."""

    def __init__(self, path: Path) -> None:
        decoder = BatchDecoder(Codec())
        parts = [decoder.decode(raw).headings for raw in read_raw_frames(path)]
        if not parts:
            raise ProcedureLogError(f"{path}: no heading frame in it")
        self.headings = Headings(
            *(np.concatenate([getattr(h, f.name) for h in parts]) for f in fields(Headings))
        )
        if np.any(np.diff(self.headings.t_ms) < 0):
            raise ProcedureLogError(f"{path}: its heading frames go back in stand time")
        self.taken = 0

    def take(self, until_ms: float) -> Headings:
        """The frames not yet taken stamped at or before `until_ms` (stand time, ms)."""
        start = self.taken
        # (1e-6: a reading time's float sum; the samples lie on whole ms of stand time)
        end = int(np.searchsorted(self.headings.t_ms, until_ms + 1e-6, side="right"))
        self.taken = max(start, end)
        return self.headings.take(slice(start, self.taken))

    @property
    def left(self) -> int:
        return len(self.headings) - self.taken


class LoggedRunUp(RunUp):
    """Run-up k re-derived from the procedures' raw log: the frames it heard live, in the same
    calls (`advance`, `pass_to`: stand time only), so the record is the live one, to the bit.
    The stand's commands were sent live."""

    def __init__(self, log: LoggedHeadings, k: int, at_s: float) -> None:
        self.k, self.at_s = k, at_s
        self.codec = Codec()
        self._logged = log
        self._now_s = 0.0
        self._t, self._heading = [], []

    @property
    def now_s(self) -> float:
        return self._now_s

    @property
    def exhausted(self) -> bool:
        return self._logged.left == 0

    def advance(self, until_s: float) -> None:
        if until_s <= self._now_s:
            return
        self._now_s = until_s  # (as `StandEngine.advance_to`: its stand time is the target)
        heard = self._logged.take(round(self.at_s * 1000.0) + until_s * 1000.0)
        if heard.t_ms.size:  # (live: a chunk without frames is not recorded)
            self._heard(heard)

    def pass_to(self, until_s: float) -> None:
        self._now_s = max(self._now_s, until_s)

    def command(self, message: can.Message) -> None:
        pass


ROLLING_WINDOW_PERIODS = 8  # a reading under rolling: the mean over whole rocking periods


def _settle_point(
    runup: RunUp, proc: ProcedurePlan, start_s: float, reference: ReferencePlan | None
) -> SettlePoint:
    """The proc's readings from `start_s` after switch-on, and the settle point they give."""
    n, interval = proc.readings, proc.interval_s
    assert n is not None and interval is not None  # resolved
    for i in range(n):
        runup.listen_for_reading(start_s + i * interval)
    runup.pass_to(start_s + (n - 1) * interval + 1.0)
    _, values = runup.record().readings(start_s, n, interval)
    if reference is None:
        return settle_point(values, interval)
    return settle_point(values, interval, reference.heading_deg, reference.uncertainty_deg)


def _rolling(
    runup: RunUp,
    proc: ProcedurePlan,
    static: SettlePoint,
    limits: StandLimits,
    progress: Progress,
) -> tuple[RollingError, ...]:
    """Each point of the envelope: rock, wait for the transient, take the readings (each a mean
    over whole rocking periods), stop; a point beyond the stand is left to the forecast. A point
    done before an interruption is kept (heard again for the raw log: the compass the same)."""
    out: list[RollingError] = []
    kept = [RollingError(**r) for r in progress.done.get("rolling", [])]
    n, interval = proc.readings, proc.interval_s
    assert n is not None and interval is not None and proc.points is not None  # resolved
    for point in proc.points:
        if limits.broken(point):
            out.append(
                RollingError(
                    point.direction_deg, point.amplitude_cm, point.period_s, None, None, True
                )
            )
            continue
        measured = len(out) >= len(kept)
        if not measured and not runup.rehears:
            out.append(kept[len(out)])
            continue
        codec = runup.codec
        runup.command(
            codec.encode_command_set(point.direction_deg, point.amplitude_cm, point.period_s)
        )
        runup.command(codec.encode_command_start())
        first = runup.now_s + proc.wait_s
        width = ROLLING_WINDOW_PERIODS * point.period_s
        for i in range(n):
            runup.listen(first + i * interval, first + i * interval + width)
        runup.pass_to(first + (n - 1) * interval + width + 1.0)
        runup.command(codec.encode_command_stop())
        if not measured:
            out.append(kept[len(out)])
            continue
        record = runup.record()
        means = []
        for i in range(n):
            a = first + i * interval
            inside = (record.t_s >= a) & (record.t_s < a + width)
            means.append(float(record.heading_deg[inside].mean()))
        out.append(
            rolling_error(
                point.direction_deg, point.amplitude_cm, point.period_s, np.array(means), static
            )
        )
        progress.save("rolling", [asdict(r) for r in out])
    return tuple(out)


RAW_LOG = PROCEDURES_RAW_LOG  # the key of the procedures' raw log in their stored record


@dataclass(frozen=True)
class ProcedureLog:
    """The procedures' raw log: the file, its frames, its SHA-256."""

    path: str
    frames: int
    sha256: str


@dataclass(frozen=True)
class ReplayedProcedures:
    """The standard's procedures re-derived from their raw log, and that log."""

    results: ProcedureResults
    log: ProcedureLog


def procedures_log_path(can_log: Path | str) -> Path:
    """The procedures' raw log beside the campaign's first raw CAN log (always BLF)."""
    can_log = Path(can_log)
    return can_log.with_name(f"{can_log.stem}.procedures.blf")


def procedures_run_log(first: Path, run: int) -> Path:
    """The procedures' log of a campaign's run on a real bus: the first run's (`first`, from
    `procedures_log_path`), then -resume1, -resume2, ... for the resumed runs."""
    return first.with_name(f"{first.stem}-resume{run}.blf") if run else first


def procedures_run_logs(first: Path | str) -> list[Path]:
    """The procedures' logs of a campaign's runs on disk, the first run's on."""
    return list(takewhile(Path.exists, (procedures_run_log(Path(first), k) for k in count())))


def procedures_logs_of(raw_log: Path | str) -> list[Path]:
    """The procedures' logs on disk that go with a campaign's raw log: those beside its CAN
    log, or, given the procedures' first log itself, it and its resumed runs'."""
    raw_log = Path(raw_log)
    procedures = raw_log.name.endswith(".procedures.blf")
    return procedures_run_logs(raw_log if procedures else procedures_log_path(raw_log))


def replay_procedures(
    config: SimConfig,
    procedures: tuple[ResolvedProcedure, ...],
    reference: ReferencePlan | None,
    model: TransientModel,
    limits: StandLimits,
    latitude_deg: float,
    path: Path,
) -> ProcedureResults:
    """The procedures re-derived from their raw log (`run_procedures` on `LoggedRunUp`s):
    ProcedureLogError when the log does not hold every frame they heard, or holds more."""
    logged = LoggedHeadings(path)
    results = run_procedures(
        config,
        procedures,
        reference,
        model,
        limits,
        latitude_deg,
        runups=lambda k, at_s: LoggedRunUp(logged, k, at_s),
    )
    if logged.left:
        raise ProcedureLogError(
            f"{path}: {logged.left} heading frames after the procedures' last: the log of "
            "other procedures than the plan's"
        )
    return results


@dataclass
class Progress:
    """What the procedures have done so far, by stage (JSON-ready: "settling", "static" and
    "static_end_s", "rolling", "runup K"), and where each new stage is saved (`save`: the
    campaign database's checkpoint, so that a resumed campaign keeps them)."""

    done: dict[str, Any] = field(default_factory=dict)
    saved: Callable[[dict[str, Any]], None] = lambda done: None

    def save(self, stage: str, value: Any) -> None:
        self.done[stage] = value
        self.saved(self.done)


def run_procedures(
    config: SimConfig,
    procedures: tuple[ResolvedProcedure, ...],
    reference: ReferencePlan | None,
    model: TransientModel,
    limits: StandLimits,
    latitude_deg: float,
    progress: Progress | None = None,
    before_switch_on: Callable[[int], None] = lambda k: None,
    runups: Callable[[int, float], RunUp] | None = None,
) -> ProcedureResults:
    """The plan's procedures on the simulated compass, in stand time: run-up 1 from switch-on
    (settling), its settle point after the settling record, the rolling points, then the
    further run-ups of the repeatability, each after the compass was off for `off_s`.

    `progress`: the stages done before an interruption are kept, not measured again; the
    simulated compass is brought through them heard as before (the same draws: the raw log
    holds every stage's frames), so the stage interrupted is redone on the compass it would have
    met. `before_switch_on(k)`: called before run-up k is switched on (a compass powered by
    hand: the operator's prompts). `runups(k, at_s)`: run-up k switched on at stand time at_s
    (default: the simulated compass, unlogged; `LoggedRunUp` in a replay)."""
    progress = progress or Progress()
    runup_at = runups or (lambda k, at_s: RunUp(config, k, at_s))
    done = progress.done
    by_kind = {p.kind: p.plan for p in procedures}
    settling = by_kind["settling"]
    assert settling.max_wait_s is not None and settling.band_deg is not None  # resolved
    before_switch_on(1)
    first = runup_at(1, 0.0)
    first.advance(settling.max_wait_s)
    if "settling" in done:
        settled = SettlingTime.from_dict(done["settling"])
    else:
        record = first.record()
        settled = settling_time(
            record.t_s,
            record.heading_deg,
            settling.band_deg / 2,
            model.w,
            model.xi,
            settling.fit_from_s or 0.0,
        )
        progress.save("settling", settled.to_dict())
    readings = by_kind.get("settle_point") or by_kind.get("repeatability")
    # the readings after settling: from the record's end, or the settling time (+ U) if later
    start_s = settling.max_wait_s
    if settled.settled:
        start_s = max(start_s, settled.value_s + settled.expanded_s)
    static = None
    if readings is not None:
        static = _settle_point(first, readings, start_s, reference)
        if "static" in done:
            static = SettlePoint.from_dict(done["static"])
        else:
            progress.save("static_end_s", first.now_s)
            progress.save("static", asdict(static))
    rolling: tuple[RollingError, ...] = ()
    if "rolling" in by_kind and static is not None:
        rolling = _rolling(first, by_kind["rolling"], static, limits, progress)
    repeat = None
    if "repeatability" in by_kind and static is not None:
        proc = by_kind["repeatability"]
        points, at_s = [static], first.at_s + first.now_s
        for k in range(2, proc.runups + 1):
            at_s += proc.off_s
            stage = f"runup {k}"
            if stage not in done:  # a run-up interrupted is redone from switch-on
                before_switch_on(k)
            runup = runup_at(k, at_s)
            point = _settle_point(runup, proc, start_s, reference)
            if stage not in done:
                progress.save(stage, {"settle_point": asdict(point), "end_s": runup.now_s})
            points.append(SettlePoint.from_dict(done[stage]["settle_point"]))
            at_s += done[stage]["end_s"]
        repeat = repeatability(points)
    return ProcedureResults(
        settling=settled,
        settle_point=static if "settle_point" in by_kind else None,
        repeatability=repeat,
        rolling=rolling,
        reference_deg=None if reference is None else reference.heading_deg,
        latitude_deg=latitude_deg,
        departures=tuple((p.kind, d) for p in procedures for d in p.departures),
    )


def store_procedures(
    sessions: sessionmaker[Session],
    campaign_id: int,
    results: ProcedureResults,
    raw_log: ProcedureLog | None = None,
) -> None:
    """Store the campaign's procedure results (once: a resumed campaign keeps them), with the
    raw log of the frames they heard."""
    record = results.to_dict()
    if raw_log is not None:
        record[RAW_LOG] = asdict(raw_log)
    _store(sessions, campaign_id, record)


def save_progress(
    sessions: sessionmaker[Session], campaign_id: int, done: dict[str, Any], raw_log: Path
) -> None:
    """The stages done so far (`Progress.done`) and the raw log being written, in the
    campaign's procedure row until the results replace them."""
    _store(sessions, campaign_id, {PROGRESS: done, RAW_LOG: {"path": str(raw_log)}})


def _store(sessions: sessionmaker[Session], campaign_id: int, record: dict[str, Any]) -> None:
    with writer(sessions).begin() as session:
        row = session.scalar(select(ProcedureRun).where(ProcedureRun.campaign_id == campaign_id))
        if row is None:
            row = ProcedureRun(campaign_id=campaign_id, results_json=record)
            session.add(row)
        row.results_json = record
        row.software_version = SOFTWARE_VERSION


def stored_progress(
    sessions: sessionmaker[Session], campaign_id: int
) -> tuple[bool, dict[str, Any]]:
    """Whether the campaign's procedures were all run and stored (a resumed campaign skips
    them), and else the stages an interrupted run did (empty: none)."""
    with sessions() as session:
        record = session.scalar(
            select(ProcedureRun.results_json).where(ProcedureRun.campaign_id == campaign_id)
        )
    if record is None:
        return False, {}
    if PROGRESS in record:
        return False, dict(record[PROGRESS])
    return True, {}
