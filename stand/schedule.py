"""Standalone mode: play a scripted stand schedule as fast as the machine allows and record every
frame to a python-can log (BLF or ASC) that decodes with the shipped DBC alone.

A schedule is a list of steps, each lasting a stand-time duration: `still` (not rocking; stops
the stand if it was rocking) or `rock` with K, A, tau (set + start; stops first if rocking). The
scripted commands and the stand's acks are recorded too, as a bus capture would show them."""

from __future__ import annotations

import functools
import math
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import can

from gyrostand.stand.engine import HeadingTransmitter, StandEngine
from gyrostand.stand.protocol import AckFrame, Codec
from gyrostand.stand.simconfig import SimConfig

if TYPE_CHECKING:
    from pydantic import BaseModel

LOG_SUFFIXES = (".blf", ".asc")
_CHUNK_S = 60.0  # stand seconds generated per batch


class ScheduleError(ValueError):
    """A schedule step or file that cannot be played."""


@dataclass(frozen=True)
class Step:
    action: str  # "still" or "rock"
    duration_s: float
    direction_deg: float = 0.0
    amplitude_cm: float = 0.0
    period_s: float = 0.0

    def __post_init__(self) -> None:
        if self.action not in ("still", "rock"):
            raise ScheduleError(f"unknown action {self.action!r} (expected still or rock)")
        if not (self.duration_s >= 0 and math.isfinite(self.duration_s)):
            raise ScheduleError(f"duration must be a number of seconds >= 0, got {self.duration_s}")

    @classmethod
    def parse(cls, text: str) -> Step:
        """`still DURATION_S` or `rock K_DEG A_CM TAU_S DURATION_S`."""
        words = text.replace(",", " ").split()
        try:
            numbers = [float(w) for w in words[1:]]
        except ValueError:
            numbers = []
        if words[:1] == ["still"] and len(numbers) == 1:
            return cls("still", numbers[0])
        if words[:1] == ["rock"] and len(numbers) == 4:
            return cls("rock", numbers[3], numbers[0], numbers[1], numbers[2])
        raise ScheduleError(
            f"bad step {text!r}: expected 'still DURATION_S' or 'rock K_DEG A_CM TAU_S DURATION_S'"
        )


def load_schedule(path: Path) -> list[Step]:
    """Steps from a TOML file: `[[step]]` tables with action, duration_s and, for rock,
    direction_deg, amplitude_cm, period_s. ScheduleError lists every problem with its path
    (``[[step]] 2 duration_s: must be >= 0``)."""
    from pydantic import ValidationError

    from gyrostand.stand.tables import problems

    try:
        document = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ScheduleError(f"cannot read schedule {path}: {exc}") from None
    model = _schedule_model()
    try:
        schedule = model.model_validate(document)
    except ValidationError as exc:
        found = problems(model, exc.errors(include_url=False))
        raise ScheduleError(f"{path}: " + "; ".join(found)) from None
    return [Step(**table.model_dump()) for table in schedule.step]  # type: ignore[attr-defined]


@functools.cache
def _schedule_model() -> type[BaseModel]:
    """The schedule file's pydantic model (built on first use: `simulate --help` stays quick)."""
    from pydantic import BaseModel, Field

    from gyrostand.stand.tables import TABLE_CONFIG

    class StepTable(BaseModel):
        model_config = TABLE_CONFIG
        action: Literal["still", "rock"]
        duration_s: float = Field(ge=0)
        direction_deg: float = 0.0
        amplitude_cm: float = 0.0
        period_s: float = 0.0

    class Schedule(BaseModel):
        model_config = TABLE_CONFIG
        step: list[StepTable] = Field(min_length=1)

    return Schedule


@dataclass(frozen=True)
class ScheduleResult:
    frames: int  # frames written to the log
    stand_duration_s: float
    wall_s: float
    refusals: tuple[AckFrame, ...]  # commands the stand refused (e.g. beyond its limits)


def run_schedule(
    config: SimConfig,
    steps: list[Step],
    log_path: Path,
    *,
    start_epoch_s: float | None = None,
    bus: can.BusABC | None = None,
    codec: Codec | None = None,
    transmitter: HeadingTransmitter | None = None,
) -> ScheduleResult:
    """Play `steps` on a fresh simulated unit, writing every frame to `log_path` (.blf / .asc)
    and, when given, sending it on `bus` too. Frame timestamps are start epoch + stand time."""
    if log_path.suffix.lower() not in LOG_SUFFIXES:
        raise ScheduleError(f"log file must end in {' or '.join(LOG_SUFFIXES)}: {log_path}")
    wall0 = time.perf_counter()
    codec = codec or Codec()
    engine = StandEngine(config, codec, transmitter)
    epoch = time.time() if start_epoch_s is None else start_epoch_s
    frames = 0
    refusals: list[AckFrame] = []
    with can.Logger(str(log_path)) as logger:

        def emit(msgs: list[can.Message]) -> None:
            nonlocal frames
            for msg in msgs:
                msg.timestamp += epoch
                logger.on_message_received(msg)
                if bus is not None:
                    bus.send(msg)
            frames += len(msgs)

        def command(msg: can.Message) -> None:
            msg.timestamp, msg.is_rx = engine.stand_time_s, False
            emit([msg])
            acks = engine.receive(msg)
            emit(acks)
            refusals.extend(
                a for a in map(codec.decode, acks) if isinstance(a, AckFrame) and not a.accepted
            )

        t_s = 0.0
        emit(engine.advance_to(t_s))
        for step in steps:
            if engine.rocking:
                command(codec.encode_command_stop())
            if step.action == "rock":
                command(
                    codec.encode_command_set(step.direction_deg, step.amplitude_cm, step.period_s)
                )
                command(codec.encode_command_start())
            end_s = t_s + step.duration_s
            while t_s < end_s:
                t_s = min(t_s + _CHUNK_S, end_s)
                emit(engine.advance_to(t_s))
    return ScheduleResult(frames, t_s, time.perf_counter() - wall0, tuple(refusals))
