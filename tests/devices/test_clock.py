"""The reception clock (devices.clock) on a synthetic real-time stream: stand statuses at 2 Hz and
headings at 10 Hz of stand time, received with random latencies on a host clock that is offset,
drifts, or runs at 1/speedup of the stand's; the headings' stand times recovered within the
latency, whatever the batches."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.devices.clock import MIN_SPAN_MS, NO_CLOCK, RATE_SNAP, WINDOW, ReceptionClock

EPOCH_S = 1_795_000_000.0


def stream(rate: float, seed: int = 1) -> tuple[np.ndarray, ...]:
    """(positions, stand ms, reception s, is status) of 600 s of stand time; the host clock
    reads EPOCH + stand / rate, latencies 0.2-3 ms of host time."""
    rng = np.random.default_rng(seed)
    status_ms = np.arange(0, 600_000, 500)
    heading_ms = np.arange(50, 600_000, 100)  # between statuses, as the compass is its own device
    stand = np.concatenate((status_ms, heading_ms))
    is_status = np.concatenate((np.ones(len(status_ms), bool), np.zeros(len(heading_ms), bool)))
    rx_s = EPOCH_S + stand / 1000.0 / rate + rng.uniform(0.2e-3, 3e-3, len(stand))
    order = np.argsort(rx_s, kind="stable")
    return np.arange(len(stand)), stand[order], rx_s[order], is_status[order]


def campaign_ms(batches: list[slice], rate: float) -> tuple[np.ndarray, np.ndarray]:
    pos, stand, rx_s, is_status = stream(rate)
    clock, got = ReceptionClock(), []
    for cut in batches:
        p, s, r, st = pos[cut], stand[cut], rx_s[cut], is_status[cut]
        clock.observe(p[st], s[st], r[st])
        got.append(clock.to_campaign_ms(p[~st], r[~st]))
    return np.concatenate(got), stand[~is_status]


@pytest.mark.parametrize("rate", [1.0, 1.00005, 20.0])  # host clock drifting 50 ppm; speedup 20
def test_headings_on_the_stand_clock_within_the_latency(rate: float) -> None:
    got, true = campaign_ms([slice(None)], rate)
    timed = got != NO_CLOCK
    assert (~timed).sum() == 0  # (the first heading comes after the first status here)
    error = got - true
    jitter_ms = 3.0 * rate  # the latency spread, in stand ms
    assert np.abs(error[600:]).max() <= jitter_ms + 1  # after a minute: the rate is known
    assert abs(np.median(error[600:])) <= jitter_ms
    if rate < 2:  # a real stand (rate 1, drifting): from the start
        assert np.abs(error).max() <= jitter_ms + 1
    else:  # sped up: from 2 s of stand time on (4 statuses) the rate is known, its error small
        # beside the latency's (timed at rate 1, the headings would be up to 430 ms off)
        assert np.abs(error[true >= 2_000]).max() <= 1.25 * jitter_ms


def test_the_same_whatever_the_batches() -> None:
    whole, _ = campaign_ms([slice(None)], 20.0)
    cuts = [0, 7, 333, 334, 5000, 9001, None]
    pieces, _ = campaign_ms([slice(a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True)], 20.0)
    assert np.array_equal(whole, pieces)


def test_before_the_first_status_there_is_no_clock() -> None:
    clock = ReceptionClock()
    assert clock.to_campaign_ms(np.array([0, 1]), np.array([5.0, 5.1])).tolist() == [-1, -1]
    clock.observe(np.array([2]), np.array([1000]), np.array([EPOCH_S]))
    got = clock.to_campaign_ms(np.array([1, 3]), np.array([EPOCH_S - 0.1, EPOCH_S + 0.25]))
    assert got.tolist() == [NO_CLOCK, 1250]


def _by_definition(rate: float) -> np.ndarray:
    """Each heading's campaign ms as the module docstring defines it, frame by frame in plain
    Python: the last status before it, that status's rate, the minimum over its window."""
    pos, stand, rx_s, is_status = stream(rate)
    rx_ms, stand_ms = rx_s[is_status] * 1000.0, stand[is_status]
    statuses = [(float(r), float(s)) for r, s in zip(rx_ms, stand_ms, strict=True)]
    first_rx, first_stand = statuses[0]
    out, seen = [], 0
    for p in range(len(pos)):
        if is_status[p]:
            seen += 1
            continue
        if seen == 0:
            out.append(NO_CLOCK)
            continue
        rx, st = statuses[seen - 1]
        span, elapsed = st - first_stand, rx - first_rx
        r = span / elapsed if span >= MIN_SPAN_MS and elapsed > 0 else 1.0
        r = 1.0 if abs(r - 1.0) < RATE_SNAP else r
        window = statuses[max(seen - WINDOW, 0) : seen]
        offset = min(r * w_rx - w_stand for w_rx, w_stand in window)
        out.append(int(np.round(r * float(rx_s[p]) * 1000.0 - offset)))
    return np.array(out)


@pytest.mark.parametrize("rate", [1.00005, 20.0])
def test_the_offset_per_status_is_the_definition(rate: float) -> None:
    """The vectorised clock (a window's minimum once per status) gives exactly the per-frame
    definition, in batches cut anywhere."""
    cuts = [0, 5, 900, 901, 4000, 8000, None]
    got, _ = campaign_ms([slice(a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True)], rate)
    assert np.array_equal(got, _by_definition(rate))
