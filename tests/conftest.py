"""Shared pytest set-up: the `socketcan` marker skips unless a SocketCAN interface is up."""

import os
import socket
from pathlib import Path

import pytest


def socketcan_channel() -> str | None:
    """The SocketCAN channel to test on (GYROSTAND_SOCKETCAN_CHANNEL, default vcan0), if usable."""
    channel = os.environ.get("GYROSTAND_SOCKETCAN_CHANNEL", "vcan0")
    if not hasattr(socket, "AF_CAN") or not Path(f"/sys/class/net/{channel}").exists():
        return None
    return channel


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if socketcan_channel() is not None:
        return
    skip = pytest.mark.skip(reason="no SocketCAN interface (vcan0) on this machine")
    for item in items:
        if "socketcan" in item.keywords:
            item.add_marker(skip)
