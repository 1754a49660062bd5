"""Configuration of the simulated gyrocompass + roll stand. Every field carries its help text,
which `gyrostand simulate --help` shows, so the options and their documentation cannot drift."""

from __future__ import annotations

import functools
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pydantic import BaseModel

TIMINGS = ("virtual", "realtime")
MAX_RATE_HZ = 1000.0  # frame rates: every frame carries its stand time in whole milliseconds


def param(default: Any, help: str) -> Any:
    """A dataclass field with its help text."""
    return field(default=default, metadata={"help": help})


@dataclass(frozen=True)
class CompassParams:
    """The simulated gyrocompass. C and T are the unit's hidden truth that a campaign estimates."""

    c_gcm2s2: float = param(
        6.0e7, "true reduced elastic compliance C of the gyrosphere, g*cm^2*s^-2 (hidden)"
    )
    t_s: float = param(
        1.1, "true time constant T of the gyrosphere's mass-centre shift, s (hidden)"
    )
    lp_gcm2s2: float = param(6.57e6, "maximum pendulous moment lP, g*cm^2*s^-2")
    h1_gcm2s: float = param(1.55e8, "angular momentum H1 of the gyrosphere along N-S, g*cm^2/s")
    u_rad_s: float = param(7.3e-5, "Earth rotation rate U, rad/s")
    g_cm_s2: float = param(981.0, "gravity g, cm/s^2")
    latitude_deg: float = param(46.5, "latitude phi of the stand, deg")
    rolling_error: bool = param(
        True, "shift the settled reading by the rolling error (Potemkin 1982, eq 1.1) while rocking"
    )
    heading_deg: float = param(120.0, "true heading of the stand (settled reading at rest), deg")
    initial_error_deg: float = param(
        0.0, "deviation of the sensitive element from equilibrium at stand time 0, deg"
    )
    transient: bool = param(
        True, "damped precessional transient to each new equilibrium (Bezvesilna & Gura, eqs 1-2)"
    )
    undamped_period_s: float = param(5064.0, "undamped precession period 2*pi/w0, s (84.4 min)")
    damping_ratio: float = param(
        0.7, "damping xi/w0 of the precession (0.7: within 5% of a step after ~40 min)"
    )
    nonlinear: bool = param(True, "keep the sin(alpha) term (Bezvesilna & Gura, eq 1; else linear)")
    harmonic_p_deg_per_g: float = param(
        1.0, "reading oscillation at the rocking frequency p, deg per g of stand acceleration A*p^2"
    )
    harmonic_2p_deg_per_g: float = param(
        0.5, "reading oscillation at 2p, deg per g of stand acceleration A*p^2"
    )
    fluid_temp_c: float = param(42.0, "supporting-fluid temperature reported in GYRO_STATUS, degC")
    settle_point_error_deg: float = param(
        0.0, "static error of the settle point: settled reading minus true heading at rest, deg"
    )
    runup_error_deg: float = param(
        30.0,
        "azimuth of the sensitive element from its settle point at switch-on (rotor stop), deg",
    )
    repeatability_sd_deg: float = param(
        0.03, "standard deviation of the settle point from one run-up to the next, deg"
    )

    def settled_shift_deg(
        self, direction_deg: float, amplitude_cm: float, period_s: float
    ) -> float:
        """The settled reading shift while rocking (0 when the rolling error is switched off)."""
        if not self.rolling_error:
            return 0.0
        from gyrostand.stand.physics import rolling_error_rad  # numpy: not for the CLI's options

        alpha = rolling_error_rad(
            direction_deg,
            amplitude_cm,
            period_s,
            C_gcm2s2=self.c_gcm2s2,
            T_s=self.t_s,
            lP_gcm2s2=self.lp_gcm2s2,
            H1_gcm2s=self.h1_gcm2s,
            U_rad_s=self.u_rad_s,
            g_cm_s2=self.g_cm_s2,
            latitude_deg=self.latitude_deg,
        )
        return math.degrees(alpha)


@dataclass(frozen=True)
class NoiseParams:
    """Angle-sensor noise (Sveshnikov, §8.3) and optional slow disturbances."""

    corr_sigma_deg: float = param(
        0.01, "sigma of the exponentially correlated noise sigma^2*exp(-mu*|tau|), deg"
    )
    corr_mu_per_s: float = param(0.05, "mu of the correlated noise, 1/s (correlation time 1/mu)")
    white_sigma_deg: float = param(0.005, "sigma of the white noise added to each sample, deg")
    quantum_deg: float = param(
        360.0 / 65536, "angle-sensor quantisation step, deg (16-bit encoder; 0 = none)"
    )
    drift_deg_per_h: float = param(0.0, "slow linear drift of the reading, deg/h")
    spurious_amplitude_deg: float = param(
        0.0, "amplitude of a spurious harmonic in the reading (Sveshnikov, §8.3 item 2), deg"
    )
    spurious_period_s: float = param(60.0, "period of the spurious harmonic, s")


