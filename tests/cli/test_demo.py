"""The demo's embedded plan is the shipped paper campaign (examples/paper.toml links to it)."""

import json
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

    from ..acquisition.harness import FAST_SIM, plan_text
    from .test_fleet_commands import TRIALS

    plan = tmp_path / "plan.toml"
    text = plan_text(TRIALS, n_obs=4, database="runs/demo.sqlite", raw_dir="runs/raw")
    plan.write_text(text.replace("acquisition_only = true", "acquisition_only = false") + FAST_SIM)
    monkeypatch.setattr(cmd_demo, "DEMO_PLAN", plan)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["demo", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "campaign 1 completed: 4 trials completed, 0 failed, 32 observations" in result.output
    report = result.output.splitlines()[-1].removeprefix("report: ")
    assert (tmp_path / report).is_file() and (tmp_path / "runs" / "demo.sqlite").is_file()
    # it ends with the result, as the report's JSON states it
    written = json.loads((tmp_path / report).with_suffix(".json").read_text())
    assert written["analysis"] is not None, written["analysis_error"]
    fit = written["analysis"]["fit"]
    (c, t), (c_ci, t_ci) = (
        (fit["estimates"][k] for k in ("C_gcm2s2", "T_s")),
        (fit["confidence_intervals"][k] for k in ("C_gcm2s2", "T_s")),
    )
    yes = {True: "yes", False: "no", None: "not tested"}
    assert result.output.splitlines()[-7:-1] == [
        "result:",
        f"  C = {c / 1e7:.4f}e7 g·cm²·s⁻², 95 % confidence interval {c_ci[0] / 1e7:.4f}e7 to "
        f"{c_ci[1] / 1e7:.4f}e7",
        f"  T = {t:.4f} s, 95 % confidence interval {t_ci[0]:.4f} to {t_ci[1]:.4f}",
        f"  trial variances homogeneous (Cochran): "
        f"{yes[written['analysis']['cochran']['homogeneous']]}",
        f"  model adequate on the trial means (Fisher): "
        f"{yes[written['analysis']['adequacy']['adequate_mean_basis']]}",
        f"  report's decision: {written['conformity']['verdict']}",
    ]
