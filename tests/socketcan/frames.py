"""Deterministic test frames and a bounded receive loop for the SocketCAN tests."""

import can


def messages(count: int, ids: tuple[int, ...] = (0x100, 0x201, 0x7FF)) -> list[can.Message]:
    """`count` distinct frames cycling through standard `ids` plus one extended ID, with payload
    lengths 0..8 and bytes that encode the frame's position (so loss or reordering shows)."""
    out = []
    for i in range(count):
        slot = i % (len(ids) + 1)
        extended = slot == len(ids)
        out.append(
            can.Message(
                arbitration_id=0x1ABCDE00 + (i & 0xFF) if extended else ids[slot],
                is_extended_id=extended,
                data=[(i >> 8) & 0xFF, i & 0xFF, 0xA5, 0x5A, i % 7, 0, 0xFF, 0x33][: i % 9],
            )
        )
    return out


def drain(bus: can.BusABC, count: int, timeout_s: float = 5.0) -> list[can.Message]:
    """Receive `count` frames; fails naming how many arrived if one takes over `timeout_s`."""
    received = []
    while len(received) < count:
        msg = bus.recv(timeout=timeout_s)
        assert msg is not None, f"only {len(received)} of {count} frames arrived"
        received.append(msg)
    return received
