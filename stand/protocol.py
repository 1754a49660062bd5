"""The CAN protocol between the test controller, the roll stand and the gyrocompass.

Frames are described by a DBC file (`DBC_PATH`, table in docs/protocol.md) and encoded/decoded
with cantools. A `SignalMap` says which DBC message/signal carries each quantity, so a lab can use
its own DBC for its own angle sensor without code changes. Decoding never raises: frames that
cannot be decoded become `InvalidFrame`. Times are STAND time in milliseconds.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import cantools
from cantools.database.can import Message as DbcMessage
from cantools.database.can import Signal

if TYPE_CHECKING:  # numpy and python-can are imported where used: `plan check` reads the DBC's
    import can  # ranges with this module and needs neither (~0.15 s of its start-up)
    import numpy as np

DBC_PATH: Path = Path(__file__).with_name("gyrostand.dbc")

COMMANDS = ("set", "start", "stop")


def _crc8_table(poly: int) -> tuple[int, ...]:
    """Lookup table of the MSB-first CRC-8 with the given polynomial."""
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ poly if crc & 0x80 else crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_CRC8_J1850 = _crc8_table(0x1D)  # SAE J1850 polynomial x^8 + x^4 + x^3 + x^2 + 1


def crc8_sae_j1850(data: bytes) -> int:
    """CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xorout 0xFF), the automotive E2E CRC.

    Table-driven here because crccheck's bitwise loop costs ~7 us a frame and the simulator
    sends 10 000 heading frames a second at 1000x (tests check it against crccheck)."""
    crc = 0xFF
    for byte in data:
        crc = _CRC8_J1850[crc ^ byte]
    return crc ^ 0xFF


def crc8_sae_j1850_rows(data: np.ndarray) -> np.ndarray:
    """`crc8_sae_j1850` of each row of an (n, k) uint8 array, as uint8."""
    import numpy as np

    table = np.array(_CRC8_J1850, dtype=np.uint8)
    crc = np.full(len(data), 0xFF, np.uint8)
    for column in range(data.shape[1]):
        crc = table[crc ^ data[:, column]]
    return crc ^ np.uint8(0xFF)


def signal_bounds(signal: Signal) -> tuple[float, float]:
    """A signal's physical [minimum, maximum] widened by a rounding tolerance (inf if unset)."""
    # cantools' range rule (Message._assert_signal_values_valid): limits +- abs(scale) * 1e-6
    tolerance = abs(signal.scale) * 1e-6
    low = signal.minimum - tolerance if signal.minimum is not None else -math.inf
    high = signal.maximum + tolerance if signal.maximum is not None else math.inf
    return low, high


class ProtocolError(ValueError):
    """A value that cannot be encoded, or a DBC / signal map that does not fit the protocol."""


