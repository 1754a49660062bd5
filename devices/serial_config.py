"""The simulated serial compass's configuration (`devices.serial_sim`): plain dataclasses,
light to import, so that `gyrostand simulate`'s options are built without the simulation."""

from __future__ import annotations

from dataclasses import dataclass

from gyrostand.stand.simconfig import param

SENTENCES = ("HDT", "THS", "ROT")
MAX_RATE_HZ = 50.0  # IEC 61162-2 high-speed outputs: up to 50 Hz (GC80/GC85 manuals)


class SerialSimError(ValueError):
    """A serial compass that cannot be simulated as asked (one line)."""


@dataclass(frozen=True)
class LineFaults:
    """Faults of the serial line, each drawn from a seeded generator of its own, so switching
    one on does not change the others."""

    checksum_error_rate: float = param(0.0, "fraction of sentences sent with a wrong checksum")
    garbage_rate: float = param(0.0, "fraction of samples preceded by 1-8 non-ASCII bytes")
    not_valid_rate: float = param(
        0.0, "fraction of samples marked not valid (HDT heading empty, THS mode V, ROT status V)"
    )
    line_silence_at_s: float | None = param(
        None, "stand time from which the compass sends nothing (the stand goes on), s"
    )
    line_silence_for_s: float = param(0.0, "how long the compass's line stays silent, s")
    sender_baud: int | None = param(
        None, "the compass's own baud rate when it is not the reader's (a wrong baud rate)"
    )


@dataclass(frozen=True)
class SerialCompassConfig:
    """The simulated compass's serial output (its heading rate is the stand's)."""

    rate_hz: float = 10.0
    baud: int = param(4800, "baud rate of the line (IEC 61162-1: 4800; 61162-2: 38400)")
    talker: str = param("HE", "talker ID of the sentences (HE: gyrocompass)")
    sentences: tuple[str, ...] = param(("HDT", "ROT"), "sentences sent each sample, in order")
    faults: LineFaults = LineFaults()
    seed: int = 0

    def check(self) -> None:
        """The configuration a real line can carry, or a `SerialSimError` saying why not."""
        if not 1.0 <= self.rate_hz <= MAX_RATE_HZ:
            raise SerialSimError(f"sentence rate {self.rate_hz:g} Hz outside 1-50 Hz")
        unknown = [s for s in self.sentences if s not in SENTENCES]
        if unknown or not self.sentences:
            raise SerialSimError(f"sentences must be some of {', '.join(SENTENCES)}")
        if not (len(self.talker) == 2 and self.talker.isalpha() and self.talker.isupper()):
            raise SerialSimError(f"talker {self.talker!r} is not two capital letters")
        f = self.faults
        for name in ("checksum_error_rate", "garbage_rate", "not_valid_rate"):
            if not 0.0 <= getattr(f, name) <= 1.0:
                raise SerialSimError(f"{name} {getattr(f, name):g} is not a fraction in [0, 1]")
        for name, value in (("baud", self.baud), ("sender_baud", f.sender_baud or 1)):
            if value <= 0:
                raise SerialSimError(f"{name} {value} is not a baud rate")
        if f.line_silence_for_s < 0:
            raise SerialSimError(f"line_silence_for_s {f.line_silence_for_s:g} is negative")
        # the longest sentences of a sample must fit on the line between two samples
        longest = {"HDT": len("$HEHDT,359.9,T*hh\r\n"), "THS": len("$HETHS,359.99,A*hh\r\n")}
        longest["ROT"] = len("$HEROT,-9999.9,A*hh\r\n")
        per_s = sum(longest[s] for s in self.sentences) * self.rate_hz
        from gyrostand.devices.framing import BITS_PER_BYTE  # (pynmeagps: when checked)

        capacity = self.baud / BITS_PER_BYTE
        if per_s > capacity:
            raise SerialSimError(
                f"{'+'.join(self.sentences)} at {self.rate_hz:g} Hz need up to {per_s:g} bytes/s; "
                f"{self.baud} baud carries {capacity:g}"
            )
