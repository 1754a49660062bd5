"""The report's figures as inline SVG images (matplotlib's object API with the SVG canvas: no
pyplot state, no display). Output is deterministic: no date or software in the metadata.

- `heading_plot`: one trial's heading from the raw CAN log (binned mean and min-max band) with
  the observation windows shaded and the settle points marked; without a log, the stored
  observations over their windows (or against k when they carry no times);
- `measured_vs_model`: <delta_i> against alpha_i for every trial;
- `residuals_plot`: v_i = <delta_i> - alpha_i per trial with the S_e bounds;
- `forecast_plot`: alpha_p against the ship's course with its prediction band and the limit;
- `iteration_path_plot`: the Gauss-Newton iterates in the (C, T) plane over contours of S^2;
- `correlation_plot`, `spectrum_plot`, `allan_plot`: the noise of the stationary reading:
  correlation estimate with the fitted models, Welch spectrum with the detection threshold and
  the harmonics found, Allan deviation.
"""

from __future__ import annotations

import base64
import functools
import io
import re
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import TYPE_CHECKING, Any, ParamSpec

import numpy as np

from gyrostand.analysis.campaign import CampaignAnalysis
from gyrostand.analysis.gyro_model import Conditions, RollingErrorModel
from gyrostand.analysis.noise import NoiseCharacterisation
from gyrostand.report import figure_cache
from gyrostand.report.build import ForecastSection, TrialRow
from gyrostand.report.model import ObservationRecord, SeriesRecord, TrialRecord

if TYPE_CHECKING:  # matplotlib is imported where a figure is drawn: not for a cached one
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

STYLE = {
    "font.family": "sans-serif",
    "font.sans-serif": ["DejaVu Sans"],  # the SVG's text: 'DejaVu Sans', sans-serif
    "font.size": 8.0,
    "axes.titlesize": 9.0,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "legend.fontsize": 7.0,
    "legend.framealpha": 0.85,
    "svg.hashsalt": "gyrostand",  # the same ids in every run: deterministic files
    "svg.fonttype": "none",
    # the title at a fixed height: matplotlib otherwise measures every tick label of the axes
    # to lift the title clear of them (a fifth of the figures' time)
    "axes.titley": 1.0,
    "axes.titlepad": 4.0,
}
NO_METADATA = {"Date": None, "Creator": None, "Format": None, "Type": None}
SERIES_COLOURS = {1: "#1f77b4", 2: "#d95f02"}  # still, rocking
SERIES_LABELS = {1: "still (j = 1)", 2: "rocking (j = 2)"}
WIDTH_IN = 7.0


P = ParamSpec("P")


def _styled(plot: Callable[P, Figure]) -> Callable[P, str]:
    """Run a figure builder under the report's style and return it as an inline SVG image (a
    data URI: the HTML stays self-contained, and the PDF gets the same figure as vectors); one
    drawn before from the same arguments comes from `figure_cache`."""

    @functools.wraps(plot)
    def svg(*args: P.args, **kwargs: P.kwargs) -> str:
        def draw() -> str:
            import matplotlib as mpl
            from matplotlib.backends.backend_svg import FigureCanvasSVG

            buffer = io.BytesIO()
            with mpl.rc_context(STYLE):
                figure = plot(*args, **kwargs)
                FigureCanvasSVG(figure).print_svg(buffer, metadata=NO_METADATA)
            width_mm = figure.get_figwidth() * 25.4
            data = base64.b64encode(buffer.getvalue()).decode("ascii")
            return (
                f'<img src="data:image/svg+xml;base64,{data}" '
                f'style="width: {width_mm:.0f}mm" alt="">'
            )

        return figure_cache.cached(plot.__qualname__, args, kwargs, STYLE, draw)

    return svg


MARGIN_IN = {"left": 0.8, "right": 0.15, "bottom": 0.45, "top": 0.3}
"""Room around the axes, inches: tick labels and axis label, title. Fixed margins rather than
matplotlib's constrained layout, which measures every text twice and took half of the figures'
time (1.8 of 3.7 s CPU for the paper campaign's 13)."""
LEGEND_ROW_IN = 0.16  # one row of a 6.5 pt legend
XLABEL_BELOW_PT = 19.0
"""Where matplotlib puts an x-axis label under one line of 8 pt tick labels: its top 19 pt below
the axes (tick 3.5, pad 3.5, the labels' line 8.0, labelpad 4.0)."""