@dataclass(frozen=True)
class StandParams:
    """Limits of the roll stand: commands outside them are refused with a reason."""

    max_amplitude_cm: float = param(50.0, "largest amplitude the stand accepts, cm")
    min_period_s: float = param(2.0, "shortest rocking period the stand accepts, s")
    max_period_s: float = param(20.0, "longest rocking period the stand accepts, s")


@dataclass(frozen=True)
class FaultParams:
    """Fault knobs (all off by default). Rates are per heading sample."""

    drop_rate: float = param(0.0, "probability that a heading frame is not sent (counter gap)")
    counter_jump_rate: float = param(0.0, "probability that the rolling counter jumps by 2..15")
    invalid_rate: float = param(0.0, "probability that a heading frame has its VALID flag cleared")
    stuck_at_s: float | None = param(None, "stand time at which the angle sensor sticks, s")
    stuck_for_s: float = param(0.0, "how long the sensor stays stuck (repeats one value), s")
    out_of_range_rate: float = param(
        0.0, "probability that a heading frame carries a raw angle above 359.999 deg"
    )
    corrupt_rate: float = param(0.0, "probability that one bit of a heading frame is flipped")
    error_frame_rate: float = param(0.0, "probability that an error frame precedes a heading frame")
    silence_at_s: float | None = param(None, "stand time at which the bus falls silent, s")
    silence_for_s: float = param(0.0, "how long the bus stays silent (no frames at all), s")
    no_ack: bool = param(False, "the stand ignores commands: no acknowledgement, no action")
    amplitude_factor: float = param(
        1.0, "the stand rocks at this multiple of the commanded amplitude (and reports it)"
    )
    amplitude_unreported: bool = param(
        False, "the stand reports the commanded amplitude, not the one it makes (uncalibrated)"
    )
    compass_fault_bits: int = param(0, "FAULT_BITS reported in GYRO_STATUS")


@dataclass(frozen=True)
class InclinometerParams:
    """A CiA 410 inclinometer on the platform (off unless `node_id` is set): its TPDO1 carries
    the slopes 0x6010 (x) and 0x6020 (y) at its event timer's rate; the one on `axis` follows
    the platform's true roll (the amplitude the stand really makes, amplitude_factor included),
    plus the sensor's own bias and white noise."""

    node_id: int | None = param(None, "CANopen node id (none: no inclinometer)")
    axis: str = param("x", "the slope that follows the roll: x (0x6010) or y (0x6020)")
    step_deg: float = param(0.01, "degrees per count of the slopes (resolution 0x6000)")
    arm_length_cm: float = param(100.0, "arm of the stand: roll angle = A / arm (rad)")
    rate_hz: float = param(10.0, "TPDO1 rate (event timer), Hz of stand time")
    bias_deg: float = param(0.02, "the sensor's zero bias, deg")
    noise_deg: float = param(0.01, "the sensor's white noise (standard deviation), deg")
    silence_at_s: float | None = param(None, "stand time at which the inclinometer falls silent")
    silence_for_s: float = param(0.0, "how long it stays silent, s")
    emcy_at_s: float | None = param(None, "stand time of an EMCY (0x5000, device hardware)")


