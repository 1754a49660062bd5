"""The layering is one-way, and every internal import goes through the `gyrostand` namespace (the
folders stay at the top of the repository; pyproject maps them to `gyrostand.<folder>`):

- `analysis` (pure computation) and `db` (schema, persistence) import no internal package;
- `stand` (protocol, simulator) imports analysis's pure helpers only;
- `plan` (the one plan model) imports stand and analysis (the transient model); `frames` (raw
  log, vectorised decoder) imports stand;
- `devices` (heading source adapters: a compass's native stream -> the engine's frames) imports
  stand, frames and analysis;
- `acquisition` (the write side) imports stand, db, analysis, plan, frames, devices;
- `report` (the read side: stored campaign -> analysis -> report/export) imports db, analysis,
  plan, frames, stand, devices and never acquisition;
- `station` (the operator station, a web page) reads db and checks plans with plan; it starts
  the acquisition and the report as `gyrostand` processes, never importing acquisition or report;
- the CLI modules in `gyrostand/` import everything. The package root (`from gyrostand import
  SOFTWARE_VERSION`) is importable from every layer.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CLI = "gyrostand"
ALLOWED = {
    "analysis": set(),
    "db": set(),
    "stand": {"analysis"},
    "plan": {"stand", "analysis"},
    "frames": {"stand"},
    "devices": {"stand", "frames", "analysis"},
    "acquisition": {"stand", "db", "analysis", "plan", "frames", "devices"},
    "report": {"db", "analysis", "plan", "frames", "stand", "devices"},
    "station": {"db", "plan"},
    CLI: {
        "acquisition",
        "analysis",
        "stand",
        "db",
        "plan",
        "frames",
        "devices",
        "report",
        "station",
    },
}
LAYERS = set(ALLOWED) - {CLI}


def imported_layers(source: str) -> set[str]:
    """The layers a module imports (absolute imports); a bare `from analysis import ...` (outside
    the namespace) is reported as "bare analysis"."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules = [(alias.name, ()) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules = [(node.module, tuple(alias.name for alias in node.names))]
        else:
            continue
        for module, names in modules:
            parts = module.split(".")
            if parts[0] in LAYERS:
                found.add(f"bare {parts[0]}")
            elif parts[0] == "gyrostand" and len(parts) > 1:
                found.add(parts[1] if parts[1] in LAYERS else CLI)
            elif parts[0] == "gyrostand":  # from gyrostand import X: a layer, CLI module or root
                found.update(n if n in LAYERS else CLI for n in names if n != "SOFTWARE_VERSION")
    return found


def violations(package: str, root: Path = ROOT) -> list[str]:
    bad = []
    for path in sorted((root / package).rglob("*.py")):
        for imported in sorted(imported_layers(path.read_text()) - ALLOWED[package] - {package}):
            bad.append(f"{path.relative_to(root)} imports {imported}")
    return bad


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_respects_layering(package: str) -> None:
    assert (ROOT / package / "__init__.py").exists()
    assert violations(package) == []


def test_checker_catches_a_violation(tmp_path: Path) -> None:
    (tmp_path / "analysis").mkdir()
    (tmp_path / "analysis" / "bad.py").write_text(
        "import numpy\nfrom gyrostand.db.schema import Trial\nfrom stand import protocol\n"
    )
    (tmp_path / "analysis" / "ok.py").write_text(
        "from gyrostand.analysis import x\nfrom . import y\n"
        "from gyrostand import SOFTWARE_VERSION\n"
    )
    assert violations("analysis", tmp_path) == [
        "analysis/bad.py imports bare stand",
        "analysis/bad.py imports db",
    ]


def test_every_layer_is_installed_under_the_namespace() -> None:
    """pyproject maps each layer folder to `gyrostand.<folder>`: nothing generic is installed."""
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert project["package-dir"] == {"gyrostand": "gyrostand"} | {
        f"gyrostand.{layer}": layer for layer in LAYERS
    }
    assert all(p == "gyrostand" or p.startswith("gyrostand.") for p in project["packages"])


def test_analysis_is_pure_computation() -> None:
    """analysis/ renders nothing: no template, plotting or PDF library is imported there."""
    rendering = {"jinja2", "matplotlib", "weasyprint"}
    found = {
        f"{path.relative_to(ROOT)} imports {alias.name.split('.')[0]}"
        for path in sorted((ROOT / "analysis").rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Import | ast.ImportFrom)
        for alias in (
            node.names if isinstance(node, ast.Import) else [ast.alias(node.module or "")]
        )
        if alias.name.split(".")[0] in rendering
    }
    assert found == set()