def _xlabel_fixed(ax: Axes) -> None:
    """The x-axis label `XLABEL_BELOW_PT` under the axes, where matplotlib would put it: placed
    by itself, matplotlib ticks and measures the axis over again for every label (about 5 % of
    a figure's time)."""
    from matplotlib.transforms import ScaledTranslation

    fig = ax.get_figure()
    assert fig is not None
    below = ScaledTranslation(0.0, -XLABEL_BELOW_PT / 72.0, fig.dpi_scale_trans)
    ax.xaxis.set_label_coords(0.5, 0.0, transform=ax.transAxes + below)


def _figure(
    height_in: float,
    width_in: float = WIDTH_IN,
    right_in: float = 0.0,
    below_in: float = 0.0,
    axes: bool = True,
) -> Figure:
    """A figure with one axes inside fixed margins, `right_in` more on the right (a legend) and
    `below_in` more below (long tick labels); without `axes`, the margins only (a grid of axes
    to add: an axes made and removed costs as much as one drawn)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in))
    fig.subplots_adjust(
        left=MARGIN_IN["left"] / width_in,
        right=1 - (MARGIN_IN["right"] + right_in) / width_in,
        bottom=(MARGIN_IN["bottom"] + below_in) / height_in,
        top=1 - MARGIN_IN["top"] / height_in,
    )
    if axes:
        ax = fig.add_subplot()
        if not below_in:  # one line of tick labels under the axes
            _xlabel_fixed(ax)
    return fig


def _legend_below(fig: Figure, ncols: int, fontsize: float) -> None:
    """The figure's legend in rows of `ncols` under the axes, the bottom margin grown to fit."""
    ax = fig.axes[0]
    rows = -(-len(ax.get_legend_handles_labels()[1]) // ncols)
    height = fig.get_figheight()
    fig.subplots_adjust(bottom=(MARGIN_IN["bottom"] + rows * LEGEND_ROW_IN + 0.05) / height)
    fig.legend(loc="lower center", bbox_to_anchor=(0.5, 0.0), ncols=ncols, fontsize=fontsize)


def _minutes(t_ms: float | np.ndarray, t0_ms: float) -> float | np.ndarray:
    return (np.asarray(t_ms, dtype=float) - t0_ms) / 60_000.0


def _trial_start_ms(record: TrialRecord) -> float | None:
    starts = [
        t
        for s in record.series
        for t in [s.settle_started_ms, *(o.window_start_ms for o in s.observations)]
        if t is not None
    ]
    if record.trace is not None and record.trace.t_ms.size:
        starts.append(float(record.trace.t_ms[0]))
    return min(starts) if starts else None


def _mark_series(
    ax: Axes, series: SeriesRecord, t0: float, labelled: set[int], legend: bool = True
) -> None:
    """Series j's windows shaded with their means as bars, its settle point; the legend's entries
    once per series (`labelled`), none when `legend` is False. The windows are one collection
    of spans and one of bars, not an artist each (a fifth of a heading figure's time)."""
    colour = SERIES_COLOURS[series.j]
    windows = _windowed(series)
    if windows:
        first = legend and series.j not in labelled
        labelled.add(series.j)
        x0 = _minutes(np.array([o.window_start_ms for o in windows], dtype=float), t0)
        x1 = _minutes(np.array([o.window_end_ms for o in windows], dtype=float), t0)
        from matplotlib.collections import PolyCollection

        spans = PolyCollection(
            [((a, 0.0), (a, 1.0), (b, 1.0), (b, 0.0)) for a, b in zip(x0, x1, strict=True)],
            transform=ax.get_xaxis_transform(),  # the spans' height: the whole axes
            color=colour,
            alpha=0.15,
            lw=0,
            label=SERIES_LABELS[series.j] + " windows" if first else None,
        )
        ax.add_collection(spans, autolim=False)  # the bars below span the same times
        ax.hlines([o.value_deg for o in windows], x0, x1, color=colour, lw=1.6)
    if series.settle_done_ms is not None:
        x = _minutes(series.settle_done_ms, t0)
        ax.axvline(x, color=colour, ls="--", lw=0.8)
        if series.settle_estimate_deg is not None:
            ax.plot(
                [x],
                [series.settle_estimate_deg],
                marker="v",
                color=colour,
                ms=6,
                ls="none",
                label=f"settled, j = {series.j}" if legend else None,
            )


def _windowed(series: SeriesRecord) -> list[ObservationRecord]:
    """Series j's observations that carry their window's times."""
    return [
        o
        for o in series.observations
        if o.window_start_ms is not None and o.window_end_ms is not None
    ]


def _zoom_on_windows(ax: Axes, record: TrialRecord, series: SeriesRecord, t0: float) -> None:
    """Series j's observation windows on a time axis of their own (they are a minute each in a
    trial of hours: slivers on the trial's axis): the heading bins inside the zoom, each window
    shaded with its k and its mean as a bar, the settle point when it falls inside."""
    windows = _windowed(series)
    first, last = windows[0].window_start_ms, windows[-1].window_end_ms
    assert first is not None and last is not None  # _windowed keeps timed windows only
    margin = 0.08 * (last - first)
    low, high = _minutes(first - margin, t0), _minutes(last + margin, t0)
    trace = record.trace
    if trace is not None and trace.t_ms.size:
        x = _minutes(trace.t_ms, t0)
        inside = (x >= low) & (x <= high)
        ax.fill_between(x[inside], trace.min_deg[inside], trace.max_deg[inside], color="0.75", lw=0)
        ax.plot(x[inside], trace.mean_deg[inside], color="0.2", lw=0.7)
    _mark_series(ax, series, t0, set(), legend=False)
    ax.set_xlim(low, high)
    top = ax.get_xaxis_transform()  # x in data, y in axes fraction
    for o in windows:  # k alone, inside its window: clear of the settle line before window 1
        middle = _minutes((o.window_start_ms + o.window_end_ms) / 2, t0)
        ax.text(
            middle,
            0.97,
            str(o.k),
            transform=top,
            ha="center",
            va="top",
            fontsize=6.5,
            color=SERIES_COLOURS[series.j],
        )
    ks = f"k = {windows[0].k}" + (f"\u2013{windows[-1].k}" if len(windows) > 1 else "")
    ax.set_title(f"{SERIES_LABELS[series.j]}: windows {ks}", loc="left", fontsize=8)
    ax.set_xlabel("stand time since the trial began, min")
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.margins(y=0.25)


HEADING_ZOOM_IN = 1.3  # the row of window zooms under the trial's heading, inches: two
# figures of 4.3 in to a page


_LAYOUTS: ContextVar[dict[int, Figure] | None] = ContextVar("_LAYOUTS", default=None)


@contextmanager
def reused_layouts() -> Iterator[None]:
    """Within it, the heading figures of one layout (so many zoom panels) are drawn on one
    matplotlib figure, its content replaced trial by trial: the axes and their ticks are made
    once, not per trial (a third of a heading figure's time). Per thread and task: a
    context variable."""
    token = _LAYOUTS.set({})
    try:
        yield
    finally:
        _LAYOUTS.reset(token)


def _heading_figure(zooms: int) -> Figure:
    """The heading figure's layout: the trial's axes on top and `zooms` panels under it (none:
    one axes), empty; from `reused_layouts` when one was drawn before."""
    pool = _LAYOUTS.get()
    if pool is not None and zooms in pool:
        fig = pool[zooms]
        for ax in fig.axes:
            for artist in (*ax.lines, *ax.collections, *ax.patches, *ax.texts):
                artist.remove()
            ax.relim()  # the data limits of what is left: nothing
            ax.set_autoscale_on(True)
        for legend in list(fig.legends):
            legend.remove()
        return fig
    fig = _figure(3.0 + (HEADING_ZOOM_IN if zooms else 0.0), axes=not zooms)
    if zooms:  # the trial on top, the zooms below: a grid in the same margins
        grid = fig.add_gridspec(2, zooms, height_ratios=(1.5, 1.1), hspace=0.45, wspace=0.22)
        fig.add_subplot(grid[0, :])
        for column in range(zooms):
            fig.add_subplot(grid[1, column])
        for ax in fig.axes:
            _xlabel_fixed(ax)
    if pool is not None:
        pool[zooms] = fig
    return fig


@_styled
def heading_plot(record: TrialRecord, title: str) -> Figure:
    """Heading of one trial against stand time, windows and settle points marked; under it, one
    panel per series zoomed on its observation windows."""
    t0 = _trial_start_ms(record)
    zoomed = [s for s in record.series if _windowed(s)] if t0 is not None else []
    fig = _heading_figure(len(zoomed))
    ax, *zooms = fig.axes
    ax.set_title(title, loc="left")
    if t0 is None:  # observations without window times: values against k
        for s in record.series:
            k = [o.k for o in s.observations]
            values = [o.value_deg for o in s.observations]
            ax.plot(k, values, "o-", color=SERIES_COLOURS[s.j], label=SERIES_LABELS[s.j])
        ax.set_xlabel("observation k")
    else:
        trace = record.trace
        if trace is not None and trace.t_ms.size:
            x = _minutes(trace.t_ms, t0)
            ax.fill_between(
                x, trace.min_deg, trace.max_deg, color="0.75", lw=0, label="heading min-max"
            )
            ax.plot(x, trace.mean_deg, color="0.2", lw=0.7, label="heading (bin mean)")
        labelled: set[int] = set()
        for s in record.series:
            _mark_series(ax, s, t0, labelled)
        ax.set_xlabel("stand time since the trial began, min")
    ax.set_ylabel("heading, deg")
    ax.ticklabel_format(axis="y", useOffset=False)
    for column, (zoom, s) in enumerate(zip(zooms, zoomed, strict=True)):
        assert t0 is not None  # zoomed: the windows carry times
        _zoom_on_windows(zoom, record, s, t0)
        if column == 0:
            zoom.set_ylabel("heading, deg")
    _legend_below(fig, ncols=3, fontsize=6.5)
    return fig


@_styled
def measured_vs_model(rows: Sequence[TrialRow]) -> Figure:
    """Observed <delta_i> against the model's alpha_i (fitted or predicted)."""
    fig = _figure(3.2, 4.6)
    ax = fig.axes[0]
    for role, marker, colour in (("fit", "o", "#1f77b4"), ("control", "s", "#d95f02")):
        chosen = [r for r in rows if r.role == role]
        if not chosen:
            continue
        err = [0.0 if r.var_mean_deg2 is None else np.sqrt(r.var_mean_deg2) for r in chosen]
        ax.errorbar(
            [r.alpha_deg for r in chosen],
            [r.delta_deg for r in chosen],
            yerr=err,
            fmt=marker,
            color=colour,
            capsize=2,
            label=f"{role} trials",
        )
        for r in chosen:
            ax.annotate(
                str(r.index),
                (r.alpha_deg, r.delta_deg),
                xytext=(4, 3) if r.index % 2 else (-9, -9),  # close points' labels apart
                textcoords="offset points",
                fontsize=7,
            )
    values = [v for r in rows for v in (r.alpha_deg, r.delta_deg)]
    lo, hi = min(values), max(values)
    pad = 0.08 * (hi - lo or 1.0)
    ax.plot(
        [lo - pad, hi + pad], [lo - pad, hi + pad], color="0.4", lw=0.8, label="measured = model"
    )
    ax.set_xlabel("model αᵢ, deg (eq 1.1)")
    ax.set_ylabel("measured ⟨δᵢ⟩, deg (eq 2.1)")
    ax.set_title("Measured against model (bars: ± S of ⟨δᵢ⟩)", loc="left")
    ax.legend(loc="upper left")
    return fig


@_styled
def residuals_plot(rows: Sequence[TrialRow], s_e_deg: float, bound_deg: float | None) -> Figure:
    """v_i per trial with +/- S_e and, when controls were judged, +/- t S_e."""
    fig = _figure(2.6, 4.6)
    ax = fig.axes[0]
    for role, marker, colour in (("fit", "o", "#1f77b4"), ("control", "s", "#d95f02")):
        chosen = [r for r in rows if r.role == role]
        if chosen:
            x, v = [r.index for r in chosen], [r.residual_deg for r in chosen]
            ax.vlines(x, 0, v, color=colour, lw=1.2)
            ax.plot(x, v, marker, color=colour, label=f"{role} trials")
    ax.axhline(0, color="0.3", lw=0.8)
    if bound_deg is not None:
        ax.axhspan(-bound_deg, bound_deg, color="#2ca02c", alpha=0.12, lw=0, label="± t Sₑ")
    for sign in (-1, 1):
        ax.axhline(
            sign * s_e_deg,
            color="#2ca02c",
            ls="--",
            lw=0.8,
            label="± Sₑ" if sign > 0 else None,
        )
    ax.set_xticks([r.index for r in rows])
    ax.set_xlabel("trial i")
    ax.set_ylabel("vᵢ = ⟨δᵢ⟩ − αᵢ, deg")
    ax.set_title("Residuals", loc="left")
    ax.legend(loc="best", ncols=2)
    return fig


@_styled
def forecast_plot(section: ForecastSection, limit_deg: float | None) -> Figure:
    """alpha_p against course at the plan's conditions with its band; other periods as lines."""
    grid = section.grid
    ship = section.point.conditions
    fig = _figure(3.0, right_in=1.75)
    ax = fig.axes[0]
    for p, period in enumerate(grid.period_s):
        alpha = grid.alpha_deg[:, 0, p, 0]
        if period == ship.period_s:
            half = grid.half_width_deg[:, 0, p, 0]
            ax.fill_between(
                grid.course_deg,
                alpha - half,
                alpha + half,
                color="#1f77b4",
                alpha=0.2,
                lw=0,
                label=f"{1 - grid.q:.0%} prediction interval",
            )
            ax.plot(
                grid.course_deg,
                alpha,
                color="#1f77b4",
                lw=1.8,
                label=f"αₚ, τ = {period:g} s (plan)",
            )
        else:
            ax.plot(grid.course_deg, alpha, lw=0.8, ls=":", label=f"τ = {period:g} s")
    if limit_deg is not None:
        for sign in (-1, 1):
            ax.axhline(
                sign * limit_deg,
                color="#d62728",
                lw=1.0,
                ls="--",
                label="limit" if sign > 0 else None,
            )
    ax.set_xticks(np.arange(0, 361, 45))
    ax.set_xlim(0, 360)
    ax.set_xlabel("ship's course, deg")
    ax.set_ylabel("predicted rolling error, deg")
    ax.set_title(
        f"Forecast: {ship.motion} {ship.roll_deg:g} deg, latitude {ship.latitude_deg:g} deg",
        loc="left",
    )
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


@_styled
def iteration_path_plot(analysis: CampaignAnalysis) -> Figure:
    """Gauss-Newton iterates theta_d (eq 1.7) over contours of S^2(C, T) (eq 1.9)."""
    fit = analysis.fit
    path = np.array([[r.theta["C_gcm2s2"], r.theta["T_s"]] for r in fit.log])
    final = np.array([fit.estimates["C_gcm2s2"], fit.estimates["T_s"]])
    se = np.array([fit.std_errors["C_gcm2s2"], fit.std_errors["T_s"]])
    points = np.vstack([path, final]) if path.size else final[None, :]
    lo = np.minimum(points.min(axis=0), final - 4 * se)
    hi = np.maximum(points.max(axis=0), final + 4 * se)
    span = hi - lo
    lo, hi = np.maximum(lo - 0.1 * span, 1e-9 * np.abs(final)), hi + 0.1 * span
    c_axis, t_axis = np.linspace(lo[0], hi[0], 160), np.linspace(lo[1], hi[1], 160)
    fitted = {i: t for i, t in ((t.index, t) for t in analysis.trials)}
    trials = [fitted[i] for i in analysis.fit_indices]
    x = Conditions(
        direction_deg=np.array([t.direction_deg for t in trials])[:, None, None],
        amplitude_cm=np.array([t.amplitude_cm for t in trials])[:, None, None],
        period_s=np.array([t.period_s for t in trials])[:, None, None],
    )
    y = np.array([t.delta_deg for t in trials])[:, None, None]
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import FuncFormatter

    model = RollingErrorModel(analysis.constants)
    alpha = model(x, c_axis[None, None, :], t_axis[None, :, None])
    r = y - alpha
    if analysis.trial_covariance is None:
        s2 = (r**2).sum(axis=0) / fit.dof  # eq 1.9 on the grid
    else:  # eq 1.9 generalised as the fit was (`analysis.gls`): r^T (V/v)^-1 r / (n - m)
        v = analysis.trial_covariance
        weight = np.linalg.inv(v / np.mean(np.diag(v)))
        s2 = np.einsum("i...,ij,j...->...", r, weight, r) / fit.dof
    fig = _figure(3.4, 5.2)
    ax = fig.axes[0]
    levels = np.geomspace(fit.s2 * 1.05, s2.max(), 12)
    contours = ax.contour(
        c_axis, t_axis, s2, levels=levels, cmap="viridis", norm=LogNorm(), linewidths=0.7
    )
    ax.clabel(contours, fmt=_two_digits, fontsize=6)
    if path.size:
        ax.plot(
            path[:, 0],
            path[:, 1],
            "o-",
            color="#d62728",
            ms=3.5,
            lw=1.0,
            label=f"iterates d = 0..{len(path) - 1} ({fit.path})",
        )
        ax.annotate("start", path[0], xytext=(5, 4), textcoords="offset points", fontsize=7)
    ax.plot(*final, marker="*", color="black", ms=10, ls="none", label="estimate")
    ax.set_xlabel("C, 10⁷ g cm² s⁻²")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 1e7:g}"))
    ax.set_ylabel("T, s")
    ax.set_title("Fit: iteration path over S²(C, T), deg² (eq 1.9)", loc="left")
    ax.legend(loc="best")
    return fig


