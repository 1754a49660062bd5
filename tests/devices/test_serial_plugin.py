"""The pytest plugin's serial compass: a user's test reads IEC 61162 sentences from a port."""

import re
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.serial_port import SerialReader

HANG_GUARD_S = 120.0


class Clock:
    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64)


def test_sentences_on_the_fixtures_port(gyro_serial_compass: Callable[..., str]) -> None:
    path = gyro_serial_compass(sentences=("THS", "ROT"), baud=38400, rate_hz=20.0, seed=4)
    source = Iec61162Source(38400, path)
    headings: list[float] = []
    deadline = time.monotonic() + HANG_GUARD_S
    with SerialReader(path, 38400) as reader:
        while len(headings) < 10 and time.monotonic() < deadline:
            out = source.decode(reader.take(wait_s=1.0), Clock())
            headings += out.headings.heading_deg.tolist()
            assert out.invalid == ()
    assert len(headings) >= 10 and all(abs(h - 120.0) < 1.0 for h in headings)
    assert source.kinds["ROT"] >= 9


def test_the_documented_example(gyro_serial_compass: Callable[..., str]) -> None:
    """docs/testing.md's serial example (its `py` block), run with this fixture."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "testing.md").read_text()
    (block,) = re.findall(r"```py\n(.*?)```", text, re.S)
    scope: dict[str, object] = {}
    exec(compile(block, "docs/testing.md", "exec"), scope)
    scope["test_reads_a_heading"](gyro_serial_compass)  # type: ignore[operator]
