"""Shared by the acquisition benchmarks: a realistic frame stream from the simulated stand, made
in lockstep with the campaign engine (no bus, no clock), and written to a python-can log."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import can

from gyrostand.acquisition.engine import Command, Engine, Phase
from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.plan.model import Plan, parse_plan
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import SimConfig

ROOT = Path(__file__).resolve().parents[1]


def paper_plan(database: str, trial_repeats: int = 1, n_obs: int = 5) -> Plan:
    """The paper's campaign (examples/paper.toml), its six trials repeated `trial_repeats`
    times, on a SQLite file."""
    text = (ROOT / "examples" / "paper.toml").read_text()
    text = text.replace('database = "runs/gyrostand.sqlite"', f'database = "{database}"')
    text = text.replace("n_obs = 5", f"n_obs = {n_obs}")
    head, sep, trials = text.partition("[[trials]]")
    return parse_plan(head + (sep + trials) * trial_repeats)


class _Null:
    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return lambda *args, **kwargs: None


class _Stand:
    """Commands reach the simulated stand between steps; its answers join the stream."""

    def __init__(self, config: SimConfig) -> None:
        self.codec = Codec()
        self.stand = StandEngine(config, Codec())
        self.pending: list[can.Message] = []

    def issue(self, command: Command, now_ms: int = 0) -> None:
        if command.kind == "set":
            msg = self.codec.encode_command_set(
                command.direction_deg, command.amplitude_cm, command.period_s
            )
        elif command.kind == "start":
            msg = self.codec.encode_command_start()
        else:
            msg = self.codec.encode_command_stop()
        msg.timestamp = self.stand.stand_time_s
        self.pending += [msg, *self.stand.receive(msg)]


def campaign_frames(plan: Plan, seed: int = 1, step_s: float = 20.0) -> Iterator[can.Message]:
    """Every frame of a campaign run of `plan` on the simulated stand, in stream order."""
    stand = _Stand(SimConfig(seed=seed))
    engine = Engine(plan, _Null(), stand)
    decoder = BatchDecoder(Codec())
    t, position = 0.0, 0
    while engine.phase is not Phase.DONE:
        t += step_s
        frames, stand.pending = stand.pending + stand.stand.advance_to(t), []
        engine.feed(decoder.decode(RawFrames.from_messages(position, frames)))
        position += len(frames)
        yield from frames


def write_log(path: Path, frames: Iterator[can.Message]) -> int:
    n = 0
    with can.Logger(path) as writer:
        for msg in frames:
            writer.on_message_received(msg)
            n += 1
    return n


def rss_mib() -> float:
    """Resident memory of this process now, MiB (Linux /proc)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")