MATHTEXT = re.compile(r"^\$\\mathdefault\{(.*)\}\$$")
SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _two_digits(value: float) -> str:
    """Two significant digits, a power of ten as ×10ⁿ (4×10⁻⁵, not the computer's 4e-05)."""
    text = f"{value:.2g}"
    if "e" not in text:
        return text
    mantissa, exponent = text.split("e")
    return f"{mantissa}×10{str(int(exponent)).translate(SUPERSCRIPT)}"


@functools.cache
def _plain_log_formatter() -> Any:
    """matplotlib's log-axis tick labels (10ⁿ, 2×10ⁿ) as plain text instead of mathtext: the
    same labels, without setting up matplotlib's mathtext parser in every fresh process (about
    0.3 s of CPU, a fifth of the figures' time)."""
    from matplotlib.ticker import LogFormatterSciNotation

    class PlainLogFormatter(LogFormatterSciNotation):
        def __call__(self, x: float, pos: int | None = None) -> str:
            label = super().__call__(x, pos)
            found = MATHTEXT.match(label)
            if found is None:  # "": a tick left unlabelled
                return label
            text = found[1].replace("\\times", "×")
            text = re.sub(r"\^\{(-?\d+)\}", lambda m: m[1].translate(SUPERSCRIPT), text)
            return text.replace("-", "−")

    return PlainLogFormatter


