"""Sentence decoding: headings, modes, alarms and every reason a sentence is not usable."""

import numpy as np
import pytest
from pynmeagps import NMEAReader
from pynmeagps.exceptions import NMEATypeError
from pynmeagps.nmeahelpers import calc_checksum
from pynmeagps.nmeatypes_core import VALNONE

from gyrostand.devices.nmea0183 import Alarm, Heading, Invalid, Other, RateOfTurn, decode


def sentence(body: str) -> bytes:
    """A sentence with its checksum computed by pynmeagps (independent of ours)."""
    return f"${body}*{calc_checksum(body)}".encode()


def test_published_examples_decode() -> None:
    # checksums as published: NemaStudio's TAG block example, the classic GGA example
    assert decode(b"$HEHDT,119.9,T*2F") == Heading("HE", "HDT", 119.9)
    gga = b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"
    assert decode(gga) == Other("GGA")


@pytest.mark.parametrize("talker", ["HE", "HN", "II", "GP", "HC"])
def test_any_talker(talker: str) -> None:
    assert decode(sentence(f"{talker}HDT,0.0,T")) == Heading(talker, "HDT", 0.0)
    assert decode(sentence(f"{talker}THS,359.99,A")) == Heading(talker, "THS", 359.99)


@pytest.mark.parametrize(
    ("mode", "reason"),
    [
        ("E", "THS mode E (estimated (dead reckoning))"),
        ("M", "THS mode M (manual input)"),
        ("S", "THS mode S (simulator)"),
        ("V", "THS mode V (data not valid)"),
        ("X", "THS mode X (unknown mode)"),
    ],
)
def test_ths_modes_other_than_a_are_invalid(mode: str, reason: str) -> None:
    assert decode(sentence(f"HETHS,231.50,{mode}")) == Heading("HE", "THS", 231.5, reason)


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        ("HEHDT,,T", "HDT: heading field empty"),
        ("HEHDT", "HDT: heading field missing"),
        ("HETHS,,V", "THS: heading field empty"),
        ("HETHS,12.0", "THS: mode field missing"),
        ("HETHS,12.0,", "THS: mode field empty"),
        ("HEHDT,360.0,T", "HDT: heading 360 outside 0-360"),
        ("HEHDT,-0.1,T", "HDT: heading -0.1 outside 0-360"),
        ("HEHDT,1x9.9,T", "HDT: unreadable field (heading '1x9.9')"),
        ("HEHDT,1e2,T", "HDT: unreadable field (heading '1e2')"),  # no exponent in NMEA
        ("HEHDT,nan,T", "HDT: unreadable field (heading 'nan')"),
    ],
)
def test_unusable_heading_fields(body: str, reason: str) -> None:
    decoded = decode(sentence(body))
    assert isinstance(decoded, Heading)
    assert (decoded.heading_deg, decoded.invalid) == (None, reason)


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b"$HEHDT,119.9,T*2E", "checksum mismatch"),
        (b"$HEHDT,119.8,T*2F", "checksum mismatch"),
        (b"$HEHDT,119.9,T", "no checksum"),
        (b"$HEHDT,119.9,T*2", "malformed checksum"),
        (b"$HEHDT,119.9,T*ZZ", "malformed checksum"),
        (b"$HEHDT,119.9\x00,T*2F", "non-printable characters"),
        (b"$HEHDT,119.9\xb0,T*2F", "non-printable characters"),
        (b"$HEHDT," + b"1" * 80 + b"*00", "longer than 82 characters"),
        (sentence("HDT,1.0,T"), "malformed address field 'HDT'"),
    ],
)
def test_invalid_sentences_name_their_reason(line: bytes, reason: str) -> None:
    assert decode(line) == Invalid(reason)


def test_rate_of_turn() -> None:
    assert decode(sentence("HEROT,-12.3,A")) == RateOfTurn("HE", -12.3)
    assert decode(sentence("TIROT,4.0,V")) == RateOfTurn("TI", 4.0, "ROT: status V (not valid)")
    assert decode(sentence("HEROT,,A")) == RateOfTurn("HE", None, "ROT: rate field empty")