def load_dbc(path: Path = DBC_PATH) -> cantools.database.can.Database:
    """A DBC file parsed by cantools, parsed again only when the file changes (its size or
    modification time): a report builds a codec per raw log and trial. Callers only read it."""
    stat = path.stat()
    return _parsed_dbc(str(path.resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=16)
def _parsed_dbc(path: str, mtime_ns: int, size: int) -> cantools.database.can.Database:
    return cantools.database.load_file(path)


@functools.cache
def shipped_range(ref: str) -> tuple[float, float]:
    """[minimum, maximum] of a signal "MESSAGE.SIGNAL" of the shipped DBC (what the simulated
    stand can put in a frame)."""
    message, signal = ref.split(".")
    found = load_dbc().get_message_by_name(message)
    found_signal = found.get_signal_by_name(signal)
    return float(found_signal.minimum), float(found_signal.maximum)


@dataclass(frozen=True)
class SignalLayout:
    """Where one signal sits in a payload of at most 8 bytes read as a 64-bit integer
    (little-endian for Intel signals, big-endian for Motorola ones), how it scales and its range
    (`signal_bounds`). The one reading of a cantools signal's bit layout: the numpy decoder and
    encoder and the codec's CRC all use it."""

    name: str
    big_endian: bool
    shift: int  # bit position of the signal's least significant bit in that integer
    length: int
    signed: bool
    is_float: bool
    scale: float
    offset: float
    low: float
    high: float

    @classmethod
    def of(cls, signal: Signal) -> SignalLayout:
        """The layout of a cantools signal; ProtocolError if it does not fit in 8 bytes."""
        big_endian = signal.byte_order == "big_endian"
        if big_endian:
            # DBC "sawtooth" numbering: start bit is the MSB; byte 0 is the top byte of the
            # big-endian integer, bit b of byte k sits at (7 - k) * 8 + b.
            shift = (7 - signal.start // 8) * 8 + signal.start % 8 - signal.length + 1
        else:
            shift = signal.start
        if shift < 0 or shift + signal.length > 64:
            raise ProtocolError(f"signal {signal.name} does not fit in 8 bytes")
        low, high = signal_bounds(signal)
        return cls(
            name=signal.name,
            big_endian=big_endian,
            shift=shift,
            length=signal.length,
            signed=signal.is_signed,
            is_float=signal.is_float,
            scale=signal.scale,
            offset=signal.offset,
            low=low,
            high=high,
        )

    @property
    def mask(self) -> int:
        """The raw value's bits: 2**length - 1."""
        return (1 << self.length) - 1

    def payload(self, raw: int) -> bytes:
        """The 8 payload bytes with this signal at raw value `raw` and every other bit zero."""
        word = (raw & self.mask) << self.shift
        return word.to_bytes(8, "big" if self.big_endian else "little")

    def raw(self, little: np.ndarray, big: np.ndarray) -> np.ndarray:
        """Raw values (int64, uint64 for unsigned 64-bit, float for IEEE signals) from the
        payloads as little- and big-endian uint64 words."""
        import numpy as np

        word = big if self.big_endian else little
        bits = (word >> np.uint64(self.shift)) & np.uint64(self.mask)
        if self.is_float:
            if self.length == 32:
                return bits.astype(np.uint32).view(np.float32).astype(np.float64)
            return bits.view(np.float64)
        if self.length == 64:
            return bits.view(np.int64) if self.signed else bits
        raw = bits.astype(np.int64)
        if self.signed:
            raw -= (raw >> (self.length - 1)) << self.length
        return raw

    def scaled(self, raw: np.ndarray) -> np.ndarray:
        """Physical values, computed as cantools does: raw * scale + offset.

        Integer scale and offset keep integers exact (as cantools does); past 52 bits that
        needs Python integers."""
        import numpy as np

        if isinstance(self.scale, int) and isinstance(self.offset, int) and not self.is_float:
            if self.length <= 52:
                return raw.astype(np.int64) * self.scale + self.offset
            return np.array([r * self.scale + self.offset for r in raw.tolist()], dtype=object)
        return raw.astype(np.float64) * self.scale + self.offset

    def place(self, values: np.ndarray) -> np.ndarray:
        """Physical values as raw values (rounded as cantools rounds, two's complement) at
        their bit position in the uint64 word."""
        import numpy as np

        raw = np.round((np.asarray(values, dtype=np.float64) - self.offset) / self.scale)
        bits = raw.astype(np.int64).view(np.uint64) & np.uint64(self.mask)
        return bits << np.uint64(self.shift)


class Reason(StrEnum):
    """Stand refusal reasons: the texts of the REASON value table in the shipped DBC."""

    DIRECTION = "direction out of stand limits"
    AMPLITUDE = "amplitude out of stand limits"
    PERIOD = "period out of stand limits"
    NOT_CONFIGURED = "not configured: send set first"
    BUSY = "busy: stop rocking first"
    FAULT = "stand fault"


ACCEPTED_REASON_TEXT = "accepted"  # REASON value-table text meaning "no refusal"


@dataclass(frozen=True)
class HeadingFrame:
    stand_time_ms: int
    heading_deg: float
    valid: bool
    counter: int


@dataclass(frozen=True)
class StandStatusFrame:
    """What the stand MEASURES it is doing (amplitude 0 and period 0 when not rocking)."""

    stand_time_ms: int
    rocking: bool
    direction_deg: float
    amplitude_cm: float
    period_s: float
    cycle: int
    phase_deg: float


@dataclass(frozen=True)
class AckFrame:
    command: str
    accepted: bool
    reason: str
    seq: int = 0
    stand_time_ms: int = 0


@dataclass(frozen=True)
class CompassStatusFrame:
    rotor_running: bool
    fluid_temp_c: float
    fault_bits: int


@dataclass(frozen=True)
class CommandFrame:
    """A stand command as the stand receives it (direction/amplitude/period used by "set")."""

    command: str
    seq: int
    direction_deg: float
    amplitude_cm: float
    period_s: float


@dataclass(frozen=True)
class ClockFrame:
    """SIM_CLOCK: the simulation's clock in virtual time (`stand.virtual_time`)."""

    stand_time_ms: int


@dataclass(frozen=True)
class InvalidFrame:
    arbitration_id: int
    reason: str
    raw: bytes


Frame = (
    HeadingFrame
    | StandStatusFrame
    | AckFrame
    | CompassStatusFrame
    | CommandFrame
    | ClockFrame
    | InvalidFrame
)


@dataclass(frozen=True)
class SignalRef:
    """One signal of one DBC message, written `MESSAGE.SIGNAL` in plans."""

    message: str
    signal: str

    @classmethod
    def parse(cls, text: str) -> SignalRef:
        message, dot, signal = text.strip().partition(".")
        if not dot or not message or not signal or "." in signal:
            raise ValueError(f"expected MESSAGE.SIGNAL, got {text!r}")
        return cls(message, signal)

    def __str__(self) -> str:
        return f"{self.message}.{self.signal}"


HEADING_KEYS = ("heading", "heading_time", "heading_counter", "heading_valid", "heading_crc")
_COMMAND_KEYS = (
    "command_code",
    "command_seq",
    "command_direction",
    "command_amplitude",
    "command_period",
)
_ACK_KEYS = ("ack_command", "ack_seq", "ack_accepted", "ack_reason", "ack_time")
_COMPASS_KEYS = ("compass_rotor", "compass_temp", "compass_faults")
STATUS_KEYS = (
    "status_time",
    "status_rocking",
    "status_direction",
    "status_amplitude",
    "status_period",
    "status_cycle",
    "status_phase",
)
_OPTIONAL = frozenset({"heading_valid", "heading_crc", "command_seq", "ack_seq", "ack_time"})


def _ref(text: str) -> SignalRef:
    return SignalRef.parse(text)


@dataclass(frozen=True)
class SignalMap:
    """Which DBC message/signal carries each quantity. Optional entries may be None.

    The heading entries must share one message (it carries its own stand time); the stand status
    is emitted when the message carrying `status_time` arrives, with the latest values of the
    other status entries (which may sit in other messages, as STAND_MOTION does here)."""

    heading: SignalRef = _ref("GYRO_HEADING.HEADING")
    heading_time: SignalRef = _ref("GYRO_HEADING.STAND_TIME")
    heading_counter: SignalRef = _ref("GYRO_HEADING.COUNTER")
    heading_valid: SignalRef | None = _ref("GYRO_HEADING.VALID")
    heading_crc: SignalRef | None = _ref("GYRO_HEADING.CRC")
    status_time: SignalRef = _ref("STAND_STATUS.STAND_TIME")
    status_rocking: SignalRef = _ref("STAND_STATUS.ROCKING")
    status_cycle: SignalRef = _ref("STAND_STATUS.CYCLE")
    status_phase: SignalRef = _ref("STAND_STATUS.PHASE")
    status_direction: SignalRef = _ref("STAND_MOTION.DIRECTION")
    status_amplitude: SignalRef = _ref("STAND_MOTION.AMPLITUDE")
    status_period: SignalRef = _ref("STAND_MOTION.PERIOD")
    command_code: SignalRef = _ref("STAND_COMMAND.COMMAND")
    command_seq: SignalRef | None = _ref("STAND_COMMAND.SEQ")
    command_direction: SignalRef = _ref("STAND_COMMAND.DIRECTION")
    command_amplitude: SignalRef = _ref("STAND_COMMAND.AMPLITUDE")
    command_period: SignalRef = _ref("STAND_COMMAND.PERIOD")
    ack_command: SignalRef = _ref("STAND_ACK.COMMAND")
    ack_seq: SignalRef | None = _ref("STAND_ACK.SEQ")
    ack_accepted: SignalRef = _ref("STAND_ACK.ACCEPTED")
    ack_reason: SignalRef = _ref("STAND_ACK.REASON")
    ack_time: SignalRef | None = _ref("STAND_ACK.STAND_TIME")
    compass_rotor: SignalRef = _ref("GYRO_STATUS.ROTOR_RUNNING")
    compass_temp: SignalRef = _ref("GYRO_STATUS.FLUID_TEMP")
    compass_faults: SignalRef = _ref("GYRO_STATUS.FAULT_BITS")

    @classmethod
    def default(cls) -> SignalMap:
        """The map matching the shipped DBC."""
        return cls()

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, object]) -> SignalMap:
        """Override the defaults from a plan's `[signals]` table: key = "MESSAGE.SIGNAL".

        An optional entry may be "" (the lab's DBC has no such signal)."""
        known = {f.name: f for f in fields(cls)}
        values: dict[str, SignalRef | None] = {}
        for key, value in mapping.items():
            if key not in known:
                raise ProtocolError(
                    f"signals: unknown key {key!r} (known: {', '.join(sorted(known))})"
                )
            if not isinstance(value, str):
                raise ProtocolError(f'signals.{key}: expected a "MESSAGE.SIGNAL" string')
            if value == "" and key in _OPTIONAL:
                values[key] = None
                continue
            try:
                values[key] = SignalRef.parse(value)
            except ValueError as exc:
                raise ProtocolError(f"signals.{key}: {exc}") from None
        return cls(**values)  # type: ignore[arg-type]


