"""`gyrostand plan check` and `gyrostand plan schema`: the shipped plans pass and match the
schema; a bad plan gets every problem with its path; unknown keys are refused in every table."""

import json
import re
import tomllib
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.plan.model import PlanError, parse_any_plan, parse_plan

ERROR = "gyrostand: error: "  # plan check's problems, one per line on stderr

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "examples" / "paper.toml"
SHIPPED = sorted(ROOT.glob("examples/*.toml")) + [ROOT / "gyrostand" / "plans" / "paper.toml"]
runner = CliRunner()


def gyrostand(*args: str | Path) -> tuple[int, str]:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result.exit_code, result.output


@pytest.mark.parametrize("plan", SHIPPED, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_shipped_plan_passes(plan: Path) -> None:
    code, out = gyrostand("plan", "check", plan)
    assert code == 0, out
    name = re.escape(str(plan))
    assert re.fullmatch(
        rf"{name}: ok — 6 trials \(4 fit, 2 control\), 2 residual degrees of freedom, N = 5, .*\n"
        rf"(?:{name}: procedure — .*\n)*"  # the standard's procedures (type-approval.toml)
        rf"{name}: warning — the fit of C and T leaves 2 residual degrees of freedom .* add fit "
        r"trials\n"
        rf"{name}: note — successive observations of the 28 s windows correlate rho = \+0\.09\d "
        r"at \[observation\] spacing_s = 30 .*: independent \(\|rho\| <= 0\.1\)\n",
        out,
    )


@pytest.mark.parametrize(
    ("spacing", "correlation_time", "said"),
    [
        # rho(28 s windows end to end) = 0.4389 (closed form in tests/analysis/test_effective.py),
        # ln(0.4389 / 0.1) / 0.05 = 29.58 s
        ("0.0", "20.0", "rho = +0.439 at [observation] spacing_s = 0 "),
        ("0.0", "20.0", "set [observation] spacing_s = 30 (stand seconds between windows)"),
        ("29.0", "20.0", "rho = +0.103 at [observation] spacing_s = 29 "),  # 0.4389 e^(-1.45)
        ("0.0", "2.0", "rho = +0.038 at [observation] spacing_s = 0 "),  # ~ 1 / (2 (14 - 1))
        ("0.0", None, "independence of successive observations not checked: state"),
    ],
)
def test_spacing_is_checked_against_the_correlation_time(
    tmp_path: Path, spacing: str, correlation_time: str | None, said: str
) -> None:
    """The spacing that makes successive observations independent (Sveshnikov eqs 8.92-8.94)."""
    text = re.sub(r"(?m)^spacing_s = .*$", f"spacing_s = {spacing}", PAPER.read_text())
    if correlation_time is None:
        text = re.sub(r"(?m)^correlation_time_s = .*\n", "", text)
    else:
        text = re.sub(
            r"(?m)^correlation_time_s = .*$", f"correlation_time_s = {correlation_time}", text
        )
    plan = tmp_path / "plan.toml"
    plan.write_text(text)
    code, out = gyrostand("plan", "check", plan)
    assert code == 0, out
    assert said in out.replace("\n", " ")
    warned = spacing == "0.0" and correlation_time == "20.0" or spacing == "29.0"
    assert ("warning — successive observations" in out) == warned


@pytest.mark.parametrize(("fit", "warned"), [(3, True), (5, False)])
def test_residual_degrees_of_freedom_are_stated_and_few_warned(
    tmp_path: Path, fit: int, warned: bool
) -> None:
    """n - m = fit trials - 2: stated in the summary, a warning at 2 or fewer."""
    text = PAPER.read_text()
    if fit == 3:  # the last fit trial becomes a control
        text = _replace_nth(text, 'role = "fit"', 'role = "control"', 4)
    else:  # a fifth fit trial: the first control becomes one
        text = text.replace('role = "control"', 'role = "fit"', 1)
    plan = tmp_path / "plan.toml"
    plan.write_text(text)
    code, out = gyrostand("plan", "check", plan)
    dof = fit - 2
    assert code == 0, out
    assert f"({fit} fit, {6 - fit} control), {dof} residual degree" in out.splitlines()[0]
    assert ("warning — " in out) == warned
    if warned:
        assert f"leaves {dof} residual degree of freedom " in out and f"t({dof})" in out


def _replace_nth(text: str, old: str, new: str, n: int) -> str:
    """text with the n-th occurrence (1-based) of old replaced by new."""
    parts = text.split(old)
    return old.join(parts[:n]) + new + old.join(parts[n:])


def test_bad_plan_lists_every_problem_with_its_path(tmp_path: Path) -> None:
    text = PAPER.read_text().replace("n_obs = 5", "n_obs = 1")
    text = text.replace("period_s = 3.5", "period_s = 0", 1).replace(
        "hold_s = 1800.0", "hold_s = -1"
    )
    text = text.replace("[tracking]", "[tracking]\nconfirm = 1")
    plan = tmp_path / "plan.toml"
    plan.write_text(text)
    code, out = gyrostand("plan", "check", plan)
    assert code == 1 and "Traceback" not in out
    assert out.splitlines() == [
        f"{ERROR}{plan}: [campaign] n_obs: must be >= 2",
        f"{ERROR}{plan}: [[trials]] 4 period_s: must be > 0",
        f"{ERROR}{plan}: [settle] hold_s: must be >= 0",
        f"{ERROR}{plan}: [tracking] confirm: unknown key",
    ]


def test_unreadable_file_and_syntax_error_are_one_line(tmp_path: Path) -> None:
    missing = tmp_path / "missing.toml"
    code, out = gyrostand("plan", "check", missing)
    assert (code, out) == (
        1,
        f"{ERROR}{missing}: cannot read the file (No such file or directory)\n",
    )
    broken = tmp_path / "broken.toml"
    broken.write_text("[campaign\n")
    code, out = gyrostand("plan", "check", broken)
    assert code == 1 and out.count("\n") == 1 and out.startswith(f"{ERROR}{broken}: TOML syntax: ")


def test_check_also_prepares_the_run(tmp_path: Path) -> None:
    """What `campaign run` checks beyond the file (here the DBC signals) is checked too."""
    plan = tmp_path / "plan.toml"
    plan.write_text(PAPER.read_text() + '\n[signals]\nheading = "NOPE.HEADING"\n')
    code, out = gyrostand("plan", "check", plan)
    assert code == 1 and "NOPE" in out and out.count("\n") == 1


# ---------------------------------------------------------------------- unknown keys


TABLES = [
    "campaign",
    "instrument",
    "site",
    "analysis",
    "forecast",
    "observation",
    "settle",
    "tracking",
    "timeouts",
    "bus",
]


@pytest.mark.parametrize("table", TABLES)
def test_unknown_key_is_refused_in_every_table(table: str) -> None:
    text = PAPER.read_text().replace(f"[{table}]", f"[{table}]\nbogus = 1", 1)
    with pytest.raises(PlanError) as caught:
        parse_plan(text)
    assert caught.value.problems == [f"[{table}] bogus: unknown key"]


@pytest.mark.parametrize(
    ("extra", "problem"),
    [
        ("bogus = 1\n", "[[trials]] 6 bogus: unknown key"),  # after the last [[trials]]
        ("[checks]\nbogus = 1\n", "[checks] bogus: unknown key"),
        ("[protocol]\nbogus = 1\n", "[protocol] bogus: unknown key"),
        ('[signals]\nbogus = "A.B"\n', "[signals] bogus: unknown key"),
        (
            "[acceptance]\ntolerance_deg = 0.1\nduration_s = 60.0\nmax_risk = 0.1\nbogus = 1\n",
            "[acceptance] bogus: unknown key",
        ),
        ("[bogus]\nx = 1\n", "bogus: unknown key"),
    ],
)
def test_unknown_key_is_refused_in_the_optional_tables(extra: str, problem: str) -> None:
    with pytest.raises(PlanError) as caught:
        parse_plan(PAPER.read_text() + "\n" + extra)
    assert caught.value.problems == [problem]


def test_partial_form_refuses_unknown_keys_too() -> None:
    text = tomllib.loads(PAPER.read_text())
    partial = "".join(
        f"[{name}]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in text[name].items())
        for name in ("instrument", "site", "analysis", "forecast")
    )
    assert parse_any_plan(partial).analysis is not None
    with pytest.raises(PlanError) as caught:
        parse_any_plan(partial + '[campaign]\noperator = "x"\nn_obs = 5\n[observation]\n')
    assert caught.value.problems == ["[campaign] n_obs: unknown key", "observation: unknown key"]


# ---------------------------------------------------------------------------- schema


def schema_errors(
    schema: dict[str, Any], value: Any, root: dict[str, Any], at: str = ""
) -> list[str]:
    """The subset of JSON Schema (2020-12) that pydantic emits for the plan, checked by hand
    (the jsonschema package is not a dependency)."""
    if "$ref" in schema:
        return schema_errors(root["$defs"][schema["$ref"].split("/")[-1]], value, root, at)
    if "anyOf" in schema:
        options = [schema_errors(s, value, root, at) for s in schema["anyOf"]]
        return [] if any(not o for o in options) else [f"{at}: matches no option"]
    types = {
        "object": dict,
        "array": list,
        "string": str,
        "boolean": bool,
        "null": type(None),
        "integer": int,
        "number": (int, float),
    }
    kind = schema.get("type")
    if kind and (
        not isinstance(value, types[kind])
        or (kind in ("integer", "number") and isinstance(value, bool))
    ):
        return [f"{at}: not {kind}"]
    errors = []
    if (
        "enum" in schema
        and value not in schema["enum"]
        or "const" in schema
        and value != schema["const"]
    ):
        errors.append(f"{at}: {value!r} not allowed")
    for key, ok in (
        ("minimum", lambda b: value >= b),
        ("maximum", lambda b: value <= b),
        ("exclusiveMinimum", lambda b: value > b),
        ("exclusiveMaximum", lambda b: value < b),
        ("minItems", lambda b: len(value) >= b),
        ("maxItems", lambda b: len(value) <= b),
        ("pattern", lambda b: re.search(b, value)),
    ):
        if key in schema and not ok(schema[key]):
            errors.append(f"{at}: violates {key}")
    if kind == "object":
        properties = schema.get("properties", {})
        errors += [f"{at}.{k}: required" for k in schema.get("required", []) if k not in value]
        for k, v in value.items():
            if k in properties:
                errors += schema_errors(properties[k], v, root, f"{at}.{k}")
            elif schema.get("additionalProperties") is False:
                errors.append(f"{at}.{k}: not allowed")
            elif isinstance(schema.get("additionalProperties"), dict):
                errors += schema_errors(schema["additionalProperties"], v, root, f"{at}.{k}")
    if kind == "array":
        prefix = schema.get("prefixItems", [])
        for i, item in enumerate(value):
            sub = prefix[i] if i < len(prefix) else schema.get("items", {})
            errors += schema_errors(sub, item, root, f"{at}[{i}]")
    return errors


@pytest.fixture(scope="module")
def schema(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("schema") / "plan.schema.json"
    code, printed = gyrostand("plan", "schema", "--out", out)
    assert (code, printed) == (0, f"wrote {out}\n")
    code, stdout = gyrostand("plan", "schema")
    assert code == 0 and json.loads(stdout) == json.loads(out.read_text())
    return json.loads(out.read_text())


@pytest.mark.parametrize("plan", SHIPPED, ids=lambda p: str(p.relative_to(ROOT)))
def test_schema_validates_the_shipped_plans(schema: dict[str, Any], plan: Path) -> None:
    assert schema_errors(schema, tomllib.loads(plan.read_text()), schema) == []


def test_schema_refuses_what_the_model_refuses(schema: dict[str, Any]) -> None:
    document = tomllib.loads(PAPER.read_text())
    document["settle"]["bnad"] = 1
    document["trials"][3]["period_s"] = -3.5
    document["bus"]["timing"] = "fast"
    del document["campaign"]["n_obs"]
    assert sorted(schema_errors(schema, document, schema)) == [
        ".bus.timing: 'fast' not allowed",
        ".campaign.n_obs: required",
        ".settle.bnad: not allowed",
        ".trials[3].period_s: violates exclusiveMinimum",
    ]


def test_schema_describes_every_field(schema: dict[str, Any]) -> None:
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    site = schema["$defs"]["SitePlan"]["properties"]
    assert site["earth_rate_rad_s"]["default"] == 7.292115e-5
    assert "Earth rotation rate" in site["earth_rate_rad_s"]["description"]
    for name, table in schema["$defs"].items():
        for key, field in table.get("properties", {}).items():
            if "$ref" not in field:  # a subtable: its own definition is described
                assert field.get("description"), f"{name}.{key} has no description"


@pytest.mark.parametrize(
    ("bus", "said"),
    [
        ('timing = "virtual"', "simulated stand in virtual time,"),
        ('timing = "realtime"\nspeedup = 50.0', "real time (paced by the wall clock),"),
    ],
)
def test_the_summary_names_the_simulated_stand_s_pace(tmp_path: Path, bus: str, said: str) -> None:
    plan = tmp_path / "plan.toml"
    plan.write_text(PAPER.read_text().replace('timing = "virtual"', bus, 1))
    code, out = gyrostand("plan", "check", plan)
    assert code == 0 and said in out and "realtime time" not in out, out


def test_the_compass_knobs_have_one_spelling_the_old_one_read_with_a_note(tmp_path: Path) -> None:
    """c_gcm2s2, t_s, lp_gcm2s2 as [instrument] and the CLI's --c-gcm2s2 spell them; before,
    [bus.simulator.compass] refused them (only C_gcm2s2, T_s, lP_gcm2s2 were known)."""
    for spelling, notes in (("c_gcm2s2", False), ("C_gcm2s2", True)):
        plan = tmp_path / f"{spelling}.toml"
        t = "T_s" if notes else "t_s"
        compass = f"\n[bus.simulator.compass]\n{spelling} = 5.0e7\n{t} = 0.9\n"
        plan.write_text(PAPER.read_text().replace("\n[[trials]]", compass + "\n[[trials]]", 1))
        code, out = gyrostand("plan", "check", plan)
        assert code == 0, out
        simulator = parse_plan(plan.read_text()).bus.simulator
        assert (simulator.compass.c_gcm2s2, simulator.compass.t_s) == (5.0e7, 0.9)
        lines = [line for line in out.splitlines() if " is spelled " in line]
        assert lines == (
            [
                f"{plan}: note — [bus.simulator.compass] {old} is spelled {new} now (the old "
                "spelling is still read)"
                for old, new in (("C_gcm2s2", "c_gcm2s2"), ("T_s", "t_s"))
            ]
            if notes
            else []
        )
