"""The heading source "nmea2000": PGN 127250 of the compass, chosen by its NAME or its product
information, never by its source address (ISO 11783-5: a device may claim another address after
power-up; its NAME stays).

Listen-only but for one request: at the start of a run gyrostand asks every device for its
address claim and product information (`nmea2000.iso_requests`, `n2k_identify`), so that a
compass that claimed its address before the run is known too. The compass is known from its
address claim (PGN 60928: address ->
NAME) and its product information (PGN 126996: model, serial number). The plan names it by NAME
(`[compass] name`), or else it is the device whose product information gives `[instrument]`
model and serial number. Before it is known its 127250 frames count as invalid (with the reason);
127250 of another device is told once as an event and not used; the compass's frames with
"not available", an out-of-range heading or a reference other than true count as invalid with
their reason. Headings are timed by reception on the campaign clock (`devices.clock`).
"""

from __future__ import annotations

import numpy as np

from gyrostand.devices.clock import NO_CLOCK, TIME_BASE
from gyrostand.devices.nmea2000 import (
    ADDRESS_CLAIM,
    ATTITUDE,
    ISO_REQUEST,
    PRODUCT_INFORMATION,
    RATE_OF_TURN,
    RESOLUTION_DEG,
    VESSEL_HEADING,
    Product,
    ReferenceDecoder,
    decode_vessel_heading,
    split_id,
)
from gyrostand.devices.source import SID, CampaignClock, SourceInfo, SourceOutput
from gyrostand.frames.batch import DeviceEvent, Headings, RawFrames
from gyrostand.stand.protocol import InvalidFrame

# (ISO requests: gyrostand's own at the start of a run, other devices'; nothing to learn)
HANDLED = (
    VESSEL_HEADING,
    RATE_OF_TURN,
    ATTITUDE,
    ADDRESS_CLAIM,
    PRODUCT_INFORMATION,
    ISO_REQUEST,
)
INFO = SourceInfo("nmea2000", RESOLUTION_DEG, TIME_BASE, SID)


def name_text(name: int) -> str:
    return f"0x{name:016X}"


