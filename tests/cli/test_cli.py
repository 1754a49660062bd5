"""The CLI skeleton: version, help, and honest non-zero exits for what is not built."""

import subprocess
import sys

from typer.testing import CliRunner

from gyrostand import __version__
from gyrostand.cli import app

runner = CliRunner()


def test_module_version() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "gyrostand", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == f"gyrostand {__version__}"
    assert __version__ == "0.1.0"


def test_help_lists_command_groups() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for group in (
        "simulate",
        "campaign",
        "analyze",
        "report",
        "import",
        "export",
        "replay",
        "demo",
    ):
        assert group in result.output
