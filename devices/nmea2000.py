"""NMEA 2000 (IEC 61162-3) on CAN: 29-bit identifiers and the PGNs of a heading sensor.

The heading PGNs, nearly all of the compass's traffic, are read and written here with numpy
(single 8-byte frames at fixed offsets, little-endian); the rare ones (ISO address claim,
product information, a fast-packet PGN) go through the `nmea2000` package (canboat), the
reference codec our bulk reading is tested against. Layouts (canboat's PGN database):

- 127250 Vessel Heading: SID u8, heading u16 x 1e-4 rad, deviation s16 x 1e-4 rad, variation
  s16 x 1e-4 rad, reference 2 bits (0 true, 1 magnetic), 6 reserved bits;
- 127251 Rate of Turn: SID u8, rate s32 x 3.125e-8 rad/s, 3 reserved bytes;
- 127257 Attitude: SID u8, yaw, pitch, roll s16 x 1e-4 rad, 1 reserved byte;
- 59904 ISO Request (ISO 11783-3): the requested PGN, u24, to one address or to all (255).

"Not available" is a field's all-ones value; canboat reads the top three values of an unsigned
field (0xFFFD error, 0xFFFE reserved, 0xFFFF no data), and of a signed one (0x7FFD..0x7FFF),
as no value. A SID of 255 means no sequence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import can
import numpy as np
from nmea2000 import NMEA2000Decoder, NMEA2000Field, NMEA2000Message, create_encoder
from nmea2000.input_formats import N2KFormat

VESSEL_HEADING = 127250
RATE_OF_TURN = 127251
ATTITUDE = 127257
ADDRESS_CLAIM = 60928
PRODUCT_INFORMATION = 126996
ISO_REQUEST = 59904
NULL_ADDRESS = 254  # ISO 11783-5: a device without an address may send a request for claims
ANGLE_RAD = 1e-4  # 127250 / 127257 angle fields, rad per bit
RATE_RAD_S = 3.125e-8  # 127251 rate, rad/s per bit
RESOLUTION_DEG = math.degrees(ANGLE_RAD)  # 0.0057 deg
MAX_HEADING_RAW = 62831  # 2 pi / 1e-4 rad, rounded down
U16_NO_VALUE = 0xFFFD  # from here up: error, reserved, not available
S16_NO_VALUE = 0x7FFD
SID_MODULO = 253  # SID 0-252; 253-255 read as no value (255: no sequence)
BROADCAST = 255


def split_id(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(PGN, source address) of 29-bit identifiers (ISO 11783-3: priority 3 bits, EDP, DP, PF,
    PS, SA; PS is a destination, not part of the PGN, when PF < 240)."""
    ids = ids.astype(np.int64)
    pf = (ids >> 16) & 0xFF
    pgn = ((ids >> 24) & 0x3) << 16 | pf << 8 | np.where(pf >= 240, (ids >> 8) & 0xFF, 0)
    return pgn, ids & 0xFF


def can_id(pgn: int, source: int, priority: int, destination: int = BROADCAST) -> int:
    """The 29-bit identifier of a PGN sent by `source` (to `destination` when PDU1)."""
    ps = pgn & 0xFF if (pgn >> 8) & 0xFF >= 240 else destination
    return priority << 26 | (pgn >> 8) << 16 | ps << 8 | source


def iso_requests(pgns: tuple[int, ...] = (ADDRESS_CLAIM, PRODUCT_INFORMATION)) -> list[can.Message]:
    """ISO Requests (PGN 59904, 3 bytes: the PGN) from the null address to every device: the
    one transmission gyrostand makes on an NMEA 2000 bus (ISO 11783-5 lets a device that has
    claimed no address request the address claims)."""
    return [
        can.Message(
            arbitration_id=can_id(ISO_REQUEST, NULL_ADDRESS, 6),
            is_extended_id=True,
            data=pgn.to_bytes(3, "little"),
        )
        for pgn in pgns
    ]


def requested_pgn(msg: can.Message, address: int) -> int | None:
    """The PGN an ISO Request to `address` (or to all) asks for; None for any other frame."""
    ident = msg.arbitration_id
    if not msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame or len(msg.data) < 3:
        return None
    if (ident >> 8) & 0x3FF00 != ISO_REQUEST or (ident >> 8) & 0xFF not in (address, BROADCAST):
        return None
    return int.from_bytes(bytes(msg.data[:3]), "little")


