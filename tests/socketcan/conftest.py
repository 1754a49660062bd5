"""Fixtures for tests on a real SocketCAN interface (vcan0 natively, or in tools/vcan-vm)."""

from collections.abc import Iterator

import can
import pytest

from tests.conftest import socketcan_channel


@pytest.fixture(scope="session")
def channel() -> str:
    """The SocketCAN channel under test (the `socketcan` marker already skips when none)."""
    name = socketcan_channel()
    assert name is not None
    return name


@pytest.fixture
def open_bus(channel: str) -> Iterator:
    """Factory for python-can SocketCAN buses on the channel, all shut down after the test."""
    buses: list[can.BusABC] = []

    def make(**kwargs: object) -> can.BusABC:
        bus = can.Bus(interface="socketcan", channel=channel, **kwargs)
        buses.append(bus)
        return bus

    yield make
    for bus in buses:
        bus.shutdown()
