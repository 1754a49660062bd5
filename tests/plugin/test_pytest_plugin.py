"""The plugin as a user meets it: the example of docs/testing.md run by pytester against the
simulated stand, with gyrostand's DBC and with a lab's DBC and signal map; the socketcan skip;
bad knobs in one line; and a run that uses no fixture imports nothing heavy."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

import gyrostand.stand_campaign  # noqa: F401  (loaded once: pytester's in-process runs unload

# what they import, and numpy cannot be loaded twice in a process)
from gyrostand.pytest_plugin import socketcan_missing

ROOT = Path(__file__).resolve().parents[2]
LAB_DBC = ROOT / "docs" / "examples" / "lab.dbc"
LAB_SIGNALS = ROOT / "docs" / "examples" / "lab-signals.toml"
LAB_OPTIONS = ("--gyrostand-dbc", str(LAB_DBC), "--gyrostand-signals", str(LAB_SIGNALS))


def example() -> str:
    """The example test file of docs/testing.md (the python block of its "Example" section)."""
    text = (ROOT / "docs" / "testing.md").read_text()
    found = re.search(r"\n## Example\n.*?```python\n(.*?)```", text, re.S)
    assert found is not None, "docs/testing.md: no python block under ## Example"
    return found.group(1)


def expected_outcomes() -> dict[str, int]:
    """Five tests; the socketcan one is skipped where this machine has no vcan0."""
    if socketcan_missing("vcan0") is None:
        return {"passed": 5}
    return {"passed": 4, "skipped": 1}


@pytest.mark.parametrize("options", [(), LAB_OPTIONS], ids=["gyrostand-dbc", "lab-dbc"])
def test_the_documented_example_passes(pytester: pytest.Pytester, options: tuple) -> None:
    pytester.makepyfile(test_lab=example())
    result = pytester.runpytest("-p", "no:cacheprovider", *options)
    result.assert_outcomes(**expected_outcomes())


NAMES = """
def test_names(gyro_stand):
    gyro_stand.advance(2.0)
    print("sent", sorted(gyro_stand.frames_per_message().items()))
"""


@pytest.mark.parametrize(
    ("options", "heading", "status", "motion", "compass"),
    [
        ((), "GYRO_HEADING", "STAND_STATUS", "STAND_MOTION", "GYRO_STATUS"),
        (LAB_OPTIONS, "LAB_ANGLE", "LAB_STAND_STATE", "LAB_STAND_MOTION", "LAB_GYRO_HEALTH"),
    ],
)
def test_the_stand_speaks_the_dbc_it_is_given(
    pytester: pytest.Pytester, options: tuple, heading, status, motion, compass
) -> None:
    pytester.makepyfile(test_names=NAMES)
    result = pytester.runpytest("-s", *options)
    result.assert_outcomes(passed=1)
    # 2 s of stand time: headings at 10 Hz from 0 to 2 s, the status messages at 2 Hz, the
    # virtual-time clock every whole second
    sent = sorted([(heading, 21), (status, 5), (motion, 5), (compass, 5), ("SIM_CLOCK", 3)])
    assert f"sent {sent}" in result.stdout.str()


SOCKETCAN = """
import pytest

@pytest.mark.socketcan
def test_marked():
    pass

def test_fixture(socketcan_channel):
    pass

def test_stand(gyro_stand_factory):
    gyro_stand_factory(interface="socketcan")
"""


def test_socketcan_tests_skip_with_the_reason_without_the_interface(
    pytester: pytest.Pytester,
) -> None:
    pytester.makepyfile(test_can=SOCKETCAN)
    result = pytester.runpytest("-rs", "--gyrostand-channel", "gyrostand-none")
    result.assert_outcomes(skipped=3)
    assert result.stdout.str().count("no SocketCAN interface 'gyrostand-none'") == 3


def test_socketcan_tests_skip_with_the_reason_off_linux(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytester.makepyfile(test_can=SOCKETCAN)
    monkeypatch.setattr(sys, "platform", "darwin")
    result = pytester.runpytest("-rs")
    result.assert_outcomes(skipped=3)
    assert result.stdout.str().count("SocketCAN needs Linux; this is darwin") == 3


BAD = """
import pytest

@pytest.mark.gyro_stand(faults={"dorp_rate": 0.1}, seed=1)
def test_typo(gyro_stand):
    pass

@pytest.mark.gyro_stand(noise={"white_sigma_deg": -1.0})
def test_negative(gyro_stand):
    pass

def test_injected(gyro_stand):
    gyro_stand.inject_fault(drop_rate=2.0)