@dataclass(frozen=True)
class _Bound:
    """A resolved signal map entry with its DBC range (physical, `signal_bounds`, for decoding;
    raw, for encoding)."""

    key: str
    ref: SignalRef
    message: DbcMessage
    signal: Signal
    low: float
    high: float
    raw_low: float
    raw_high: float

    @classmethod
    def of(cls, key: str, ref: SignalRef, message: DbcMessage, signal: Signal) -> _Bound:
        low, high = signal_bounds(signal)
        raw_low, raw_high = sorted(
            ((low - signal.offset) / signal.scale, (high - signal.offset) / signal.scale)
        )
        return cls(key, ref, message, signal, low, high, raw_low, raw_high)

    def check(self, value: float) -> None:
        """Refuse a value whose encoded (rounded) value falls outside the DBC range."""
        try:
            raw = round((value - self.signal.offset) / self.signal.scale)
        except (ValueError, OverflowError):
            raise ProtocolError(f"{self.ref} = {value} is not a finite number") from None
        if not self.raw_low <= raw <= self.raw_high:
            unit = f" {self.signal.unit}" if self.signal.unit else ""
            raise ProtocolError(
                f"{self.ref} = {value} is outside the allowed range "
                f"[{self.signal.minimum}, {self.signal.maximum}]{unit}"
            )