def _u16(data: np.ndarray, at: int) -> np.ndarray:
    return data[:, at].astype(np.int64) | data[:, at + 1].astype(np.int64) << 8


def _s16(data: np.ndarray, at: int) -> np.ndarray:
    v = _u16(data, at)
    return np.where(v >= 0x8000, v - 0x10000, v)


@dataclass(frozen=True)
class VesselHeadings:
    """PGN 127250 of n frames, raw field values."""

    sid: np.ndarray
    heading: np.ndarray  # u16
    deviation: np.ndarray  # s16
    variation: np.ndarray  # s16
    reference: np.ndarray  # 0 true, 1 magnetic, 2 error, 3 null

    def sequence(self) -> np.ndarray:
        """SID, or -1 (`devices.source.NO_SEQUENCE`) where it carries none."""
        return np.where(self.sid >= SID_MODULO, -1, self.sid)

    def heading_rad(self) -> np.ndarray:
        """Heading, rad; NaN where not available."""
        return np.where(self.heading >= U16_NO_VALUE, np.nan, self.heading * ANGLE_RAD)

    def problems(self) -> dict[int, str]:
        """Why frames give no usable heading, by row (the rows not named do)."""
        out: dict[int, str] = {}
        na = self.heading >= U16_NO_VALUE
        beyond = ~na & (self.heading > MAX_HEADING_RAW)
        for i in np.flatnonzero(self.reference != 0).tolist():
            kind = ("magnetic", "error", "null")[int(self.reference[i]) - 1]
            out[i] = f"PGN 127250 heading reference {kind}, not true"
        for i in np.flatnonzero(beyond).tolist():
            rad = int(self.heading[i]) * ANGLE_RAD
            out[i] = f"PGN 127250 heading {rad:.4f} rad outside [0, 2 pi]"
        for i in np.flatnonzero(na).tolist():
            out[i] = "PGN 127250 heading not available"
        return out


def decode_vessel_heading(data: np.ndarray) -> VesselHeadings:
    """PGN 127250 from (n, 8) payloads."""
    return VesselHeadings(
        sid=data[:, 0].astype(np.int64),
        heading=_u16(data, 1),
        deviation=_s16(data, 3),
        variation=_s16(data, 5),
        reference=(data[:, 7] & 0x3).astype(np.int64),
    )


def encode_vessel_heading(sid: np.ndarray, heading_rad: np.ndarray) -> np.ndarray:
    """(n, 8) payloads of PGN 127250: true heading (NaN: not available), deviation and
    variation not available."""
    n = len(sid)
    raw = np.round(np.mod(np.nan_to_num(heading_rad), 2 * math.pi) / ANGLE_RAD).astype(np.int64)
    raw = np.where(raw > MAX_HEADING_RAW, 0, raw)  # 2 pi rounds up to 0
    raw = np.where(np.isnan(heading_rad), 0xFFFF, raw)
    data = np.empty((n, 8), dtype=np.uint8)
    data[:, 0] = sid
    data[:, 1], data[:, 2] = raw & 0xFF, raw >> 8
    data[:, 3:7] = (0xFF, 0x7F, 0xFF, 0x7F)
    data[:, 7] = 0xFC  # reference true (0), reserved bits set
    return data


