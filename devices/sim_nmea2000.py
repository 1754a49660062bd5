"""The simulated compass speaking NMEA 2000: the stand simulator's heading samples (the same
physics, `stand.physics`) sent as PGN 127250 Vessel Heading, 127251 Rate of Turn and 127257
Attitude at the heading rate, after an ISO address claim (PGN 60928) and the product information
(PGN 126996, fast-packet), which it sends again when an ISO Request (PGN 59904) asks for it, as
a real device does; another device claiming its address with a lower NAME makes it claim
`new_address` (ISO 11783-5 address arbitration). Frames carry the stand time of their sample as
their timestamp: in virtual time that is their reception time, so runs are byte-reproducible.

Fault knobs (`Nmea2000Faults`): an address change at a stand time (a new claim, then the same
NAME sends from the new address), "not available" headings at a rate, no SID (255); silence and
dropped samples come from the stand's own fault knobs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import can
import numpy as np

from gyrostand.devices.nmea2000 import (
    ADDRESS_CLAIM,
    ATTITUDE,
    PRODUCT_INFORMATION,
    RATE_OF_TURN,
    SID_MODULO,
    VESSEL_HEADING,
    Product,
    ReferenceEncoder,
    can_id,
    encode_attitude,
    encode_rate_of_turn,
    encode_vessel_heading,
    iso_name,
    requested_pgn,
    split_id,
)

PRIORITY = {VESSEL_HEADING: 2, RATE_OF_TURN: 2, ATTITUDE: 3}  # canboat's default priorities


@dataclass(frozen=True)
class Nmea2000Faults:
    address_change_at_s: float | None = None  # stand time of a new address claim
    new_address: int = 36  # claimed then, or on losing its address to a lower NAME
    not_available_rate: float = 0.0  # probability that a 127250 heading is 0xFFFF
    no_sid: bool = False  # SID 255 in every frame


@dataclass(frozen=True)
class Nmea2000Device:
    """Who the simulated compass is on the bus."""

    product: Product
    name: int = iso_name(4242)  # ISO 11783-5 NAME
    address: int = 35


def simulated_compass(
    model: str, serial: str, name: str | None = None, seed: int = 0
) -> Nmea2000Compass:
    """The simulated compass of a plan: its [instrument] in the product information, the
    [compass] name when the plan gives one."""
    device = Nmea2000Device(Product(model, serial, "1.0"))
    if name is not None:
        device = Nmea2000Device(device.product, int(name, 16))
    return Nmea2000Compass(device, seed=seed)


class Nmea2000Compass:
    """A `stand.engine.HeadingTransmitter`: heading samples -> NMEA 2000 frames."""

    def __init__(
        self, device: Nmea2000Device, faults: Nmea2000Faults | None = None, seed: int = 0
    ) -> None:
        self.device = device
        self.faults = faults or Nmea2000Faults()
        self.address = device.address
        self._reference = ReferenceEncoder()
        self._rng = np.random.default_rng(seed)
        self._claimed = False
        self._last: tuple[float, float] | None = None  # (t s, heading rad) of the last sample

    def _announce(self, t_s: float) -> list[can.Message]:
        """Address claim and product information from the current address."""
        frames = self._reference.address_claim(self.device.name, self.address, t_s)
        return frames + self._reference.product_information(self.device.product, self.address, t_s)

    def answers(self, msg: can.Message) -> bool:
        """Whether `msg` is a request this device answers (address claim, product information,
        to its address or to all) or another device's claim of its address."""
        asked = requested_pgn(msg, self.address) in (ADDRESS_CLAIM, PRODUCT_INFORMATION)
        return asked or self._contender(msg) is not None

    def _contender(self, msg: can.Message) -> int | None:
        """The NAME of another device claiming this device's address."""
        if not msg.is_extended_id or msg.is_error_frame or len(msg.data) != 8:
            return None
        (pgn,), (source,) = split_id(np.array([msg.arbitration_id]))
        name = int.from_bytes(bytes(msg.data), "little")
        if pgn != ADDRESS_CLAIM or source != self.address or name == self.device.name:
            return None
        return name

    def answer(self, msg: can.Message, t_s: float) -> list[can.Message]:
        """The answer (`answers`) at stand time `t_s`: to a request, what it asks for; to a
        claim of its address, its own claim (ISO 11783-5: the lower NAME keeps the address, the
        other claims another one, here `Nmea2000Faults.new_address`)."""
        other = self._contender(msg)
        pgn = ADDRESS_CLAIM if other is not None else requested_pgn(msg, self.address)
        if other is not None and other < self.device.name:
            self.address = self.faults.new_address
        if pgn == ADDRESS_CLAIM:
            return self._reference.address_claim(self.device.name, self.address, t_s)
        if pgn == PRODUCT_INFORMATION:
            return self._reference.product_information(self.device.product, self.address, t_s)
        return []

    def frames(
        self, t_s: np.ndarray, reading_deg: np.ndarray, index: np.ndarray
    ) -> list[can.Message]:
        out: list[can.Message] = []
        change = self.faults.address_change_at_s
        if change is not None and self.address != self.faults.new_address and len(t_s):
            cut = int(np.searchsorted(t_s, change - 1e-9))
            if cut < len(t_s):
                out += self._samples(t_s[:cut], reading_deg[:cut], index[:cut])
                self.address = self.faults.new_address
                out += self._announce(float(t_s[cut]))
                t_s, reading_deg, index = t_s[cut:], reading_deg[cut:], index[cut:]
        return out + self._samples(t_s, reading_deg, index)

    def _samples(
        self, t_s: np.ndarray, reading_deg: np.ndarray, index: np.ndarray
    ) -> list[can.Message]:
        n = len(t_s)
        if n == 0:
            return []
        out = [] if self._claimed else self._announce(float(t_s[0]))
        self._claimed = True
        heading = np.radians(reading_deg)
        # rate of turn: the change since the previous sample (the first: none)
        prev_t = np.concatenate(([np.nan], t_s[:-1]))
        prev_h = np.concatenate(([np.nan], heading[:-1]))
        if self._last is not None:
            prev_t[0], prev_h[0] = self._last
        self._last = (float(t_s[-1]), float(heading[-1]))
        turn = (heading - prev_h + math.pi) % (2 * math.pi) - math.pi
        rate = np.nan_to_num(turn / (t_s - prev_t))
        sid = np.full(n, 255) if self.faults.no_sid else index % SID_MODULO
        na = self._rng.random(n) < self.faults.not_available_rate
        payloads = {
            VESSEL_HEADING: encode_vessel_heading(sid, np.where(na, np.nan, heading)),
            RATE_OF_TURN: encode_rate_of_turn(sid, rate),
            ATTITUDE: encode_attitude(
                sid, np.stack((heading, np.full(n, np.nan), np.full(n, np.nan)), axis=1)
            ),
        }
        ids = {pgn: can_id(pgn, self.address, PRIORITY[pgn]) for pgn in payloads}
        rows = [payloads[pgn].tobytes() for pgn in payloads]
        for i, t in enumerate(t_s.tolist()):
            for k, pgn in enumerate(payloads):
                out.append(
                    can.Message(
                        timestamp=t,
                        arbitration_id=ids[pgn],
                        is_extended_id=True,
                        data=rows[k][8 * i : 8 * i + 8],
                    )
                )
        return out