class Codec:
    """Encode and decode gyrostand frames with cantools according to a DBC and a signal map.

    Decoding keeps the latest parts of a stand status (they may span messages), so give each
    receiving thread its own Codec."""

    def __init__(self, dbc_path: Path = DBC_PATH, signal_map: SignalMap | None = None) -> None:
        try:
            self._db = load_dbc(dbc_path)
        except (OSError, ValueError, cantools.database.UnsupportedDatabaseFormatError) as exc:
            # ValueError: a file name cantools cannot tell the format of, a text it cannot decode
            raise ProtocolError(f"cannot load DBC {dbc_path}: {exc}") from None
        self.dbc_path = dbc_path
        self.signal_map = signal_map or SignalMap.default()
        self._bound: dict[str, _Bound] = {}
        for f in fields(self.signal_map):
            ref = getattr(self.signal_map, f.name)
            if ref is not None:
                self._bound[f.name] = self._resolve(f.name, ref)
        self._heading = self._one_message("heading", HEADING_KEYS)
        self._command = self._one_message("command", _COMMAND_KEYS)
        self._ack = self._one_message("ack", _ACK_KEYS)
        self._compass = self._one_message("compass", _COMPASS_KEYS)
        self._status_keys = [k for k in STATUS_KEYS if k in self._bound]
        status_messages = {self._bound[k].message.frame_id for k in self._status_keys}
        if self._heading.frame_id in status_messages:
            raise ProtocolError("signals: the heading message cannot also carry stand status")
        self._status_trigger = self._bound["status_time"].message.frame_id
        self._status_cache: dict[str, float] = {}
        self._crc: SignalLayout | None = None
        self._crc_keep = 0  # the payload bits outside the CRC signal
        crc = self._bound.get("heading_crc")
        if crc is not None:
            self._crc = SignalLayout.of(crc.signal)
            ones = self._crc.payload(self._crc.mask)[: crc.message.length]
            self._crc_keep = ~int.from_bytes(ones, "little")
        # physical value of raw 0 for every signal: the filler for signals a frame does not set
        self._zero = {m.name: {s.name: s.offset for s in m.signals} for m in self._db.messages}
        self._decoders = {
            self._heading.frame_id: self._decode_heading,
            self._command.frame_id: self._decode_command,
            self._ack.frame_id: self._decode_ack,
            self._compass.frame_id: self._decode_compass,
        }
        for frame_id in status_messages:
            self._decoders[frame_id] = self._decode_status

    @classmethod
    def of(cls, dbc_path: str | Path | None, signals: Mapping[str, object]) -> Codec:
        """The codec of a DBC (None: the shipped one) and a `[signals]` table as plans write it
        (the acquisition's and the simulated stand's one reading of a lab's message layout)."""
        return cls(Path(dbc_path) if dbc_path else DBC_PATH, SignalMap.from_mapping(signals))

    # ----------------------------------------------------------------------------- set-up helpers
    def _resolve(self, key: str, ref: SignalRef) -> _Bound:
        try:
            message = self._db.get_message_by_name(ref.message)
        except KeyError:
            raise ProtocolError(f"signals.{key}: no message {ref.message!r} in the DBC") from None
        try:
            signal = message.get_signal_by_name(ref.signal)
        except KeyError:
            raise ProtocolError(
                f"signals.{key}: message {ref.message} has no signal {ref.signal!r}"
            ) from None
        return _Bound.of(key, ref, message, signal)

    def _one_message(self, group: str, keys: tuple[str, ...]) -> DbcMessage:
        messages = {self._bound[k].message.name for k in keys if k in self._bound}
        if len(messages) != 1:
            raise ProtocolError(
                f"signals: the {group} entries must share one message, got {sorted(messages)}"
            )
        return self._bound[keys[0]].message

    @property
    def heading_arbitration_id(self) -> int:
        return self._heading.frame_id

    @property
    def command_arbitration_id(self) -> int:
        return self._command.frame_id

    @property
    def ack_arbitration_id(self) -> int:
        return self._ack.frame_id

    @property
    def status_arbitration_ids(self) -> frozenset[int]:
        """The messages that make up a stand status."""
        return frozenset(self._bound[k].message.frame_id for k in self._status_keys)

    def layout(self, keys: Iterable[str]) -> list[tuple[DbcMessage, dict[str, Signal]]]:
        """The DBC messages carrying the given map entries, each with its signals by key
        (for batch encoding); the message completing a stand status comes last."""
        groups: dict[str, tuple[DbcMessage, dict[str, Signal]]] = {}
        for key in keys:
            bound = self._bound.get(key)
            if bound is not None:
                groups.setdefault(bound.message.name, (bound.message, {}))[1][key] = bound.signal
        return sorted(groups.values(), key=lambda g: g[0].frame_id == self._status_trigger)

    @property
    def has_sequence(self) -> bool:
        """Whether commands and acks carry a sequence number (to pair an ack with its command)."""
        return "command_seq" in self._bound and "ack_seq" in self._bound

    @property
    def database(self) -> cantools.database.can.Database:
        return self._db

    # ------------------------------------------------------------------------------------ encode
    def _encode(self, values: Mapping[str, float], *, strict: bool = True) -> list[can.Message]:
        """Encode signal-map entries (key -> physical value) into one frame per DBC message."""
        by_message: dict[str, tuple[DbcMessage, dict[str, float]]] = {}
        for key, value in values.items():
            bound = self._bound.get(key)
            if bound is None:
                continue  # an optional entry this DBC does not have
            if strict:
                bound.check(value)
            entry = by_message.get(bound.message.name)
            if entry is None:
                entry = by_message[bound.message.name] = (
                    bound.message,
                    dict(self._zero[bound.message.name]),
                )
            entry[1][bound.signal.name] = value
        import can

        return [
            can.Message(
                arbitration_id=message.frame_id,
                is_extended_id=message.is_extended_frame,
                data=message.encode(data, strict=False),
            )
            for message, data in by_message.values()
        ]

    def encode_heading(
        self,
        stand_time_ms: int,
        heading_deg: float,
        valid: bool,
        counter: int,
        *,
        strict: bool = True,
    ) -> can.Message:
        """Heading frame (with its CRC when the map has one). strict=False lets the simulator put
        an out-of-range heading on the wire."""
        values = {
            "heading_time": stand_time_ms,
            "heading": heading_deg,
            "heading_valid": int(valid),
            "heading_counter": counter,
            "heading_crc": 0,
        }
        (msg,) = self._encode(values, strict=strict)
        if self._crc is not None:  # the CRC bits are still zero: OR the CRC into them
            crc_bits = self._crc.payload(self._crc_of(bytes(msg.data)))[: len(msg.data)]
            msg.data = bytearray(a | b for a, b in zip(msg.data, crc_bits, strict=True))
        return msg

    def _crc_of(self, data: bytes) -> int:
        """CRC of the payload with the CRC bits zeroed, cut to the CRC signal length."""
        assert self._crc is not None
        masked = (int.from_bytes(data, "little") & self._crc_keep).to_bytes(len(data), "little")
        return crc8_sae_j1850(masked) & self._crc.mask

    def encode_status(
        self,
        stand_time_ms: int,
        rocking: bool,
        direction_deg: float,
        amplitude_cm: float,
        period_s: float,
        cycle: int,
        phase_deg: float,
    ) -> list[can.Message]:
        """Stand status frames; the one carrying the stand time comes last (it completes the
        status at the receiver)."""
        msgs = self._encode(
            {
                "status_time": stand_time_ms,
                "status_rocking": int(rocking),
                "status_direction": direction_deg,
                "status_amplitude": amplitude_cm,
                "status_period": period_s,
                "status_cycle": cycle,
                "status_phase": phase_deg,
            }
        )
        return sorted(msgs, key=lambda m: m.arbitration_id == self._status_trigger)

    def _command_msg(
        self, command: str, seq: int, direction_deg: float, amplitude_cm: float, period_s: float
    ) -> can.Message:
        values = {
            "command_code": _choice_code(self._bound["command_code"], command),
            "command_seq": seq,
            "command_direction": direction_deg,
            "command_amplitude": amplitude_cm,
            "command_period": period_s,
        }
        (msg,) = self._encode(values)
        return msg

    def encode_command(
        self,
        name: str,
        direction_deg: float = 0.0,
        amplitude_cm: float = 0.0,
        period_s: float = 0.0,
        *,
        seq: int = 0,
    ) -> can.Message:
        """A command by name: "set" (with its motion K deg, A cm, tau s), "start" or "stop"."""
        if name not in COMMANDS:
            raise ProtocolError(f"unknown command {name!r} (one of {', '.join(COMMANDS)})")
        if name != "set":
            direction_deg = amplitude_cm = period_s = 0.0
        return self._command_msg(name, seq, direction_deg, amplitude_cm, period_s)

    def encode_command_set(
        self, direction_deg: float, amplitude_cm: float, period_s: float, *, seq: int = 0
    ) -> can.Message:
        return self._command_msg("set", seq, direction_deg, amplitude_cm, period_s)

    def encode_command_start(self, *, seq: int = 0) -> can.Message:
        return self._command_msg("start", seq, 0.0, 0.0, 0.0)

    def encode_command_stop(self, *, seq: int = 0) -> can.Message:
        return self._command_msg("stop", seq, 0.0, 0.0, 0.0)

    def encode_ack(
        self,
        command: str,
        accepted: bool,
        reason: str = "",
        *,
        seq: int = 0,
        stand_time_ms: int = 0,
    ) -> can.Message:
        """Acknowledgement (accepted, reason "") or refusal (reason from the REASON value table)."""
        if accepted and reason:
            raise ProtocolError("an accepted command carries no refusal reason")
        if not accepted and not reason:
            raise ProtocolError("a refusal needs a reason")
        reason_bound = self._bound["ack_reason"]
        (msg,) = self._encode(
            {
                "ack_command": _choice_code(self._bound["ack_command"], command),
                "ack_seq": seq,
                "ack_accepted": int(accepted),
                "ack_reason": _choice_code(reason_bound, reason or ACCEPTED_REASON_TEXT),
                "ack_time": stand_time_ms,
            }
        )
        return msg

    def encode_compass_status(
        self, rotor_running: bool, fluid_temp_c: float, fault_bits: int
    ) -> can.Message:
        (msg,) = self._encode(
            {
                "compass_rotor": int(rotor_running),
                "compass_temp": fluid_temp_c,
                "compass_faults": fault_bits,
            }
        )
        return msg

    # ------------------------------------------------------------------------------------ decode
    def decode(self, msg: can.Message) -> Frame | None:
        """Decode one frame; None for IDs the protocol does not use (and for a status part that
        waits for the rest of its status). Never raises: bad frames become InvalidFrame."""
        raw = bytes(msg.data)
        if msg.is_error_frame:
            return InvalidFrame(msg.arbitration_id, "error frame", raw)
        decoder = self._decoders.get(msg.arbitration_id)
        if decoder is None:
            return None
        if msg.is_remote_frame:
            return InvalidFrame(msg.arbitration_id, "remote frame", raw)
        try:
            return decoder(msg.arbitration_id, raw)
        except _Invalid as exc:
            return InvalidFrame(msg.arbitration_id, str(exc), raw)
        except Exception as exc:  # a corrupt frame must never kill the receiving thread
            return InvalidFrame(msg.arbitration_id, f"undecodable payload: {exc}", raw)

    def _values(
        self, frame_id: int, raw: bytes, keys: Sequence[str], *, check_range: bool = True
    ) -> dict[str, float]:
        """Physical values of the given map entries from one frame, range-checked."""
        message = self._db.get_message_by_frame_id(frame_id)
        if len(raw) != message.length:
            raise _Invalid(f"wrong length: {len(raw)} bytes, {message.name} has {message.length}")
        decoded = message.decode(raw, decode_choices=False)
        out: dict[str, float] = {}
        for key in keys:
            bound = self._bound.get(key)
            if bound is None or bound.message is not message:
                continue
            value = decoded[bound.signal.name]
            if check_range and not bound.low <= value <= bound.high:
                raise _Invalid(
                    f"{bound.ref} = {value} outside [{bound.signal.minimum}, "
                    f"{bound.signal.maximum}]"
                )
            out[key] = value
        return out

    def _decode_heading(self, frame_id: int, raw: bytes) -> HeadingFrame:
        if self._crc is not None:  # first: a payload failing its CRC is corrupt, whatever it reads
            crc = self._values(frame_id, raw, ("heading_crc",), check_range=False)["heading_crc"]
            if crc != self._crc_of(raw):
                raise _Invalid("CRC mismatch: corrupt payload")
        v = self._values(frame_id, raw, HEADING_KEYS)
        return HeadingFrame(
            stand_time_ms=int(v["heading_time"]),
            heading_deg=float(v["heading"]),
            valid=bool(v.get("heading_valid", 1)),
            counter=int(v["heading_counter"]),
        )

    def _decode_status(self, frame_id: int, raw: bytes) -> StandStatusFrame | None:
        self._status_cache.update(self._values(frame_id, raw, self._status_keys))
        if frame_id != self._status_trigger or len(self._status_cache) < len(self._status_keys):
            return None
        v = self._status_cache
        return StandStatusFrame(
            stand_time_ms=int(v["status_time"]),
            rocking=bool(v["status_rocking"]),
            direction_deg=float(v["status_direction"]),
            amplitude_cm=float(v["status_amplitude"]),
            period_s=float(v["status_period"]),
            cycle=int(v["status_cycle"]),
            phase_deg=float(v["status_phase"]),
        )

    def _decode_command(self, frame_id: int, raw: bytes) -> CommandFrame:
        v = self._values(frame_id, raw, _COMMAND_KEYS)
        return CommandFrame(
            command=_choice_name(self._bound["command_code"], v["command_code"], COMMANDS),
            seq=int(v.get("command_seq", 0)),
            direction_deg=float(v["command_direction"]),
            amplitude_cm=float(v["command_amplitude"]),
            period_s=float(v["command_period"]),
        )

    def _decode_ack(self, frame_id: int, raw: bytes) -> AckFrame:
        v = self._values(frame_id, raw, _ACK_KEYS)
        reason_bound = self._bound["ack_reason"]
        choices = reason_bound.signal.choices or {}
        code = int(v["ack_reason"])
        reason = str(choices[code]) if code in choices else f"reason code {code}"
        accepted = bool(v["ack_accepted"])
        return AckFrame(
            command=_choice_name(self._bound["ack_command"], v["ack_command"], COMMANDS),
            accepted=accepted,
            reason="" if accepted else reason,
            seq=int(v.get("ack_seq", 0)),
            stand_time_ms=int(v.get("ack_time", 0)),
        )

    def _decode_compass(self, frame_id: int, raw: bytes) -> CompassStatusFrame:
        v = self._values(frame_id, raw, _COMPASS_KEYS)
        return CompassStatusFrame(
            rotor_running=bool(v["compass_rotor"]),
            fluid_temp_c=float(v["compass_temp"]),
            fault_bits=int(v["compass_faults"]),
        )


class _Invalid(Exception):
    """Internal: the frame is invalid for the given reason."""


def _choice_code(bound: _Bound, name: str) -> int:
    for code, text in (bound.signal.choices or {}).items():
        if str(text) == name:
            return int(code)
    known = ", ".join(repr(str(t)) for t in (bound.signal.choices or {}).values())
    raise ProtocolError(f"{bound.ref}: {name!r} is not one of the DBC values ({known})")


def _choice_name(bound: _Bound, code: float, allowed: tuple[str, ...]) -> str:
    name = str((bound.signal.choices or {}).get(int(code), ""))
    if name not in allowed:
        raise _Invalid(f"{bound.ref}: unknown command code {int(code)}")
    return name
