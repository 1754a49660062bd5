"""What gyrostand's pytest plugin costs a pytest run that uses none of its fixtures: the wall
time of `pytest --collect-only` over 300 test files (1500 tests) with the plugin (installed,
entry point `pytest11`) and with `-p no:gyrostand`, alternately, and the modules the plugin
loads (none of numpy, scipy, python-can, cantools, SQLAlchemy, pydantic) and the time to import
it. On a loaded machine the medians scatter by tenths of a second either way; the minima and the
import time are the figures to compare."""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FILES = 300
ROUNDS = 15
TEST_FILE = "".join(f"def test_{i}():\n    assert {i} + 1 > {i}\n\n\n" for i in range(5))
HEAVY = ("numpy", "scipy", "can", "cantools", "sqlalchemy", "pydantic")


def collect_s(folder: Path, *options: str) -> float:
    start = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "--collect-only",
            "-q",
            "-p",
            "no:cacheprovider",
            *options,
        ],
        cwd=folder,
        check=True,
        capture_output=True,
    )
    return time.perf_counter() - start


def plugin_import() -> tuple[float, list[str]]:
    """Seconds to import the plugin once pytest is loaded, and the heavy modules it loads."""
    probe = (
        "import sys, time, pytest; t = time.perf_counter(); import gyrostand.pytest_plugin; "
        "print(time.perf_counter() - t); "
        f"print(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r}))"
    )
    out = subprocess.run([sys.executable, "-c", probe], check=True, capture_output=True, text=True)
    seconds, modules = out.stdout.splitlines()
    return float(seconds), eval(modules)  # a printed float and list of module names


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "pytest.ini").write_text("[pytest]\n")
        for i in range(FILES):
            (folder / f"test_m{i:03d}.py").write_text(TEST_FILE)
        collect_s(folder)  # warm the file system cache and the .pyc files
        with_plugin, without = [], []
        for i in range(ROUNDS):  # alternating, each first every other round
            pairs = [(with_plugin, ()), (without, ("-p", "no:gyrostand"))]
            for runs, options in pairs[:: -1 if i % 2 else 1]:
                runs.append(collect_s(folder, *options))
    a, b = statistics.median(with_plugin), statistics.median(without)
    print(f"collect {FILES} files / {FILES * 5} tests, median of {ROUNDS} alternating runs:")
    print(f"  with the plugin       {a:.3f} s  (min {min(with_plugin):.3f})")
    print(f"  -p no:gyrostand       {b:.3f} s  (min {min(without):.3f})")
    print(f"  difference            {a - b:+.3f} s")
    seconds, modules = min(plugin_import() for _ in range(5))
    print(f"  importing the plugin  {seconds * 1000:.1f} ms (best of 5), heavy modules: {modules}")


if __name__ == "__main__":
    main()
