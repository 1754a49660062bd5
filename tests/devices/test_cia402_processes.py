"""The CiA 402 campaign of docs/examples/cia402-vcan.toml in two processes on the host, over
python-can's `udp_multicast` (the VM's vcan0 version, tests/socketcan/test_cia402.py, is skipped
under software emulation): `gyrostand simulate-drive --plan` and `gyrostand campaign run`, in
real time (about three minutes; opt-in: make test-processes)."""

from __future__ import annotations

import os

import pytest

from tests.devices.test_n2k_processes import multicast_group
from tests.socketcan.processes import cia402_campaign


@pytest.mark.skipif(
    os.environ.get("GYROSTAND_PROCESS_TESTS") != "1",
    reason="opt-in: make test-processes (a real-time two-process campaign, ~3 min)",
)
def test_cia402_campaign_in_two_processes_over_udp_multicast(tmp_path) -> None:
    try:
        import msgpack  # noqa: F401  (python-can's udp_multicast needs it)
    except ImportError:
        pytest.skip("msgpack is not installed (python-can's udp_multicast needs it)")
    cia402_campaign(tmp_path, "udp_multicast", multicast_group())
