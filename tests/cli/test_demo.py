"""The demo's embedded plan is the shipped paper campaign (examples/paper.toml links to it)."""

from pathlib import Path

from gyrostand.cmd_demo import DEMO_PLAN
from gyrostand.plan.model import parse_plan

ROOT = Path(__file__).resolve().parents[2]


def test_demo_plan_is_the_paper_campaign() -> None:
    plan = parse_plan(DEMO_PLAN.read_text())
    assert (ROOT / "examples" / "paper.toml").read_text() == DEMO_PLAN.read_text()
    assert plan.bus.simulated
    assert [(t.direction_deg, t.amplitude_cm, t.period_s, t.role) for t in plan.trials] == [
        (332.0, 24.0, 8.0, "fit"),
        (18.0, 24.0, 6.3, "fit"),
        (316.0, 23.0, 5.5, "fit"),
        (346.0, 17.8, 3.5, "fit"),
        (31.0, 23.5, 6.2, "control"),
        (346.0, 17.8, 5.5, "control"),
    ]


def test_examples_are_plain_files_and_the_demo_plan_is_the_example() -> None:
    """examples/ can be copied anywhere (no symlinks); the packaged demo plan is that file."""
    from importlib.resources import files

    examples = Path(__file__).resolve().parents[2] / "examples"
    assert not [p.name for p in examples.iterdir() if p.is_symlink()]
    packaged = (files("gyrostand") / "plans" / "paper.toml").read_text()
    assert packaged == (examples / "paper.toml").read_text()


def test_the_demo_runs_the_whole_chain(tmp_path: Path, monkeypatch) -> None:
    """`gyrostand demo` on a small plan in its place: campaign, analysis, report files (the
    command once called the campaign runner with a stale signature and no test ran it)."""
    from typer.testing import CliRunner

    from gyrostand import cmd_demo
    from gyrostand.cli import app

    from ..acquisition.harness import plan_text

    plan = tmp_path / "plan.toml"
    plan.write_text(plan_text(n_obs=3, database="runs/demo.sqlite", raw_dir="runs/raw"))
    monkeypatch.setattr(cmd_demo, "DEMO_PLAN", plan)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["demo", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "campaign 1 completed: 2 trials completed, 0 failed, 12 observations" in result.output
    report = result.output.splitlines()[-1].removeprefix("report: ")
    assert (tmp_path / report).is_file() and (tmp_path / "runs" / "demo.sqlite").is_file()