@dataclass(frozen=True)
class SimConfig:
    compass: CompassParams = field(default_factory=CompassParams)
    noise: NoiseParams = field(default_factory=NoiseParams)
    faults: FaultParams = field(default_factory=FaultParams)
    timing: str = param(
        "virtual",
        "virtual: the stand runs as far as the controller's SIM_SYNC allows (same seed, same "
        "frames, as fast as the CPU allows); realtime: at --speedup x the wall clock",
    )
    speedup: float = param(1.0, "stand seconds per wall second with --timing realtime")
    heading_rate_hz: float = param(10.0, "GYRO_HEADING rate, Hz of stand time")
    status_rate_hz: float = param(2.0, "STAND_STATUS/STAND_MOTION/GYRO_STATUS rate, Hz")
    seed: int = param(0, "random seed: equal seeds and schedules give equal frames")
    stand: StandParams = field(default_factory=StandParams)
    inclinometer: InclinometerParams = field(default_factory=InclinometerParams)

    def __post_init__(self) -> None:
        problems = self.problems()
        if problems:
            raise SimConfigError(problems)

    def problems(self) -> list[tuple[str, str]]:
        """Every inconsistent value, as (dotted field path, message): quantities of the model
        out of their physical domain, and values the simulated stand could not put in its
        frames (their DBC ranges; stand times in whole milliseconds)."""
        from gyrostand.stand.protocol import shipped_range

        compass, noise, faults, stand = self.compass, self.noise, self.faults, self.stand
        positive = {
            "speedup": self.speedup,
            "heading_rate_hz": self.heading_rate_hz,
            "status_rate_hz": self.status_rate_hz,
            "compass.undamped_period_s": compass.undamped_period_s,
            "compass.c_gcm2s2": compass.c_gcm2s2,
            "compass.lp_gcm2s2": compass.lp_gcm2s2,
            "compass.h1_gcm2s": compass.h1_gcm2s,
            "compass.u_rad_s": compass.u_rad_s,
            "compass.g_cm_s2": compass.g_cm_s2,
            "noise.corr_mu_per_s": noise.corr_mu_per_s,
            "noise.spurious_period_s": noise.spurious_period_s,
            "stand.max_amplitude_cm": stand.max_amplitude_cm,
            "stand.min_period_s": stand.min_period_s,
            "stand.max_period_s": stand.max_period_s,
            "inclinometer.arm_length_cm": self.inclinometer.arm_length_cm,
            "inclinometer.rate_hz": self.inclinometer.rate_hz,
        }
        found = [
            (name, f"must be a positive number, got {value}")
            for name, value in positive.items()
            if not (value > 0 and math.isfinite(value))
        ]
        not_negative = {
            "compass.t_s": compass.t_s,
            "noise.corr_sigma_deg": noise.corr_sigma_deg,
            "noise.white_sigma_deg": noise.white_sigma_deg,
            "noise.quantum_deg": noise.quantum_deg,
            "noise.spurious_amplitude_deg": noise.spurious_amplitude_deg,
            "compass.repeatability_sd_deg": compass.repeatability_sd_deg,
            "faults.stuck_at_s": faults.stuck_at_s,
            "faults.stuck_for_s": faults.stuck_for_s,
            "faults.silence_at_s": faults.silence_at_s,
            "faults.silence_for_s": faults.silence_for_s,
            "faults.amplitude_factor": faults.amplitude_factor,
            "inclinometer.noise_deg": self.inclinometer.noise_deg,
            "inclinometer.silence_at_s": self.inclinometer.silence_at_s,
            "inclinometer.silence_for_s": self.inclinometer.silence_for_s,
            "inclinometer.emcy_at_s": self.inclinometer.emcy_at_s,
        }
        found += [
            (name, f"must be a number >= 0, got {value}")
            for name, value in not_negative.items()
            if value is not None and not (value >= 0 and math.isfinite(value))
        ]
        if not -90.0 < compass.latitude_deg < 90.0:
            found.append(("compass.latitude_deg", "must be in (-90, 90)"))
        if not 0.0 <= compass.heading_deg < 360.0:
            found.append(("compass.heading_deg", "must be in [0, 360)"))
        for name in ("heading_rate_hz", "status_rate_hz"):
            if getattr(self, name) > MAX_RATE_HZ:
                found.append(
                    (name, f"must be <= {MAX_RATE_HZ:g} (frames carry stand time in whole ms)")
                )
        found += self.inclinometer_problems()
        if stand.max_period_s < stand.min_period_s:
            found.append(("stand.max_period_s", "must be >= min_period_s"))
        reported = {  # what the stand puts in its frames, the DBC signal carrying it, from what
            "faults.compass_fault_bits": (
                faults.compass_fault_bits,
                "GYRO_STATUS.FAULT_BITS",
                {"faults.compass_fault_bits"},
            ),
            "compass.fluid_temp_c": (
                compass.fluid_temp_c,
                "GYRO_STATUS.FLUID_TEMP",
                {"compass.fluid_temp_c"},
            ),
            "faults.amplitude_factor": (
                faults.amplitude_factor * stand.max_amplitude_cm,
                "STAND_MOTION.AMPLITUDE",
                {"faults.amplitude_factor", "stand.max_amplitude_cm"},
            ),
        }
        told = {name for name, _ in found}
        for name, (value, signal, sources) in reported.items():
            if sources & told:
                continue
            low, high = shipped_range(signal)
            if not low <= value <= high:
                outside = f"outside [{low:g}, {high:g}]"
                found.append((name, f"would put {value:g} in {signal}, {outside}"))
        if self.timing not in TIMINGS:
            found.append(("timing", f"must be one of {', '.join(TIMINGS)}, got {self.timing!r}"))
        elif self.timing == "virtual" and self.speedup != 1.0:
            found.append(("speedup", "applies only with timing realtime"))
        if not self.compass.damping_ratio >= 0.0:
            found.append(("compass.damping_ratio", "must be >= 0"))
        if not self.compass.undamped_period_s * self.heading_rate_hz >= 20:
            found.append(("compass.undamped_period_s", "must span at least 20 heading intervals"))
        for f in fields(FaultParams):
            if f.name.endswith("_rate") and not 0.0 <= getattr(self.faults, f.name) <= 1.0:
                found.append((f"faults.{f.name}", "must be a probability in [0, 1]"))
        return found

    def inclinometer_problems(self) -> list[tuple[str, str]]:
        incl = self.inclinometer
        found = []
        if incl.node_id is not None and not 1 <= incl.node_id <= 127:
            found.append(("inclinometer.node_id", "must be a CANopen node id, 1 to 127"))
        if incl.axis not in ("x", "y"):
            found.append(("inclinometer.axis", f"must be x or y, got {incl.axis!r}"))
        if not (incl.step_deg != 0 and math.isfinite(incl.step_deg)):
            found.append(("inclinometer.step_deg", "must be a non-zero number"))
        if incl.rate_hz > MAX_RATE_HZ:
            found.append(("inclinometer.rate_hz", f"must be <= {MAX_RATE_HZ:g}"))
        return found


