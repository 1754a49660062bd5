"""The layering is one-way: analysis and db import no internal package, stand imports no
acquisition, acquisition may import stand/db/analysis, only the CLI (gyrostand) imports all."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
INTERNAL = {"gyrostand", "acquisition", "analysis", "stand", "db"}
ALLOWED = {
    "analysis": set(),
    "db": set(),
    "stand": set(),
    "acquisition": {"stand", "db", "analysis"},
    "gyrostand": {"acquisition", "analysis", "stand", "db"},
}


def imported_packages(source: str) -> set[str]:
    """Top-level internal packages imported anywhere in a module (absolute imports)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        found.update(n.split(".")[0] for n in names if n.split(".")[0] in INTERNAL)
    return found


def violations(package: str, root: Path = ROOT) -> list[str]:
    bad = []
    for path in sorted((root / package).rglob("*.py")):
        for imported in imported_packages(path.read_text()) - ALLOWED[package] - {package}:
            bad.append(f"{path.relative_to(root)} imports {imported}")
    return bad


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_respects_layering(package: str) -> None:
    assert (ROOT / package / "__init__.py").exists()
    assert violations(package) == []


def test_checker_catches_a_violation(tmp_path: Path) -> None:
    (tmp_path / "analysis").mkdir()
    (tmp_path / "analysis" / "bad.py").write_text("import numpy\nfrom db.schema import Trial\n")
    (tmp_path / "analysis" / "ok.py").write_text("from analysis import x\nfrom . import y\n")
    assert violations("analysis", tmp_path) == ["analysis/bad.py imports db"]
