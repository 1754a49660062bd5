"""The fleet report's figures (`report.plots`'s style and inline SVG): the control chart of one
parameter over the fleet's units."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from gyrostand.analysis.fleet import ParameterAnalysis
from gyrostand.report.plots import _figure, _styled

if TYPE_CHECKING:  # matplotlib is imported where a figure is drawn: not for a cached one
    from matplotlib.figure import Figure

SCALE = {"C": (1e7, "C, 10⁷ g·cm²·s⁻²"), "T": (1.0, "T, s")}
"""How each parameter is plotted: the divisor and the axis label with the unit."""
OUTSIDE = "#d62728"


@_styled
def control_chart(p: ParameterAnalysis, order: Sequence[str], factor: str) -> Figure:
    """Each unit's estimate (± its SE, coloured by its group of `factor`) in `order` of serials,
    with the fleet mean and the type's prediction interval the unit was judged against; units
    outside it ringed."""
    scale, label = SCALE[p.symbol]
    units = {u.serial: u for u in p.units}
    chosen = [units[s] for s in order]
    colours = dict(zip((g.group for g in p.groups), _palette(len(p.groups)), strict=True))
    rotation = 90 if len(chosen) > 12 else 45
    fig = _figure(3.0, right_in=2.0, below_in=0.5 if rotation == 90 else 0.3)
    ax = fig.axes[0]
    x = range(len(chosen))
    ax.vlines(
        x,
        [(u.center - u.half_width) / scale for u in chosen],
        [(u.center + u.half_width) / scale for u in chosen],
        color="0.55",
        alpha=0.35,
        lw=7,
        label="prediction interval from the other units",
    )
    ax.axhline(p.anova.grand_mean / scale, color="0.3", lw=0.9, ls="--", label="fleet mean")
    for g in p.groups:
        at = [i for i, u in zip(x, chosen, strict=True) if u.group == g.group]
        ax.errorbar(
            at,
            [chosen[i].value / scale for i in at],
            yerr=[chosen[i].se / scale for i in at],
            fmt="o",
            ms=4,
            capsize=2,
            color=colours[g.group],
            label=f"{factor} {g.group}{' (differs)' if g.differs else ''}",
        )
    outside = [(i, u) for i, u in zip(x, chosen, strict=True) if u.outside]
    if outside:
        ax.plot(
            [i for i, _ in outside],
            [u.value / scale for _, u in outside],
            "o",
            ms=10,
            mfc="none",
            mec=OUTSIDE,
            mew=1.3,
            label="outside the interval",
        )
    ax.set_xticks(list(x), [u.serial for u in chosen], rotation=rotation)
    ax.tick_params(axis="x", labelsize=6.5)
    ax.set_xlim(-0.7, len(chosen) - 0.3)
    ax.set_xlabel("unit (serial), in the order of the campaigns' start")
    ax.set_ylabel(label)
    ax.set_title(f"{p.symbol} per unit (bars: ± SE of the unit's fit)", loc="left")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=6.5)
    return fig


def _palette(n: int) -> list[tuple[float, float, float, float]]:
    """n colours, distinct up to 20 (matplotlib's tab10, tab20 for more groups)."""
    from matplotlib import colormaps

    colours = colormaps["tab10" if n <= 10 else "tab20"]
    return [colours(i % colours.N) for i in range(n)]
