"""The report's figures from the per-user cache (`report.figure_cache`): a figure drawn again
from the same arguments comes from it, identical and without matplotlib; any other argument,
a damaged entry or caching off draws it (a report made again in a fresh process:
test_figure_cache_cli.py). And the log axes' labels as plain text."""

from pathlib import Path

import pytest
from matplotlib.backends.backend_svg import FigureCanvasSVG
from matplotlib.ticker import LogFormatterSciNotation

from gyrostand.report import figure_cache, plots
from gyrostand.report.build import Report


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[int]:
    """Caching into tmp_path/figures; the list grows by one per figure matplotlib draws."""
    monkeypatch.setenv(figure_cache.ENV, str(tmp_path / "figures"))
    calls: list[int] = []
    print_svg = FigureCanvasSVG.print_svg

    def counted(self: FigureCanvasSVG, *args: object, **kwargs: object) -> None:
        calls.append(1)
        print_svg(self, *args, **kwargs)

    monkeypatch.setattr(FigureCanvasSVG, "print_svg", counted)
    return calls


def test_a_figure_drawn_again_comes_from_the_cache(
    paper_report: Report, drawn: list[int], tmp_path: Path
) -> None:
    s_e = paper_report.analysis.cochran.s_e
    first = plots.residuals_plot(paper_report.trials, s_e, None)
    assert drawn == [1] and first.startswith('<img src="data:image/svg+xml;base64,')
    assert plots.residuals_plot(paper_report.trials, s_e, None) == first
    assert drawn == [1]  # from the cache
    other = plots.residuals_plot(paper_report.trials, s_e * 1.01, None)
    assert drawn == [1, 1] and other != first  # another argument: drawn
    (entry,) = [p for p in (tmp_path / "figures").iterdir() if p.read_text() == first]
    entry.write_text(first[:1000])  # damaged: drawn again and stored whole
    assert plots.residuals_plot(paper_report.trials, s_e, None) == first
    assert drawn == [1, 1, 1] and entry.read_text() == first


def test_caching_off_draws_every_time(
    paper_report: Report, drawn: list[int], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv(figure_cache.ENV, "off")
    once = plots.measured_vs_model(paper_report.trials)
    assert plots.measured_vs_model(paper_report.trials) == once
    assert drawn == [1, 1] and not (tmp_path / "figures").exists()


def test_the_cache_keeps_its_newest_entries(
    paper_report: Report, drawn: list[int], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(figure_cache, "KEEP", 2)
    for scale in (1.0, 1.1, 1.2):
        plots.residuals_plot(paper_report.trials, scale, None)
    assert len(list((tmp_path / "figures").glob("*.html"))) == 2
    plots.residuals_plot(paper_report.trials, 1.2, None)  # the newest: kept
    assert len(drawn) == 3


@pytest.mark.parametrize(
    ("value", "label"),
    [(1e-3, "10⁻³"), (1.0, "10⁰"), (100.0, "10²"), (2e-3, "2×10⁻³"), (3e4, "3×10⁴")],
)
def test_log_labels_are_matplotlibs_as_plain_text(value: float, label: str) -> None:
    """The same ticks labelled as matplotlib's log scale labels them, minor ones included,
    without mathtext: before, each log axis set up matplotlib's mathtext parser."""
    plain = plots._plain_log_formatter()(labelOnlyBase=False)
    assert plain(value) == label
    assert LogFormatterSciNotation(labelOnlyBase=False)(value).startswith("$\\mathdefault{")
