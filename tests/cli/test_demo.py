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