def _log_axes(ax: Axes) -> None:
    """Both axes logarithmic, labelled as matplotlib's log scale does (`_plain_log_formatter`)."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    plain = _plain_log_formatter()
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(plain())
        axis.set_minor_formatter(plain(labelOnlyBase=False))


HALF_IN = 3.45  # two figures side by side
K_UNIT = 1e-4  # correlation plotted in 10^-4 deg^2


@_styled
def correlation_plot(noise: NoiseCharacterisation) -> Figure:
    """K^(tau) (seed 004 eq 8.92) against the fitted exponential and smooth models (8.89), each
    plus the cosines a^2/2 cos(nu tau) of the harmonics found (8.91), with tau_k marked."""
    est, exp_model, smooth = noise.correlation, noise.exponential, noise.smooth
    tau_k = exp_model.correlation_time_s
    keep = est.lag_s <= min(est.lag_s[-1], 10 * tau_k)
    tau = est.lag_s[keep]
    periodic = sum(
        (h.amplitude_from_correlation**2 / 2 * np.cos(2 * np.pi * h.frequency_hz * tau))
        for h in noise.harmonics.harmonics
        if np.isfinite(h.amplitude_from_correlation)
    )
    fig = _figure(2.7, HALF_IN)
    ax = fig.axes[0]
    ax.plot(tau, est.covariance[keep] / K_UNIT, color="0.25", lw=0.9, label="estimate (eq 8.92)")
    ax.plot(
        tau,
        (exp_model(tau) + periodic) / K_UNIT,
        color="#1f77b4",
        lw=1.2,
        label=f"σ² exp(−μu), μ = {exp_model.decay_per_s:.3g} s⁻¹",
    )
    ax.plot(
        tau, (smooth(tau) + periodic) / K_UNIT, color="#d95f02", lw=1.0, ls="--", label="smooth"
    )
    ax.axvline(tau_k, color="0.5", lw=0.8, ls=":", label=f"uₖ = {tau_k:.3g} s")
    ax.axhline(0, color="0.3", lw=0.6)
    ax.set_xlabel("lag u, s")
    ax.set_ylabel("R(u), 10⁻⁴ deg²")
    ax.set_title("Correlation function (eqs 8.92, 8.89)", loc="left")
    ax.legend(loc="upper right")
    return fig


@_styled
def spectrum_plot(noise: NoiseCharacterisation) -> Figure:
    """Welch spectral density with its running-median background, the detection threshold for
    the false-alarm level, and the harmonics found (seed 004 eqs 8.90-8.91)."""
    search = noise.harmonics
    f = search.frequency_hz[1:]
    fig = _figure(2.7, HALF_IN)
    ax = fig.axes[0]
    _log_axes(ax)
    ax.plot(f, search.psd[1:], color="0.25", lw=0.7, label="Welch")
    ax.plot(f, search.background[1:], color="#1f77b4", lw=0.9, label="background")
    ax.plot(
        f,
        search.threshold[1:],
        color="#d62728",
        lw=0.8,
        ls="--",
        label=f"threshold, false alarm {search.false_alarm:g}",
    )
    for h in search.harmonics:
        i = int(np.argmin(np.abs(search.frequency_hz - h.frequency_hz)))
        ax.plot(
            [search.frequency_hz[i]],
            [search.psd[i] * 1.8],
            marker="v",
            color="#d62728",
            ls="none",
        )
        ax.annotate(
            f"{h.frequency_hz:.4g} Hz, {h.amplitude:.2g} deg",
            (search.frequency_hz[i], search.psd[i] * 1.8),
            xytext=(6, -2),
            textcoords="offset points",
            ha="left",
            va="center",
            fontsize=6.5,
        )
    ax.set_xlabel("frequency, Hz")
    ax.set_ylabel("spectral density, deg²/Hz")
    ax.set_title("Spectrum and hidden harmonics", loc="left")
    _legend_below(fig, ncols=3, fontsize=6)
    return fig


@_styled
def allan_plot(noise: NoiseCharacterisation) -> Figure:
    """Overlapping Allan deviation of the reading against the averaging time."""
    allan = noise.allan
    fig = _figure(2.5, HALF_IN)
    ax = fig.axes[0]
    _log_axes(ax)
    ax.plot(allan.tau_s, allan.deviation, "o-", color="#1f77b4", ms=3, lw=1.0)
    ax.set_xlabel("averaging time tₐ, s")
    ax.set_ylabel("Allan deviation σ_A(tₐ), deg")
    ax.set_title("Allan deviation", loc="left")
    ax.grid(True, which="both", alpha=0.3)
    return fig