class Nmea2000Heading:
    """PGN 127250 of one device -> `Headings` on the campaign clock."""

    info = INFO

    def __init__(
        self,
        name: int | None = None,
        product: tuple[str, str] | None = None,
        bus: int | None = None,
    ) -> None:
        """`name`: the compass's NAME; else `product` (model, serial number) picks it; `bus`:
        the `RawFrames.channel` it is on (None: any, a one-bus stream)."""
        self.bus = bus
        if name is None and product is None:
            raise ValueError("the compass needs a NAME or a product (model, serial number)")
        self.wanted_name = name
        self.wanted_product = product
        self.compass: int | None = name  # its NAME, once known
        self._names: dict[int, int] = {}  # source address -> NAME (address claims)
        self._products: dict[int, Product] = {}  # NAME -> product information
        self._reference = ReferenceDecoder()
        self._foreign: set[tuple[int, int | None]] = set()  # (address, NAME) told
        self._compass_at: int | None = None  # the compass's address in its last claim seen

    def claims(self, raw: RawFrames) -> np.ndarray:
        """Rows that are this source's business (NMEA 2000 PGNs of a heading sensor)."""
        pgn, _ = split_id(raw.arbitration_id)
        ok = raw.is_extended & ~(raw.is_error | raw.is_remote) & raw.on_bus(self.bus)
        return ok & np.isin(pgn, HANDLED)

    def _address(self) -> int | None:
        """The compass's source address now."""
        for address, name in self._names.items():
            if name == self.compass:
                return address
        return None

    def decode(
        self, raw: RawFrames, clock: CampaignClock, claimed: np.ndarray | None = None
    ) -> SourceOutput:
        """`claimed`: `claims(raw)`, when the caller has it already."""
        claimed = self.claims(raw) if claimed is None else claimed
        pgn, source = split_id(raw.arbitration_id)
        control = np.flatnonzero(claimed & np.isin(pgn, (ADDRESS_CLAIM, PRODUCT_INFORMATION)))
        heading = claimed & (pgn == VESSEL_HEADING)
        rows: list[np.ndarray] = []  # the compass's 127250 rows
        invalid: list[tuple[int, InvalidFrame]] = []
        events: list[tuple[int, DeviceEvent]] = []
        start = 0
        for stop in [*control.tolist(), len(raw)]:
            here = np.flatnonzero(heading[start:stop]) + start
            address = self._address()
            mine = source[here] == address if address is not None else np.zeros(len(here), bool)
            rows.append(here[mine])
            for row in here[~mine].tolist():
                self._not_the_compass(raw, row, int(source[row]), invalid, events)
            if stop < len(raw):
                self._control(raw, stop, int(source[stop]), events)
            start = stop + 1
        own = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
        return SourceOutput(
            self._headings(raw, own, clock, invalid),
            tuple(sorted(invalid, key=lambda x: x[0])),
            tuple(events),
            claimed,
        )

    def _headings(
        self,
        raw: RawFrames,
        rows: np.ndarray,
        clock: CampaignClock,
        invalid: list[tuple[int, InvalidFrame]],
    ) -> Headings:
        """The compass's 127250 frames: usable ones as headings, the rest invalid."""
        decoded = decode_vessel_heading(raw.data[rows])
        problems = decoded.problems()
        pos = rows + raw.start
        t_ms = clock.to_campaign_ms(pos, raw.timestamp[rows])
        for i in np.flatnonzero(t_ms == NO_CLOCK).tolist():
            problems[i] = "PGN 127250 received before the stand's first status (no clock)"
        for i in np.flatnonzero(raw.dlc[rows] != 8).tolist():
            problems[i] = f"PGN 127250 of {int(raw.dlc[rows[i]])} bytes, not 8"
        bad = np.zeros(len(rows), dtype=bool)
        bad[list(problems)] = True
        for i, why in sorted(problems.items()):
            row = int(rows[i])
            frame = InvalidFrame(int(raw.arbitration_id[row]), why, raw.data[row].tobytes())
            invalid.append((int(pos[i]), frame))
        good = ~bad
        return Headings(
            pos=pos[good],
            t_ms=t_ms[good],
            heading_deg=np.degrees(decoded.heading_rad()[good]) % 360.0,
            valid=np.ones(int(good.sum()), dtype=bool),
            counter=decoded.sequence()[good],
        )

    def _not_the_compass(
        self,
        raw: RawFrames,
        row: int,
        address: int,
        invalid: list[tuple[int, InvalidFrame]],
        events: list[tuple[int, DeviceEvent]],
    ) -> None:
        pos = raw.start + row
        if self.compass is None or self._address() is None:
            why = "no address claim from the compass yet" if self.compass else "compass not known"
            reason = f"PGN 127250 from address {address} before the compass is identified ({why})"
            frame = InvalidFrame(int(raw.arbitration_id[row]), reason, raw.data[row].tobytes())
            invalid.append((pos, frame))
            return
        name = self._names.get(address)
        if (address, name) in self._foreign:
            return
        self._foreign.add((address, name))
        who = f"NAME {name_text(name)}" if name is not None else "no address claim seen"
        message = (
            f"another heading source on the bus: PGN 127250 from address {address} ({who}); "
            f"the compass is NAME {name_text(self.compass)} at address {self._address()}"
        )
        events.append((pos, DeviceEvent("other device", "info", message)))

    def _control(
        self, raw: RawFrames, row: int, address: int, events: list[tuple[int, DeviceEvent]]
    ) -> None:
        """An address claim or a frame of product information."""
        got = self._reference.decode(raw.message(row))
        pos = raw.start + row
        if isinstance(got, int):
            self._claim(pos, address, got, events)
        elif isinstance(got, Product):
            self._product(pos, address, got, events)

    def _claim(
        self, pos: int, address: int, name: int, events: list[tuple[int, DeviceEvent]]
    ) -> None:
        for other in [a for a, n in self._names.items() if n == name and a != address]:
            del self._names[other]  # the NAME moved
        self._names[address] = name
        if name != self.compass:
            return
        # (its address as it last claimed it: another device may have taken it since)
        before, self._compass_at = self._compass_at, address
        if before == address:
            return
        text = f"compass NAME {name_text(name)} claimed address {address}"
        if before is not None:
            text += f" (was {before}); its headings follow it"
        events.append((pos, DeviceEvent("address claim", "info", text)))

    def _product(
        self, pos: int, address: int, product: Product, events: list[tuple[int, DeviceEvent]]
    ) -> None:
        name = self._names.get(address)
        if name is None:
            return  # no claim from that address yet: whose it is is unknown
        self._products[name] = product
        told = f"model {product.model!r}, serial {product.serial!r}, software {product.software!r}"
        if self.compass is None and (product.model, product.serial) == self.wanted_product:
            self.compass, self._compass_at = name, address
            text = f"compass identified by its product information: NAME {name_text(name)}, {told}"
            events.append((pos, DeviceEvent("compass identified", "info", text)))
        elif name == self.compass:
            severity = "info"
            if self.wanted_product and (product.model, product.serial) != self.wanted_product:
                severity = "error"
                told += f" (the plan's instrument is {self.wanted_product[0]!r}, serial "
                told += f"{self.wanted_product[1]!r})"
            events.append((pos, DeviceEvent("product information", severity, f"compass: {told}")))
