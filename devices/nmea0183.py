"""IEC 61162-1 (NMEA 0183) sentences from a gyrocompass, one at a time: heading (HDT, THS), rate
of turn (ROT), alarms (ALR, ALF, HBT, proprietary $P...), and why a sentence is not usable.

Fields are read by pynmeagps (it knows THS; pynmea2 does not). The checks pynmeagps leaves to its
caller are ours: the characters allowed, the checksum present and right (pynmeagps's own check
reports both as one error text), empty and missing fields, THS modes other than A."""

from __future__ import annotations

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
    value = 0
    for b in body:
        value ^= b
    return value


def decode(line: bytes) -> Decoded:
    """One sentence, from its '$' (or '!') up to, not including, its <CR><LF>."""
    if len(line) + 2 > MAX_SENTENCE_BYTES:
        return Invalid(f"longer than {MAX_SENTENCE_BYTES} characters")
    if not all(0x20 <= b <= 0x7E for b in line):
        return Invalid("non-printable characters")
    star = line.rfind(b"*")
    if star < 0:
        return Invalid("no checksum")  # IEC 61162-1 §7.2.4: mandatory in every sentence
    given = line[star + 1 :]
    if len(given) != 2 or not all(c in b"0123456789ABCDEFabcdef" for c in given):
        return Invalid("malformed checksum")
    if int(given, 16) != checksum(line[1:star]):
        return Invalid("checksum mismatch")
    text = line.decode("ascii")
    address = text[1:star].split(",", 1)[0]
    if address.startswith("P"):
        return Alarm(f"proprietary {address}", f"proprietary sentence {text[:star]}", "info")
    if len(address) != 5:
        return Invalid(f"malformed address field {address!r}")
    talker, kind = address[:2], address[2:]
    if kind not in ("HDT", "THS", "ROT", *ALARM_SENTENCES):
        return Other(kind)
    try:
        msg = NMEAReader.parse(line + b"\r\n", validate=VALNONE)
    except (NMEAMessageError, NMEAParseError, NMEATypeError, ValueError) as exc:
        return Invalid(f"{kind}: unreadable field ({exc})")
    if kind == "HDT":
        return _heading(talker, kind, msg, "headingT")
    if kind == "THS":
        heading = _heading(talker, kind, msg, "headt")
        mode, reason = _field(msg, "mi")
        if heading.invalid is None and reason is not None:
            return Heading(talker, kind, None, f"THS: mode field {reason}")
        if heading.invalid is None and mode != "A":
            name = THS_MODES.get(str(mode), "unknown mode")
            return Heading(talker, kind, heading.heading_deg, f"THS mode {mode} ({name})")
        return heading
    if kind == "ROT":
        return _rate(talker, msg)
    return _alarm(talker, kind, msg)


def _field(msg: object, name: str) -> tuple[object, str | None]:
    """A field's value, or why there is none (a sentence cut short, or the field empty)."""
    if not hasattr(msg, name):
        return None, "missing"
    value = getattr(msg, name)
    if value == "":
        return None, "empty"
    return value, None


def _heading(talker: str, kind: str, msg: object, name: str) -> Heading:
    value, reason = _field(msg, name)
    if reason is not None:
        return Heading(talker, kind, None, f"{kind}: heading field {reason}")
    heading = float(value)  # type: ignore[arg-type]
    if not 0.0 <= heading < 360.0:
        return Heading(talker, kind, None, f"{kind}: heading {heading:g} outside 0-360")
    if kind == "HDT" and getattr(msg, "headingTu", "T") not in ("T", ""):
        return Heading(talker, kind, None, "HDT: not a true heading")
    return Heading(talker, kind, heading)


def _rate(talker: str, msg: object) -> RateOfTurn:
    value, reason = _field(msg, "rot")
    if reason is not None:
        return RateOfTurn(talker, None, f"ROT: rate field {reason}")
    status = getattr(msg, "valid", "")
    if status != "A":
        return RateOfTurn(talker, float(value), f"ROT: status {status or 'empty'} (not valid)")  # type: ignore[arg-type]
    return RateOfTurn(talker, float(value))  # type: ignore[arg-type]


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
