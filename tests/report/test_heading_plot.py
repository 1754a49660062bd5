"""report.plots.heading_plot: the observation windows, a minute each in a trial of hours, get a
panel per series zoomed on them (issue 33: "figures 1-6 whose observation windows are slivers"),
and each window shows its k and its mean on that panel."""

import matplotlib as mpl
import numpy as np
import pytest

from gyrostand.report.model import HeadingTrace, ObservationRecord, SeriesRecord, TrialRecord
from gyrostand.report.plots import STYLE, heading_plot

MIN = 60_000  # ms


def _series(j: int, start_min: float, means: list[float], window_min: float = 1.0) -> SeriesRecord:
    observations = tuple(
        ObservationRecord(
            k=k,
            value_deg=value,
            window_start_ms=int((start_min + 1.5 * (k - 1)) * MIN),
            window_end_ms=int((start_min + 1.5 * (k - 1) + window_min) * MIN),
        )
        for k, value in enumerate(means, start=1)
    )
    return SeriesRecord(
        j=j,
        settle_started_ms=0,
        settle_done_ms=int(start_min * MIN),
        settle_estimate_deg=means[0],
        observations=observations,
    )


def _record(window_min: float = 1.0) -> TrialRecord:
    t = np.linspace(0.0, 180 * MIN, 600)
    heading = 120.0 - 0.15 * (t > 100 * MIN)
    trace = HeadingTrace(t, heading, heading - 0.02, heading + 0.02, frames=6000)
    still = _series(1, 57.0, [120.001, 120.008, 120.007, 119.986, 120.002], window_min)
    rocking = _series(2, 160.0, [119.866, 119.857, 119.860, 119.854, 119.853], window_min)
    return TrialRecord(index=1, series=(still, rocking), trace=trace)


def _drawn(record: TrialRecord):  # the figure before it becomes SVG
    with mpl.rc_context(STYLE):
        return heading_plot.__wrapped__(record, "Trial 1")


def test_each_series_has_a_panel_zoomed_on_its_windows() -> None:
    record = _record()
    figure = _drawn(record)
    trial, *zooms = figure.axes
    assert len(zooms) == 2
    span = np.diff(trial.get_xlim())[0]
    for zoom, series in zip(zooms, record.series, strict=True):
        low, high = zoom.get_xlim()
        starts = [o.window_start_ms / MIN for o in series.observations]
        ends = [o.window_end_ms / MIN for o in series.observations]
        assert low < min(starts) and max(ends) < high  # every window inside its panel
        width = high - low
        assert width == pytest.approx(7.0 * 1.16)  # 7 min of windows, 8 % margin each side
        # a window takes an eighth of its panel, against 1/180 of the trial's axis
        assert 1.0 / width > 0.12 and 1.0 / span < 0.01
        labels = [text.get_text() for text in zoom.texts]
        assert labels == ["1", "2", "3", "4", "5"]
        assert zoom.get_title(loc="left").endswith("windows k = 1\u20135")
        bars = {  # the windows' means: one collection of horizontal bars
            round(float(segment[0][1]), 6)
            for c in zoom.collections
            for segment in (c.get_segments() if hasattr(c, "get_segments") else ())
            if len(segment) == 2 and segment[0][1] == segment[1][1]
        }
        assert {o.value_deg for o in series.observations} <= bars  # each window's mean


def test_each_k_stands_inside_its_window_clear_of_the_settle_line() -> None:
    """Issue 33: "k = 1" touched the settle line drawn just before window 1 (windows of half a
    minute every 1.5 min, as the paper campaign's rocking series)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    record = _record(window_min=0.5)
    figure = _drawn(record)
    renderer = FigureCanvasAgg(figure).get_renderer()  # text extents
    for zoom, series in zip(figure.axes[1:], record.series, strict=True):
        to_px = zoom.transData.transform
        settle_x = to_px((series.settle_done_ms / MIN, 0.0))[0]
        for text, o in zip(zoom.texts, series.observations, strict=True):
            box = text.get_window_extent(renderer)
            left = to_px((o.window_start_ms / MIN, 0.0))[0]
            right = to_px((o.window_end_ms / MIN, 0.0))[0]
            assert left < box.x0 and box.x1 < right  # inside its window
            assert box.x0 - settle_x > 2.0  # pixels clear of the settle line


def test_the_legend_names_each_thing_once() -> None:
    labels = [t.get_text() for t in _drawn(_record()).legends[0].get_texts()]
    assert len(labels) == len(set(labels)) == 6


def test_observations_without_times_keep_one_panel() -> None:
    still = SeriesRecord(1, None, None, None, (ObservationRecord(1, 120.0, None, None),))
    figure = _drawn(TrialRecord(index=1, series=(still,), trace=None))
    assert len(figure.axes) == 1


def test_a_reused_layout_draws_the_same_figures() -> None:
    """`reused_layouts`: the trials' figures drawn on one matplotlib figure, content replaced,
    are byte for byte the figures each drawn on its own, in any order."""
    from gyrostand.report.plots import reused_layouts

    longer = _record(window_min=0.5)
    shifted = TrialRecord(
        index=2,
        series=longer.series,
        trace=HeadingTrace(
            longer.trace.t_ms,
            longer.trace.mean_deg + 3.0,
            longer.trace.min_deg + 2.9,
            longer.trace.max_deg + 3.1,
            frames=6000,
        ),
    )
    records = [_record(), longer, shifted]
    alone = [heading_plot(r, f"Trial {i}") for i, r in enumerate(records)]
    with reused_layouts():
        reused = [heading_plot(r, f"Trial {i}") for i, r in enumerate(records)]
    with reused_layouts():
        backwards = [heading_plot(r, f"Trial {i}") for i, r in reversed(list(enumerate(records)))]
    assert reused == alone and backwards[::-1] == alone
    assert len(set(alone)) == 3


def test_the_x_labels_sit_under_the_tick_labels_as_matplotlib_puts_them() -> None:
    """`_xlabel_fixed`: each axis label 4 pt (matplotlib's labelpad) under its tick labels,
    clear of them: the fixed place holds for the report's style."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    figure = _drawn(_record())
    renderer = FigureCanvasAgg(figure).get_renderer()
    for ax in figure.axes:
        ticks = [t.get_window_extent(renderer) for t in ax.get_xticklabels() if t.get_text()]
        label = ax.xaxis.label.get_window_extent(renderer)
        gap_pt = (min(t.y0 for t in ticks) - label.y1) * 72 / figure.dpi
        assert gap_pt == pytest.approx(4.0, abs=0.05)
