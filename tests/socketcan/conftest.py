"""Fixtures for tests on a real SocketCAN interface (vcan0 natively, or in tools/vcan-vm)."""

from collections.abc import Iterator

import can
import pytest


@pytest.fixture(scope="session")
def channel(socketcan_channel: str) -> str:
    """The SocketCAN channel under test (gyrostand's plugin: the `socketcan` marker skips when
    there is none)."""
    return socketcan_channel


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
