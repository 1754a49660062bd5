"""`python -m gyrostand`."""

from gyrostand.cli import app

app(prog_name="gyrostand")