"""


def test_bad_knobs_fail_in_one_line(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_bad=BAD)
    result = pytester.runpytest()
    result.assert_outcomes(errors=2, failed=1)
    result.stdout.fnmatch_lines(
        [
            "*simulated stand: faults.dorp_rate: Extra inputs are not permitted; valid: drop_rate*",
            "*simulated stand: noise.white_sigma_deg: must be a number >= 0, got -1.0",
            "E * inject_fault: drop_rate must be a probability in ?0, 1?",
        ],
        consecutive=False,
    )
    # the knobs of the fixture fail in their line alone (the call in the test body shows where)
    assert result.stdout.str().count("simulated_stand.py:") == 1


UNUSED = """
def test_plain():
    assert 1 + 1 == 2
"""

HEAVY = ("numpy", "scipy", "can", "cantools", "sqlalchemy", "pydantic", "gyrostand.stand")


def test_a_run_without_the_fixtures_imports_nothing_heavy(pytester: pytest.Pytester) -> None:
    """What the plugin costs a run that uses none of its fixtures: its module and pytest's."""
    pytester.makepyfile(test_plain=UNUSED)
    pytester.makeconftest(
        "import sys\n"
        "def pytest_sessionfinish(session):\n"
        f"    loaded = sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r}\n"
        "                    or m.startswith('gyrostand.stand'))\n"
        "    print('heavy', loaded, 'plugin', 'gyrostand.pytest_plugin' in sys.modules)\n"
    )
    result = pytester.runpytest_subprocess("-s", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)
    assert "heavy [] plugin True" in result.stdout.str()


def test_the_entry_point_is_the_plugin() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import importlib.metadata as m; print([e.value for e in "
            "m.entry_points(group='pytest11') if e.name == 'gyrostand'])",
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert out.strip() == "['gyrostand.pytest_plugin']"


N2K = """
from collections import Counter

import numpy as np
import pytest

from gyrostand.devices.nmea2000 import ReferenceDecoder, split_id


@pytest.mark.gyro_stand(protocol="nmea2000", nmea2000={"model": "GX-1", "serial": "S-7"})
def test_nmea2000(gyro_stand):
    bus = gyro_stand.open_bus()
    gyro_stand.advance(2.0)
    frames = []
    while (msg := bus.recv(0.5)) is not None:
        frames.append(msg)
    n2k = [m for m in frames if m.is_extended_id]
    pgn, source = split_id(np.array([m.arbitration_id for m in n2k]))
    counts = Counter(pgn.tolist())
    assert counts[127250] == counts[127251] == counts[127257] == 21
    assert counts[60928] == 1 and set(source.tolist()) == {35}
    reference = ReferenceDecoder()
    told = [reference.decode(m) for m, p in zip(n2k, pgn) if p in (60928, 126996)]
    assert told[-1].model == "GX-1" and told[-1].serial == "S-7"

@pytest.mark.gyro_stand(protocol="nmea2001")
def test_unknown(gyro_stand):
    pass

@pytest.mark.gyro_stand(protocol="nmea2000", nmea2000={"adress": 3})
def test_typo(gyro_stand):
    pass
"""


def test_the_stand_speaks_nmea2000_when_asked(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_n2k=N2K)
    result = pytester.runpytest()
    result.assert_outcomes(passed=1, errors=2)
    result.stdout.fnmatch_lines(
        [
            "*simulated stand: protocol 'nmea2001' is not one of gyrostand, nmea2000, cia406*",
            "*simulated stand: unknown nmea2000 knob(s) adress",
        ],
        consecutive=False,
    )


CIA406 = """
import struct

import pytest


@pytest.mark.gyro_stand(protocol="cia406", cia406={"node_id": 7, "heartbeat_ms": 500})
def test_cia406(gyro_stand):
    bus = gyro_stand.open_bus()
    gyro_stand.advance(2.0)
    frames = []
    while (msg := bus.recv(0.5)) is not None:
        frames.append(msg)
    tpdo = [m for m in frames if m.arbitration_id == 0x187]
    beats = [m.data[0] for m in frames if m.arbitration_id == 0x707]
    assert len(tpdo) == 21 and all(len(m.data) == 4 for m in tpdo)
    assert beats == [0, 5, 5, 5, 5, 5]  # boot-up, then OPERATIONAL every 500 ms
    counts = [struct.unpack("<I", bytes(m.data))[0] for m in tpdo]
    assert all(0 <= c < 65536 for c in counts)

@pytest.mark.gyro_stand(protocol="cia406", cia406={"node": 3})
def test_typo(gyro_stand):
    pass
"""


def test_the_stand_speaks_cia406_when_asked(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_cia406=CIA406)
    result = pytester.runpytest()
    result.assert_outcomes(passed=1, errors=1)
    result.stdout.fnmatch_lines(["*simulated stand: unknown cia406 knob 'node'"])
