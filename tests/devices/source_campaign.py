"""A campaign on the lockstep simulated stand (virtual time) whose compass is a heading source of
`devices` (NMEA 2000, CiA 406), and the checks every such source shares: the same observations
as with gyrostand's own heading frame, window means of the frames sent, byte-reproducible."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from gyrostand.acquisition.engine import Engine, ObservationResult
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.devices.cia406 import Cia406Heading
from gyrostand.devices.decoder import SourceDecoder
from gyrostand.devices.n2k_heading import Nmea2000Heading
from gyrostand.devices.source import SourceInfo
from gyrostand.stand.protocol import Codec
from tests.acquisition.harness import Recorder, quick_config, small_plan

PLAN = small_plan(n_obs=3)


def campaign(
    device: object | None = None,
    source: Callable[[], Nmea2000Heading | Cia406Heading] | None = None,
    info: SourceInfo | None = None,
    **stand_faults: float,
) -> tuple[Recorder, Lockstep]:
    """PLAN run with the simulated `device` as compass, read by a fresh `source` (`info`: what
    the engine is told of it); without a device, by gyrostand's own heading frame."""
    sink = Recorder()
    config = quick_config(seed=1, **stand_faults)
    if device is None or source is None:
        stand = Lockstep(config, 5.0)
        engine = Engine(PLAN, sink, stand)
    else:
        codec = Codec()
        decoder: Callable[[], SourceDecoder] = lambda: SourceDecoder(codec, source())  # noqa: E731
        stand = Lockstep(config, 5.0, codec, (device, decoder))  # type: ignore[arg-type]
        engine = Engine(PLAN, sink, stand, source=info)
    stand.run(engine)
    return sink, stand


def assert_as_gyrostand(
    ours: list[ObservationResult], gyrostand: list[ObservationResult], resolution_deg: float
) -> None:
    """The same samples at the source's resolution: the same windows, each mean within half a
    resolution step (the mean of ~300 rounding errors is far smaller), nothing lost, a still
    compass not stuck."""
    assert [(o.trial, o.j, o.k) for o in ours] == [(o.trial, o.j, o.k) for o in gyrostand]
    assert len(ours) == 12
    for a, b in zip(ours, gyrostand, strict=True):
        assert (a.window_start_ms, a.window_end_ms) == (b.window_start_ms, b.window_end_ms)
        assert abs(a.frames_used - b.frames_used) <= 1  # (the first heading: before any status)
        assert abs(a.value_deg - b.value_deg) < resolution_deg / 2
        assert a.frames_lost == 0 and "stuck" not in a.flags


def assert_window_means(sink: Recorder, t_ms: np.ndarray, deg: np.ndarray) -> None:
    """Each observation is the mean of the headings sent (stand ms `t_ms`) in its window,
    independently of the engine."""
    for obs in sink.observations:
        inside = (t_ms >= obs.window_start_ms) & (t_ms < obs.window_end_ms)
        assert obs.frames_used == inside.sum()
        ref = deg[inside][0]  # deviations from one of them: no wrap at 360 inside a window
        assert obs.value_deg == pytest.approx(ref + np.mean(deg[inside] - ref), abs=1e-9)


def stream_key(stand: Lockstep) -> list[tuple[Any, ...]]:
    """Every frame of the run as (time, identifier, payload): equal lists, equal streams."""
    return [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in stand.stream]