class SimConfigError(ValueError):
    """An inconsistent SimConfig; `problems` as (dotted field path, message), the text names
    each field as the command-line option does."""

    def __init__(self, problems: list[tuple[str, str]]) -> None:
        self.problems = problems
        super().__init__("; ".join(f"{path.split('.')[-1]} {text}" for path, text in problems))


_TABLES = {
    "compass": CompassParams,
    "noise": NoiseParams,
    "faults": FaultParams,
    "stand": StandParams,
    "inclinometer": InclinometerParams,
}


RENAMED_KNOBS = {
    "compass": {
        "C_gcm2s2": "c_gcm2s2",
        "T_s": "t_s",
        "lP_gcm2s2": "lp_gcm2s2",
        "H1_gcm2s": "h1_gcm2s",
        "U_rad_s": "u_rad_s",
    }
}
"""Knobs spelled as physics symbols before one spelling (lower case, as the plan's
[instrument] lp_gcm2s2 and the CLI's --lp-gcm2s2) was chosen: table -> {old: new}. The old
spelling is still read (`renamed_knobs` says what to write instead)."""


def renamed_knobs(simulator: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    """(table, old, new) for each knob of `[bus.simulator]` tables (or of a plugin's stand) in
    its old spelling."""
    return [
        (table, old, new)
        for table, renamed in RENAMED_KNOBS.items()
        if isinstance(given := simulator.get(table), Mapping)
        for old, new in renamed.items()
        if old in given
    ]


@functools.cache
def simulator_tables() -> type[BaseModel]:
    """The pydantic model of a plan's `[bus.simulator]` overrides (tables compass, noise,
    faults, stand and the scalar fields of SimConfig), generated from the dataclasses: their
    defaults, and their help texts as descriptions; unknown keys refused."""
    from pydantic import AliasChoices, Field, create_model

    from gyrostand.stand.tables import TABLE_CONFIG

    def model(cls: type, name: str, doc: str, table: str = "", **nested: Any) -> type[BaseModel]:
        hints = typing.get_type_hints(cls)
        old = {new: old for old, new in RENAMED_KNOBS.get(table, {}).items()}
        scalars: dict[str, Any] = {
            f.name: (
                hints[f.name],
                Field(
                    f.default,
                    description=f.metadata["help"],
                    validation_alias=AliasChoices(f.name, old[f.name]) if f.name in old else None,
                ),
            )
            for f in fields(cls)
            if f.name not in nested
        }
        return create_model(name, __config__=TABLE_CONFIG, __doc__=doc, **scalars, **nested)

    nested: dict[str, Any] = {}
    for name, cls in _TABLES.items():
        table = model(cls, f"Simulator{name.title()}", cls.__doc__ or name, name)
        nested[name] = (table, Field(default_factory=table))
    return model(SimConfig, "SimulatorTables", "[bus.simulator]: the simulated stand.", **nested)


def simulator_config(tables: BaseModel, **base: Any) -> SimConfig:
    """The SimConfig of validated `simulator_tables()` over the defaults and `base` (the plan's
    [bus] speedup, seed, timing; keys set in the tables win). SimConfigError: inconsistent."""
    given = tables.model_dump(exclude_unset=True)
    parts = {name: cls(**given.pop(name, {})) for name, cls in _TABLES.items()}
    return SimConfig(**{**base, **given, **parts})
