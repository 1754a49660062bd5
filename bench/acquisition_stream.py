"""Shared by the acquisition benchmarks: a realistic frame stream from the simulated stand, made
in lockstep with the campaign engine (no bus, no clock), and written to a python-can log."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import can

from gyrostand.acquisition.bus import transmitter
from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.devices.decoder import frame_decoder, source_info
from gyrostand.plan.model import Plan, parse_plan
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import SimConfig

ROOT = Path(__file__).resolve().parents[1]
ENCODER = {"cia406": "node_id = 5\ncounts_per_revolution = 65536\n"}  # the rest of [compass]


def paper_plan(
    database: str, trial_repeats: int = 1, n_obs: int = 5, protocol: str = "gyrostand"
) -> Plan:
    """The paper's campaign (examples/paper.toml), its six trials repeated `trial_repeats`
    times, on a SQLite file, its compass speaking `protocol` ([compass])."""
    text = (ROOT / "examples" / "paper.toml").read_text()
    text = text.replace('database = "runs/gyrostand.sqlite"', f'database = "{database}"')
    text = text.replace("n_obs = 5", f"n_obs = {n_obs}")
    head, sep, trials = text.partition("[[trials]]")
    compass = f'\n[compass]\nprotocol = "{protocol}"\n' + ENCODER.get(protocol, "")
    return parse_plan(head + (sep + trials) * trial_repeats + compass)


class _Null:
    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return lambda *args, **kwargs: None


def campaign_frames(plan: Plan, seed: int = 1, step_s: float = 20.0) -> Iterator[can.Message]:
    """Every frame of a campaign run of `plan` on the simulated stand, in stream order (its
    compass speaking the plan's [compass] protocol)."""
    compass = None
    if plan.compass.protocol != "gyrostand":
        codec = Codec()
        compass = (transmitter(plan), lambda: frame_decoder(codec, *plan.heading_source))
    stand = Lockstep(SimConfig(seed=seed), step_s, compass=compass)  # type: ignore[arg-type]
    source = source_info(Codec(), plan.compass.protocol, True, encoder=plan.compass.encoder())
    engine = Engine(plan, _Null(), stand, source=source)
    for frames in stand.steps(engine, max_stand_s=math.inf):
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
