"""IEC 61162-1 (NMEA 0183) sentences from a gyrocompass, one at a time: heading (HDT, THS), rate
of turn (ROT), alarms (ALR, ALF, HBT, proprietary $P...), and why a sentence is not usable.

The alarms' fields are read by pynmeagps (it knows THS and the alarm sentences; pynmea2 lacks
THS). The checks pynmeagps leaves to its caller are ours: the characters allowed, the checksum
present and right (pynmeagps's own check reports both as one error text), empty and missing
fields, THS modes other than A; and the hot sentences' few fields (see `_heading`)."""

from __future__ import annotations

import functools
import operator
import re
from dataclasses import dataclass

from pynmeagps import NMEAReader
from pynmeagps.exceptions import NMEAMessageError, NMEAParseError, NMEATypeError
from pynmeagps.nmeatypes_core import VALNONE

# IEC 61162-1 §7.1.2: a sentence, from '$' or '!' to <CR><LF>, is at most 82 characters
MAX_SENTENCE_BYTES = 82
# IEC 61162-1 THS mode indicator (§8.3 THS); only A (autonomous) is a valid reading
THS_MODES = {
    "A": "autonomous",
    "E": "estimated (dead reckoning)",
    "M": "manual input",
    "S": "simulator",
    "V": "data not valid",
}
ALARM_SENTENCES = ("ALR", "ALF", "HBT")


@dataclass(frozen=True)
class Heading:
    """A heading sentence (HDT or THS): heading in degrees, or why it is not a valid reading."""

    talker: str
    sentence: str
    heading_deg: float | None
    invalid: str | None = None  # the reason, None when valid


@dataclass(frozen=True)
class RateOfTurn:
    """ROT: rate of turn in degrees per minute (negative: bow turns to port)."""

    talker: str
    deg_per_min: float | None
    invalid: str | None = None


@dataclass(frozen=True)
class Alarm:
    """An alarm, alert or heartbeat sentence, or a proprietary one: its identity (what repeats
    of it share) and the text an event shows."""

    key: str
    text: str
    severity: str  # "info" (a heartbeat or alarm back to normal), "warning", "error"


@dataclass(frozen=True)
class Invalid:
    """A sentence (or bytes) that gives nothing usable, and why."""

    reason: str


@dataclass(frozen=True)
class Other:
    """A well-formed sentence a heading source does not use (e.g. $GPGGA on the same line)."""

    sentence: str


Decoded = Heading | RateOfTurn | Alarm | Invalid | Other


def checksum(body: bytes) -> int:
    """IEC 61162-1 §7.2.4: the XOR of every character between '$' (or '!') and '*'."""
    return functools.reduce(operator.xor, body, 0)


def decode(line: bytes) -> Decoded:
    """One sentence, from its '$' (or '!') up to, not including, its <CR><LF>."""
    if len(line) + 2 > MAX_SENTENCE_BYTES:
        return Invalid(f"longer than {MAX_SENTENCE_BYTES} characters")
    text = line.decode("latin-1")
    if not (line.isascii() and text.isprintable()):
        return Invalid("non-printable characters")
    star = text.rfind("*")
    if star < 0:
        return Invalid("no checksum")  # IEC 61162-1 §7.2.4: mandatory in every sentence
    if not _CHECKSUM.fullmatch(text, star + 1):
        return Invalid("malformed checksum")
    if int(text[star + 1 :], 16) != checksum(line[1:star]):
        return Invalid("checksum mismatch")
    fields = text[1:star].split(",")
    address = fields[0]
    if address.startswith("P"):
        return Alarm(f"proprietary {address}", f"proprietary sentence {text[:star]}", "info")
    if len(address) != 5:
        return Invalid(f"malformed address field {address!r}")
    talker, kind = address[:2], address[2:]
    if kind in ("HDT", "THS"):
        return _heading(talker, kind, fields[1:])
    if kind == "ROT":
        return _rate(talker, fields[1:])
    if kind not in ALARM_SENTENCES:
        return Other(kind)
    try:  # the alarms' many fields: pynmeagps's names for them
        msg = NMEAReader.parse(line + b"\r\n", validate=VALNONE)
    except (NMEAMessageError, NMEAParseError, NMEATypeError, ValueError) as exc:
        return Invalid(f"{kind}: unreadable field ({exc})")
    return _alarm(talker, kind, msg)