def test_alarms_become_alarm_records() -> None:
    alr = decode(sentence("HEALR,120000.00,001,A,V,GYRO FAILURE"))
    assert alr == Alarm("HEALR 001", "HEALR alarm 001 active: GYRO FAILURE", "error")
    cleared = decode(sentence("HEALR,120100.00,001,V,A,GYRO FAILURE"))
    assert cleared == Alarm(
        "HEALR 001", "HEALR alarm 001 normal, acknowledged: GYRO FAILURE", "info"
    )
    alf = decode(sentence("HEALF,1,1,0,120000.00,A,W,A,,123,1,0,0,HDG DIFF"))
    assert alf == Alarm("HEALF 123.1", "HEALF warning 123.1 state A: HDG DIFF", "warning")
    assert decode(sentence("HEHBT,1.0,A,3")) == Alarm(
        "HEHBT", "HEHBT heartbeat: normal operation", "info"
    )
    assert decode(sentence("HEHBT,1.0,V,4")).severity == "warning"  # type: ignore[union-attr]
    prop = decode(sentence("PTKM,GYRO,1,2"))
    assert prop == Alarm("proprietary PTKM", "proprietary sentence $PTKM,GYRO,1,2", "info")


def reference(line: bytes) -> tuple[str, float | None, str | None]:
    """HDT/THS/ROT read with pynmeagps's fields: kind, value, status (None: unreadable)."""
    try:
        msg = NMEAReader.parse(line + b"\r\n", validate=VALNONE)
    except NMEATypeError:
        return "unreadable", None, None
    kind = msg.msgID
    name, status = {"HDT": ("headingT", None), "THS": ("headt", "mi"), "ROT": ("rot", "valid")}[
        kind
    ]
    value = getattr(msg, name, None)
    return kind, None if value in ("", None) else float(value), getattr(msg, status or "", None)


def test_the_hot_sentences_read_as_pynmeagps_reads_them() -> None:
    """HDT, THS, ROT read without pynmeagps (speed): the same values as pynmeagps's fields on
    3000 random sentences, empty and missing fields and unreadable numbers among them."""
    rng = np.random.default_rng(7)
    numbers = ["", "1x2", "-", "12.", ".5", "+3.25", "007.0"]
    for _ in range(3000):
        kind = str(rng.choice(["HDT", "THS", "ROT"]))
        value = (
            f"{rng.uniform(-400, 400):.{rng.integers(0, 4)}f}"
            if rng.random() < 0.7
            else str(rng.choice(numbers))
        )
        status = str(rng.choice(["A", "V", "E", ""]))
        tail = {"HDT": "T", "THS": status, "ROT": status}[kind]
        body = f"HE{kind},{value},{tail}" if rng.random() < 0.95 else f"HE{kind},{value}"
        ours, (ref_kind, ref_value, ref_status) = decode(sentence(body)), reference(sentence(body))
        if ref_kind == "unreadable" or value == "-":
            assert "unreadable field" in str(ours), body
            continue
        assert isinstance(ours, Heading | RateOfTurn)
        got = ours.heading_deg if isinstance(ours, Heading) else ours.deg_per_min
        if ref_value is None:
            assert got is None and "field" in str(ours.invalid), body
            continue
        in_range = kind == "ROT" or 0 <= ref_value < 360
        if not in_range:
            assert got is None and "outside 0-360" in str(ours.invalid), body
            continue
        if kind == "THS" and not ref_status:  # no mode: no reading either
            assert got is None and "mode field" in str(ours.invalid), body
            continue
        assert got == ref_value, body
        valid = kind == "HDT" or ref_status == "A"
        assert (ours.invalid is None) == valid, body


def test_serialized_by_pynmeagps_round_trips() -> None:
    from pynmeagps import NMEAMessage

    raw = NMEAMessage("HE", "THS", 0, headt=87.25, mi="A").serialize()
    assert decode(raw.rstrip(b"\r\n")) == Heading("HE", "THS", 87.25)
