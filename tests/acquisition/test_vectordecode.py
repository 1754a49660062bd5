"""The numpy decoder agrees with cantools bit for bit on every signal of random layouts."""

import math

import numpy as np
from cantools.database.can import Message, Signal
from cantools.database.conversion import BaseConversion
from hypothesis import given, settings
from hypothesis import strategies as st

from gyrostand.frames.vectordecode import VectorDecoder
from gyrostand.stand.protocol import SignalLayout


@st.composite
def signals(draw: st.DrawFn, index: int) -> Signal:
    is_float = draw(st.booleans()) and draw(st.booleans())
    length = draw(st.sampled_from([32, 64])) if is_float else draw(st.integers(1, 64))
    shift = draw(st.integers(0, 64 - length))
    big = draw(st.booleans())
    if big:
        msb = shift + length - 1
        start = 8 * (7 - msb // 8) + msb % 8
    else:
        start = shift
    scale = draw(st.sampled_from([1, 0.001, 0.1, 2, 1e-6, 0.0001]))
    offset = draw(st.sampled_from([0, -180.0, 40, 0.5]))
    return Signal(
        name=f"s{index}",
        start=start,
        length=length,
        byte_order="big_endian" if big else "little_endian",
        is_signed=draw(st.booleans()) and not is_float,
        conversion=BaseConversion.factory(scale=scale, offset=offset, is_float=is_float),
    )


def payload_bits(signal: Signal) -> set[tuple[int, int]]:
    """(byte, bit) cells a signal occupies, to keep random layouts from overlapping."""
    if signal.byte_order == "little_endian":
        return {(p // 8, p % 8) for p in range(signal.start, signal.start + signal.length)}
    msb = (7 - signal.start // 8) * 8 + signal.start % 8
    return {(7 - p // 8, p % 8) for p in range(msb - signal.length + 1, msb + 1)}


@st.composite
def messages(draw: st.DrawFn) -> Message:
    sigs: list[Signal] = []
    used: set[tuple[int, int]] = set()
    for i in range(draw(st.integers(1, 4))):  # a signal overlapping earlier ones is left out
        sig = draw(signals(i))
        if not payload_bits(sig) & used:
            sigs.append(sig)
            used |= payload_bits(sig)
    return Message(frame_id=0x123, name="m", length=8, signals=sigs, strict=False)


def same(got: object, expected: int | float) -> bool:
    """Equal as cantools returns it: exact integers, or the same float64 bit pattern."""
    if isinstance(expected, int):
        return int(got) == expected  # type: ignore[call-overload]
    if math.isnan(expected):
        return math.isnan(float(got))  # type: ignore[arg-type]
    return np.float64(got).tobytes() == np.float64(expected).tobytes()


@settings(max_examples=150, deadline=None)
@given(messages(), st.lists(st.binary(min_size=8, max_size=8), min_size=1, max_size=20))
def test_vector_decoder_equals_cantools(message: Message, payloads: list[bytes]) -> None:
    decoder = VectorDecoder(message)
    array = np.frombuffer(b"".join(payloads), dtype=np.uint8).reshape(len(payloads), 8)
    decoded = decoder.decode(array)
    for row, payload in enumerate(payloads):
        expected = message.decode(payload, decode_choices=False, scaling=True)
        for name, value in expected.items():
            got = decoded[name][row]
            assert same(got, value), (name, payload.hex(), got, value)


@settings(max_examples=150, deadline=None)
@given(messages(), st.data())
def test_layout_payload_equals_cantools(message: Message, data: st.DataObject) -> None:
    for signal in message.signals:
        if signal.is_float:
            continue
        raw = data.draw(st.integers(0, 2**signal.length - 1))
        alone = {s.name: 0 for s in message.signals} | {signal.name: raw}
        if signal.is_signed and raw >= 2 ** (signal.length - 1):
            alone[signal.name] = raw - 2**signal.length  # cantools takes the signed value
        expected = message.encode(alone, scaling=False, strict=False)
        assert SignalLayout.of(signal).payload(raw) == expected, (signal.name, raw)


def test_out_of_range_uses_dbc_limits() -> None:
    scale = BaseConversion.factory(scale=0.001)
    sig = Signal("heading", 0, 20, minimum=0, maximum=360, conversion=scale)
    decoder = VectorDecoder(Message(0x10, "h", 8, [sig]))
    raw = np.array([0, 360_000, 360_001, 2**20 - 1], dtype="<u8").view(np.uint8).reshape(4, 8)
    values = decoder.decode(raw)
    assert values["heading"].tolist() == [0.0, 360.0, 360_001 * 0.001, (2**20 - 1) * 0.001]
    assert decoder.out_of_range(values).tolist() == [False, False, True, True]


def test_out_of_range_allows_the_rounding_tolerance() -> None:
    """raw 3599 at scale 0.1 is 359.90000000000003: inside [0, 359.9] as cantools and the codec
    judge it (limits widened by abs(scale) * 1e-6)."""
    scale = BaseConversion.factory(scale=0.1)
    sig = Signal("heading", 0, 20, minimum=0, maximum=359.9, conversion=scale)
    decoder = VectorDecoder(Message(0x10, "h", 8, [sig]))
    raw = np.array([3599, 3600], dtype="<u8").view(np.uint8).reshape(2, 8)
    values = decoder.decode(raw)
    assert values["heading"][0] > 359.9
    assert decoder.out_of_range(values).tolist() == [False, True]