def decode_rate_of_turn(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(SID, rate rad/s; NaN not available) of PGN 127251 payloads."""
    v = (_u16(data, 1) | _u16(data, 3) << 16).astype(np.int64)
    v = np.where(v >= 0x80000000, v - 0x100000000, v)
    return data[:, 0].astype(np.int64), np.where(v >= 0x7FFFFFFD, np.nan, v * RATE_RAD_S)


def encode_rate_of_turn(sid: np.ndarray, rate_rad_s: np.ndarray) -> np.ndarray:
    raw = np.round(rate_rad_s / RATE_RAD_S).astype(np.int64) & 0xFFFFFFFF
    data = np.full((len(sid), 8), 0xFF, dtype=np.uint8)
    data[:, 0] = sid
    for k in range(4):
        data[:, 1 + k] = (raw >> (8 * k)) & 0xFF
    return data


def decode_attitude(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(SID, (n, 3) yaw, pitch, roll rad; NaN not available) of PGN 127257 payloads."""
    angles = np.stack([_s16(data, at) for at in (1, 3, 5)], axis=1)
    return data[:, 0].astype(np.int64), np.where(angles >= S16_NO_VALUE, np.nan, angles * ANGLE_RAD)


def encode_attitude(sid: np.ndarray, ypr_rad: np.ndarray) -> np.ndarray:
    """PGN 127257 payloads from (n, 3) yaw, pitch, roll (NaN: not available)."""
    raw = np.round(np.nan_to_num(ypr_rad) / ANGLE_RAD).astype(np.int64)
    raw = np.where(np.isnan(ypr_rad), 0x7FFF, raw) & 0xFFFF
    data = np.full((len(sid), 8), 0xFF, dtype=np.uint8)
    data[:, 0] = sid
    for k in range(3):
        data[:, 1 + 2 * k], data[:, 2 + 2 * k] = raw[:, k] & 0xFF, raw[:, k] >> 8
    return data


# ---------------------------------------------------------------- the rare PGNs: reference codec
@dataclass(frozen=True)
class Product:
    """What PGN 126996 tells of a device."""

    model: str
    serial: str
    software: str


class ReferenceDecoder:
    """Address claims and product information (fast-packet, reassembled per source) by the
    `nmea2000` package; one frame at a time, never raising."""

    def __init__(self) -> None:
        self._decoder = NMEA2000Decoder(include_pgns=[ADDRESS_CLAIM, PRODUCT_INFORMATION])

    def decode(self, msg: can.Message) -> int | Product | None:
        """The NAME of an address claim, the product of a complete 126996, else None."""
        try:
            decoded = self._decoder.decode(msg)
        except Exception:  # a malformed frame of a rare PGN: nothing to learn from it
            return None
        if decoded is None:
            return None
        if decoded.PGN == ADDRESS_CLAIM:
            return int.from_bytes(bytes(msg.data[:8]), "little")
        field = decoded.get_field_str_value_by_id
        return Product(
            (field("modelId") or "").strip(),
            (field("modelSerialCode") or "").strip(),
            (field("softwareVersionCode") or "").strip(),
        )


class ReferenceEncoder:
    """Address claim and product information frames (the simulated compass's)."""

    def __init__(self) -> None:
        self._encoder = create_encoder(N2KFormat.PYTHON_CAN)

    def _frames(self, message: NMEA2000Message, t_s: float) -> list[can.Message]:
        frames = self._encoder.encode(message)
        for frame in frames:
            frame.timestamp, frame.is_rx = t_s, True
        return frames

    def address_claim(self, name: int, source: int, t_s: float) -> list[can.Message]:
        msg = can.Message(
            arbitration_id=can_id(ADDRESS_CLAIM, source, 6),
            is_extended_id=True,
            data=name.to_bytes(8, "little"),
            timestamp=t_s,
        )
        return [msg]

    def product_information(self, product: Product, source: int, t_s: float) -> list[can.Message]:
        fields = {
            "nmea2000Version": 2.1,
            "productCode": 1,
            "modelId": product.model,
            "softwareVersionCode": product.software,
            "modelVersion": "1",
            "modelSerialCode": product.serial,
            "certificationLevel": 1,
            "loadEquivalency": 1,
        }
        message = NMEA2000Message(
            PGN=PRODUCT_INFORMATION,
            id="productInformation",
            priority=6,
            source=source,
            destination=BROADCAST,
            fields=[NMEA2000Field(k, value=v) for k, v in fields.items()],
        )
        return self._frames(message, t_s)


def iso_name(unique_number: int, manufacturer: int = 2046, function: int = 140) -> int:
    """A NAME (ISO 11783-5): unique number 21 bits, manufacturer code 11 bits, function 8 bits
    (140: ownship attitude), device class 60 (navigation), industry group 4 (marine), arbitrary
    address capable."""
    return (
        unique_number & 0x1FFFFF
        | manufacturer << 21
        | function << 40
        | 60 << 49
        | 4 << 60
        | 1 << 63
    )
