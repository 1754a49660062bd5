"""The pytest plugin's serial compass: a user's test reads IEC 61162 sentences from a port."""

import re
from collections.abc import Callable
from pathlib import Path

from tests.devices.serial_reading import read_headings


def test_sentences_on_the_fixtures_port(gyro_serial_compass: Callable[..., str]) -> None:
    path = gyro_serial_compass(sentences=("THS", "ROT"), baud=38400, rate_hz=20.0, seed=4)
    headings, source = read_headings(path, 38400, 10)
    assert len(headings) >= 10 and all(abs(h - 120.0) < 1.0 for h in headings)
    assert source.kinds["ROT"] >= 9


def test_the_documented_example(gyro_serial_compass: Callable[..., str]) -> None:
    """docs/testing.md's serial example (its `py` block), run with this fixture."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "testing.md").read_text()
    (block,) = re.findall(r"```py\n(.*?)```", text, re.S)
    scope: dict[str, object] = {}
    exec(compile(block, "docs/testing.md", "exec"), scope)
    scope["test_reads_a_heading"](gyro_serial_compass)  # type: ignore[operator]