# The hot sentences (HDT, THS, ROT: every sample) are read here rather than through pynmeagps's
# NMEAMessage, which took 60% of the serial source's time (bench/bench_serial.py); the result
# is checked against pynmeagps's fields in tests/devices/test_nmea0183.py.
_CHECKSUM = re.compile(r"[0-9A-Fa-f]{2}")
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)")  # IEC 61162-1 §7.2.3 numeric field: no exponent


def _number(kind: str, name: str, fields: list[str], i: int) -> float | str:
    """Field i as a number, or why it is none (missing: the sentence has fewer fields)."""
    if i >= len(fields):
        return f"{kind}: {name} field missing"
    value = fields[i]
    if value == "":
        return f"{kind}: {name} field empty"
    if not _NUMBER.fullmatch(value):
        return f"{kind}: unreadable field ({name} {value!r})"
    return float(value)


def _heading(talker: str, kind: str, fields: list[str]) -> Heading:
    heading = _number(kind, "heading", fields, 0)
    if isinstance(heading, str):
        return Heading(talker, kind, None, heading)
    if not 0.0 <= heading < 360.0:
        return Heading(talker, kind, None, f"{kind}: heading {heading:g} outside 0-360")
    if kind == "HDT":
        if len(fields) > 1 and fields[1] not in ("T", ""):
            return Heading(talker, kind, None, "HDT: not a true heading")
        return Heading(talker, kind, heading)
    if len(fields) < 2 or fields[1] == "":
        return Heading(
            talker, kind, None, f"THS: mode field {'missing' if len(fields) < 2 else 'empty'}"
        )
    mode = fields[1]
    if mode != "A":
        name = THS_MODES.get(mode, "unknown mode")
        return Heading(talker, kind, heading, f"THS mode {mode} ({name})")
    return Heading(talker, kind, heading)


def _rate(talker: str, fields: list[str]) -> RateOfTurn:
    rate = _number("ROT", "rate", fields, 0)
    if isinstance(rate, str):
        return RateOfTurn(talker, None, rate)
    status = fields[1] if len(fields) > 1 else ""
    if status != "A":
        return RateOfTurn(talker, rate, f"ROT: status {status or 'empty'} (not valid)")
    return RateOfTurn(talker, rate)


def _alarm(talker: str, kind: str, msg: object) -> Alarm:
    """ALR (IEC 61162-1 §8.3 ALR): alarm number, condition A threshold exceeded / V not,
    acknowledge state A/V, text. ALF (IEC 61162-1 Ed.5 §8.3 ALF, BAM alerts): category,
    priority, state, identifier, text. HBT: repeat interval, status A normal / V not, sequence."""
    f = msg.__dict__
    if kind == "ALR":
        active = f.get("alarmcond") == "A"
        state = "active" if active else "normal"
        acked = ", acknowledged" if f.get("alarmstate") == "A" else ""
        return Alarm(
            f"{talker}ALR {f.get('alarmnum', '')}",
            f"{talker}ALR alarm {f.get('alarmnum', '')} {state}{acked}: {f.get('alarmtext', '')}",
            "error" if active else "info",
        )
    if kind == "ALF":
        priority = {"E": "emergency", "A": "alarm", "W": "warning", "C": "caution"}
        level = priority.get(str(f.get("alertpriority", "")), "alert")
        ident = f"{f.get('alertid', '')}.{f.get('alertinst', '')}"
        state = f.get("alertstate", "")
        return Alarm(
            f"{talker}ALF {ident}",
            f"{talker}ALF {level} {ident} state {state}: {f.get('alerttxt', '')}",
            "info" if state == "N" else ("error" if level in ("emergency", "alarm") else "warning"),
        )
    normal = f.get("status") == "A"
    return Alarm(
        f"{talker}HBT",
        f"{talker}HBT heartbeat: {'normal operation' if normal else 'not in normal operation'}",
        "info" if normal else "warning",
    )
