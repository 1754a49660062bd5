"""Test helpers: plans in a few lines, a recording sink (the lockstep simulated stand that feeds
the engine without a bus or a clock is `gyrostand.acquisition.lockstep`)."""

from __future__ import annotations

import dataclasses
import sqlite3
from pathlib import Path
from typing import Any

from gyrostand.acquisition.engine import Command, Measured, ObservationResult
from gyrostand.plan.model import Plan, parse_plan
from gyrostand.stand.simconfig import CompassParams, FaultParams, NoiseParams, SimConfig

ROOT = Path(__file__).resolve().parents[2]

SMALL_PLAN = """
[campaign]
operator = "test"
n_obs = {n_obs}
database = "{database}"
on_trial_failure = "{on_failure}"
raw_log_dir = "{raw_dir}"
acquisition_only = true

[instrument]
model = "test compass"
serial = "T-1"
lp_gcm2s2 = 6.57e6
h1_gcm2s = 1.55e8

[site]
latitude_deg = 46.5
earth_rate_rad_s = 7.3e-5
gravity_cm_s2 = 981.0

[analysis]
start_c = 7.0e7
start_t_s = 0.55

[forecast]
roll_deg = 5.0
arm_cm = 750.0
period_s = 7.0
course_deg = 45.0
latitude_deg = 57.0

[observation]
still_window_s = 30.0
rocking_window_periods = 4
spacing_s = {spacing_s}

[settle]
band_deg = 0.05
hold_s = {hold_s}
max_wait_s = 3600.0

[tracking]
confirm_s = 30.0

[timeouts]
ack_s = 2.0
bus_silence_s = 5.0

[bus]
simulated = true
seed = {seed}
{bus_extra}
{trials}
"""

# a simulated stand that settles in minutes, heading at 2 Hz: quick CLI and process tests
FAST_SIM = """
[bus.simulator]
heading_rate_hz = 2.0
status_rate_hz = 0.5
[bus.simulator.compass]
undamped_period_s = 240.0
damping_ratio = 0.8
"""


TRIAL = """
[[trials]]
direction_deg = {0}
amplitude_cm = {1}
period_s = {2}
role = "{3}"
"""


def plan_text(
    trials: list[tuple[float, float, float, str]] | None = None,
    *,
    n_obs: int = 3,
    database: str = "runs/test.sqlite",
    on_failure: str = "continue",
    hold_s: float = 60.0,
    spacing_s: float = 0.0,
    seed: int = 1,
    raw_dir: str = "runs/raw",
    bus_extra: str = "",
) -> str:
    trials = trials or [(45.0, 24.0, 6.0, "fit"), (315.0, 20.0, 5.0, "control")]
    rows = "".join(TRIAL.format(*t) for t in trials)
    return SMALL_PLAN.format(
        n_obs=n_obs,
        database=database,
        on_failure=on_failure,
        hold_s=hold_s,
        spacing_s=spacing_s,
        seed=seed,
        raw_dir=raw_dir,
        bus_extra=bus_extra,
        trials=rows,
    )


def small_plan(**kwargs: Any) -> Plan:
    return parse_plan(plan_text(**kwargs))


def quick_config(seed: int = 1, **faults: Any) -> SimConfig:
    """A simulated compass with a short transient (fast to settle) and the default noise."""
    return SimConfig(
        compass=CompassParams(undamped_period_s=240.0, damping_ratio=0.8),
        noise=NoiseParams(),
        faults=FaultParams(**faults),
        heading_rate_hz=10.0,
        seed=seed,
    )


class Recorder:
    """A Sink that keeps every call (to compare runs)."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[Any, ...]]] = []

    def __getattr__(self, name: str) -> Any:
        def record(*args: Any, **kwargs: Any) -> None:
            self.calls.append((name, args + tuple(sorted(kwargs.items()))))

        return record

    def flush(self) -> None:
        """(Nothing held back: not a call to compare.)"""

    def of(self, name: str) -> list[tuple[Any, ...]]:
        return [args for n, args in self.calls if n == name]

    @property
    def observations(self) -> list[ObservationResult]:
        return [args[0] for args in self.of("observation")]

    @property
    def measured(self) -> list[Measured | None]:
        return [args[1] for args in self.of("trial_completed")]


class NoCommands:
    """Replay's commander: the decisions were taken live; the log holds the stand's answers."""

    def issue(self, command: Command, now_ms: int = 0) -> None:
        pass


def replace_faults(config: SimConfig, **faults: Any) -> SimConfig:
    return dataclasses.replace(config, faults=FaultParams(**faults))


def dump(db: Path) -> str:
    """The whole database content as SQL text (equal iff the contents are)."""
    with sqlite3.connect(db) as conn:
        return "\n".join(conn.iterdump())


def files(folder: Path) -> list[str]:
    """The files in `folder` but SQLite's own beside a database (its write-ahead log and index,
    there while a connection is open: this process's, closed whenever it is collected)."""
    found = (p for p in folder.rglob("*") if not p.name.endswith(("-wal", "-shm", "-journal")))
    return sorted(str(p.relative_to(folder)) for p in found)
