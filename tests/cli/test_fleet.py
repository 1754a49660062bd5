"""`gyrostand fleet analyze` on a simulated fleet (gyrostand/simulated_fleet.py): three factories
of one model, the units of factory C with a time constant T 0.3 s shorter; the analysis sets C
apart and no other factory, in text and JSON; and its one-line refusals."""

import json

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.plan.model import parse_plan
from gyrostand.simulated_fleet import FleetDesign, simulate_fleet
from tests.acquisition.harness import FAST_SIM, plan_text

TRIALS = [
    (332.0, 24.0, 8.0, "fit"),
    (18.0, 24.0, 6.3, "fit"),
    (316.0, 23.0, 5.5, "fit"),
    (346.0, 17.8, 3.5, "fit"),
]
DESIGN = FleetDesign(groups=("A", "B", "C"), units_per_group=2, shifted="C", t_shift_s=-0.3, seed=3)


@pytest.fixture(scope="module")
def fleet_db(tmp_path_factory: pytest.TempPathFactory) -> str:
    folder = tmp_path_factory.mktemp("fleet")
    db = f"sqlite:///{folder / 'lab.sqlite'}"
    text = plan_text(TRIALS, n_obs=10, database=db, raw_dir=str(folder / "raw")) + FAST_SIM
    plan = parse_plan(text.replace("acquisition_only = true", "acquisition_only = false"))
    simulate_fleet(plan, db, DESIGN)
    return db


def gyrostand(*args: str) -> str:
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result.stdout


def test_the_shifted_factory_is_found_and_no_other(fleet_db: str) -> None:
    args = ("fleet", "analyze", "--model", "test compass", "--by", "factory", "--db", fleet_db)
    document = json.loads(gyrostand(*args, "--json"))
    assert document["n_units"] == 6 and document["left_out"] == []
    c, t = document["parameters"]
    assert t["anova"]["groups_differ"]
    assert t["anova"]["f"] > t["anova"]["f_critical"]
    assert [g["group"] for g in t["groups"] if g["differs"]] == ["C"]
    text = gyrostand(*args)
    assert "Sveshnikov, section 8.2" in text
    assert "the groups differ" in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--model", "nope", "--by", "factory"), "no completed campaign of model 'nope'"),
        (
            ("--model", "test compass", "--by", "lot"),
            "model test compass: the fleet has 0 groups by lot: at least 2 are needed",
        ),
        (("--model", "test compass", "--by", "Lot!"), "--by 'Lot!' is no label key"),
    ],
)
def test_refusals_are_one_line(fleet_db: str, args: tuple[str, ...], message: str) -> None:
    result = CliRunner().invoke(app, ["fleet", "analyze", *args, "--db", fleet_db])
    assert result.exit_code == 2
    assert result.stderr.startswith("gyrostand: error: ") and message in result.stderr
    assert len(result.stderr.splitlines()) == 1
