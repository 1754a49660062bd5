"""Which NMEA 2000 device is the compass, checked before a campaign stores anything: gyrostand
asks every device for its address claim and product information (`nmea2000.iso_requests`) and
reads the answers. The compass is the device with the plan's NAME (`[compass] name`), else the
one whose product information gives the plan's `[instrument]` model and serial number; a
product information contradicting the plan, or no answer within `IDENTIFY_WALL_S`, is one line
naming what was seen (`IdentificationError`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import can
import numpy as np

from gyrostand.devices.n2k_heading import name_text
from gyrostand.devices.nmea2000 import Product, ReferenceDecoder, iso_requests, split_id

# ISO 11783-3 gives a device 200 ms to answer a request; the product information (fast-packet,
# about 20 frames) follows at once. Ten times that, for a loaded gateway or host.
IDENTIFY_WALL_S = 2.0


class IdentificationError(Exception):
    """The compass is not the plan's, or did not answer: one line saying which and why."""


@dataclass
class _Device:
    name: int | None = None
    product: Product | None = None


@dataclass
class Identification:
    """The answers of a bus's devices, frame by frame (`feed`), judged against the plan."""

    name: int | None  # the plan's [compass] name
    product: tuple[str, str]  # the plan's [instrument] model, serial
    devices: dict[int, _Device] = field(default_factory=dict)  # by source address
    _reference: ReferenceDecoder = field(default_factory=ReferenceDecoder)

    def feed(self, msg: can.Message) -> None:
        (_,), (address,) = split_id(np.array([msg.arbitration_id]))
        got = self._reference.decode(msg) if msg.is_extended_id else None
        if isinstance(got, int):
            for other in [a for a, d in self.devices.items() if d.name == got and a != address]:
                del self.devices[other]  # the NAME moved
            self.devices.setdefault(int(address), _Device()).name = got
        elif isinstance(got, Product):
            self.devices.setdefault(int(address), _Device()).product = got

    def _compass(self) -> tuple[int, _Device] | None:
        for address, device in self.devices.items():
            if device.name is None or device.product is None:
                continue
            if device.name == self.name or (
                self.name is None and (device.product.model, device.product.serial) == self.product
            ):
                return address, device
        return None

    def verdict(self) -> str | None:
        """ "" once the compass is identified and its product checked; a line when it is known
        to be wrong (the named compass's product contradicts the plan); None: keep listening."""
        found = self._compass()
        if found is None:
            return None
        address, device = found
        assert device.product is not None and device.name is not None
        if (device.product.model, device.product.serial) == self.product:
            return ""
        return (
            f"the compass (NAME {name_text(device.name)}, address {address}) is "
            f"{_product(device.product)}, not the plan's [instrument] {_wanted(self.product)}"
        )

    def timed_out(self, waited_s: float) -> str:
        """What is wrong when no verdict came within `waited_s` of wall time."""
        seen = "; ".join(
            f"address {a}"
            + (f" (NAME {name_text(d.name)})" if d.name is not None else " (no address claim)")
            + (f" is {_product(d.product)}" if d.product else " sent no product information")
            for a, d in sorted(self.devices.items())
        )
        if not seen:
            return (
                "no NMEA 2000 device answered the request for address claims and product "
                f"information (PGN 59904) within {waited_s:g} s: is the compass connected, "
                "powered, and on this bus at 250 kbit/s?"
            )
        if self.name is not None:
            wanted = f"the compass NAME {name_text(self.name)} ([compass] name)"
        else:
            wanted = f"the plan's [instrument] {_wanted(self.product)}"
        return (
            f"none of the NMEA 2000 devices that answered within {waited_s:g} s is {wanted}: {seen}"
        )


def _product(product: Product) -> str:
    return f"model {product.model!r}, serial {product.serial!r}"


def _wanted(product: tuple[str, str]) -> str:
    return f"(model {product[0]!r}, serial {product[1]!r})"


def identify(
    bus: can.BusABC,
    name: int | None,
    product: tuple[str, str],
    timeout_wall_s: float = IDENTIFY_WALL_S,
) -> None:
    """Send the requests on `bus` and read the answers until the compass is identified as the
    plan's (IdentificationError with the line saying why not)."""
    heard = Identification(name, product)
    for msg in iso_requests():
        bus.send(msg)
    deadline = time.monotonic() + timeout_wall_s
    while (left := deadline - time.monotonic()) > 0:
        msg = bus.recv(timeout=left)
        if msg is None:
            break
        heard.feed(msg)
        verdict = heard.verdict()
        if verdict == "":
            return
        if verdict is not None:
            raise IdentificationError(verdict)
    raise IdentificationError(heard.timed_out(timeout_wall_s))
