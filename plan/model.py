"""The campaign plan: one typed model of the plan file (pydantic), parsed once, used by every layer.

The models mirror the TOML: one class per table, unknown keys refused, field constraints and
cross-field rules in the models, the field docs doubling as the JSON Schema's descriptions
(`gyrostand plan schema`). `parse_plan` reports every problem at once in one `PlanError`, each
with its path in the plan's terms (``[settle] hold_s: must be >= 0``, ``[[trials]] 3 period_s:
must be > 0``), so an operator fixes the whole file before the bus or the database is touched.

A plan without ``[[trials]]`` is the *partial form* (`PartialPlan`): the instrument, site and
analysis tables alone. `gyrostand import --plan` and `gyrostand analyze --plan` accept it, and an
import without a plan file stores it (``db.io.metadata_toml`` writes [instrument] and [site]);
`parse_any_plan` reads either form.
"""

from __future__ import annotations

import hashlib
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeVar

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainValidator,
    PrivateAttr,
    StringConstraints,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from gyrostand.plan.procedures import (
    ProcedurePlan,
    ReferencePlan,
    RollingPoint,
    StandardPlan,
    duplicated,
    needs,
)
from gyrostand.stand.encoder import Encoder, EncoderError, encoder_from_eds
from gyrostand.stand.protocol import SignalMap
from gyrostand.stand.simconfig import SimConfigError, simulator_config, simulator_tables
from gyrostand.stand.tables import TABLE_CONFIG, check, problems

if TYPE_CHECKING:  # (numpy and scipy: not for checking a plan)
    from gyrostand.analysis.transient import TransientModel

EARTH_RATE_RAD_S = 7.292115e-5  # the sidereal rotation rate of the Earth (IERS)
GRAVITY_CM_S2 = 981.0

Role = Literal["fit", "control"]
Timing = Literal["virtual", "realtime"]
ESTIMATE_KEYS = (
    "undamped_period_s",
    "damping_ratio",
    "expected_se_deg",
    "tolerance_fraction",
    "stable_estimates",
    "transient_fraction",
)
TRANSIENT_KEYS = ESTIMATE_KEYS[:2]  # instrument data: also the analysis's transient bound
MAX_N_OBS = 2**31 - 1
"""Largest N: observation k is an Integer column of the database (32-bit signed in PostgreSQL
and MySQL), and so is the campaign's n_obs."""
MAX_SERIES_STAND_DAYS = 7
"""Largest stand time the N observation windows of one series may take, N x (window + spacing)
(settling not counted): a week of stand time; more is a typing error, not a campaign."""
FIT_PARAMETERS = 2
"""m, the parameters the analysis fits: C and T (Potemkin 1982, model 1.1)."""
MIN_FIT_TRIALS = FIT_PARAMETERS + 1
"""n >= m + 1 fit trials: the adequacy test (Potemkin 1982, eq 2.8) needs n - m >= 1 degrees of
freedom."""
FEW_RESIDUAL_DOF = 2
"""At most this many residual degrees of freedom n - m is a fragile design: t(n - m) intervals
are wide, and a residual variance near 0 by chance (F_p near 0) goes unnoticed in them."""


class PlanError(ValueError):
    """A plan that cannot run; `problems` lists every defect as ``path: message``."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        super().__init__("invalid plan: " + "; ".join(problems))


def _no_default(schema: dict[str, Any]) -> None:
    """Drop a default the JSON Schema cannot state (infinity, or one that depends on the table)."""
    schema.pop("default", None)


def _interval(value: Any) -> tuple[float, float]:
    numbers = isinstance(value, list | tuple) and len(value) == 2
    numbers = numbers and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
    )
    if not numbers or not 0 < value[0] < value[1]:
        raise ValueError("must be [low, high] with 0 < low < high")
    return float(value[0]), float(value[1])


def _storable_n(value: int) -> int:
    if value > MAX_N_OBS:
        raise ValueError(
            f"must be <= {MAX_N_OBS} (observation k is a 32-bit integer column of the database)"
        )
    return value


def _number(value: float) -> str:
    """A plan value as the operator wrote it: 40 for 40.0, 17.8 for 17.8."""
    return format(value, ".15g")


def _interface(value: str) -> str:
    from can.interfaces import VALID_INTERFACES

    if value not in VALID_INTERFACES:
        known = ", ".join(sorted(VALID_INTERFACES))
        raise ValueError(f"unknown python-can interface {value!r} (one of {known})")
    return value


def _channel(value: Any) -> str:
    if isinstance(value, bool) or not isinstance(value, str | int):
        raise ValueError("must be a string or an integer")
    return str(value)


_SIGNALS = tuple(f.name for f in fields(SignalMap))


def _known_signals(table: dict[str, str]) -> dict[str, str]:
    check([(key, "unknown key") for key in table if key not in _SIGNALS])
    return table


SimulatorTables = simulator_tables()
Text = Annotated[str, StringConstraints(pattern=r"\S")]
Interval = Annotated[tuple[float, float], BeforeValidator(_interval)]
Channel = Annotated[str, PlainValidator(_channel, json_schema_input_type=str | int)]
Interface = Annotated[Text, AfterValidator(_interface)]
Signals = Annotated[dict[str, str], AfterValidator(_known_signals)]


class _Table(BaseModel):
    """A plan table (`stand.tables.TABLE_CONFIG`)."""

    model_config = TABLE_CONFIG


class CampaignPlan(_Table):
    """[campaign]: who runs it, how many observations per series, where everything goes."""

    operator: Text
    """Who runs the campaign (stored with it, signs the report)."""
    n_obs: Annotated[int, AfterValidator(_storable_n)] = Field(
        ge=2, json_schema_extra={"maximum": MAX_N_OBS}
    )
    """N, observations per series (Potemkin 1982, eq 2.1); at most 2147483647, and the N windows
    of a series may take at most 7 days of stand time."""
    database: Text
    """A file path (SQLite) or any SQLAlchemy URL."""
    raw_log_format: Literal["blf", "asc"] = "blf"
    """Format of the python-can log that receives every frame."""
    raw_log_dir: Text | None = None
    """Folder of the raw CAN logs; default: `raw` beside the database file (`runs/raw` for a
    database given as a server URL)."""
    on_trial_failure: Literal["continue", "pause"] = "continue"
    """What a failed trial does to the campaign."""
    acquisition_only: bool = False
    """Acquire and store the data without the promise of an analysis: the design may then have
    fewer than the 3 fit trials the analysis needs (m + 1 for the m = 2 parameters C and T), and
    such a campaign cannot be analysed."""


class InstrumentPlan(_Table):
    """[instrument]: the compass under test and its known constants B (Potemkin 1982, eq 1.1)."""

    model: Text
    """Instrument model."""
    serial: Text
    """Serial number."""
    manufacturer: Text | None = None
    """Manufacturer (the report names it; a final report needs it)."""
    lp_gcm2s2: float = Field(gt=0)
    """Maximum pendulous moment lP, g*cm^2*s^-2."""
    h1_gcm2s: float = Field(gt=0)
    """Angular momentum H1 of the gyrosphere along N-S, g*cm^2*s^-1."""


class SitePlan(_Table):
    """[site]: where the stand is."""

    latitude_deg: float = Field(gt=-90, lt=90)
    """Latitude phi of the stand, deg."""
    earth_rate_rad_s: float = Field(EARTH_RATE_RAD_S, gt=0)
    """Earth rotation rate U, rad/s (default: the sidereal rate 7.292115e-5)."""
    gravity_cm_s2: float = Field(GRAVITY_CM_S2, gt=0)
    """Gravity g, cm/s^2."""


class AnalysisPlan(_Table):
    """[analysis]: the regression of Potemkin (1982): level q, start values, prior region."""

    q: float = Field(0.05, gt=0, lt=1)
    """Significance level of the tests."""
    start_c: float = Field(gt=0)
    """Start value of the reduced elastic compliance C, g*cm^2*s^-2."""
    start_t_s: float = Field(gt=0)
    """Start value of the time constant T, s."""
    admissible_c: Interval | None = None
    """Admissible range [low, high] of C (checked and reported, not imposed)."""
    admissible_t_s: Interval | None = None
    """Admissible range [low, high] of T, s (checked and reported, not imposed)."""


class ForecastPlan(_Table):
    """[forecast]: the ship's rocking for which the error at sea is predicted."""

    roll_deg: float = Field(gt=0, lt=90)
    """Roll (or pitch) amplitude theta0, deg."""
    arm_cm: float = Field(gt=0)
    """Height h of the compass above the rocking axis, cm."""
    period_s: float = Field(gt=0)
    """Rocking period tau, s."""
    course_deg: float = Field(ge=0, lt=360)
    """Ship's course, deg in [0, 360)."""
    latitude_deg: float = Field(gt=-90, lt=90)
    """Latitude phi of the voyage, deg."""
    motion: Literal["roll", "pitch"] = "roll"
    """Rolling (K = course + 90 deg) or pitching (K = course)."""
    amplitude_cm: float | None = Field(None, gt=0)
    """Acceleration amplitude A, cm, instead of theta0 x h (Potemkin 1982 rounds 65.45 to 65)."""


class TrialPlan(_Table):
    """[[trials]]: one row of the design: rocking direction K, amplitude A, period tau, role."""

    direction_deg: float = Field(ge=0, lt=360)
    """Rocking direction K, deg in [0, 360)."""
    amplitude_cm: float = Field(gt=0)
    """Rocking amplitude A, cm."""
    period_s: float = Field(gt=0)
    """Rocking period tau, s."""
    role: Role = "fit"
    """"fit": estimates C and T; "control": checks the fitted model."""
    _index: int = PrivateAttr(0)

    @property
    def index(self) -> int:
        """The trial's number in the plan, from 1."""
        return self._index


PROMPT_ANSWER_CHARS = 200
"""Longest answer to a text prompt (one line, whitespace collapsed)."""
CONFIRMED = "yes"


def _prompt_id(value: str) -> str:
    if not re.fullmatch(r"[a-z][a-z0-9_]{0,39}", value):
        raise ValueError("must be lowercase letters, digits and _ (at most 40), from a letter")
    return value


def _before(value: Any) -> str | int:
    trial = isinstance(value, int) and not isinstance(value, bool) and value > 0
    if value == "campaign" or trial:
        return value
    raise ValueError('must be "campaign" or a trial number (1 = the first [[trials]])')


class PromptPlan(_Table):
    """[[prompt]]: a question to the operator, answered before the campaign starts or before a
    trial begins (at the station, on the terminal or with `--answer`); the question and its
    answer are stored as events."""

    id: Annotated[str, AfterValidator(_prompt_id)]
    """Its name: lowercase letters, digits and _, starting with a letter (`--answer id=...`)."""
    text: Text
    """The question, as the operator reads it."""
    kind: Literal["confirm", "text"] = "confirm"
    """"confirm": answered yes (or the campaign is stopped); "text": a line of text."""
    before: Annotated[str | int, PlainValidator(_before, json_schema_input_type=str | int)]
    """"campaign", or the number of the trial it comes before."""

    def answer(self, value: str) -> str:
        """The answer to store for `value` (ValueError saying what is wrong with it)."""
        value = " ".join(value.split())
        if self.kind == "confirm":
            if value.casefold() not in ("y", CONFIRMED):
                raise ValueError(f"{self.id}: answer yes to confirm ({self.text})")
            return CONFIRMED
        if not value:
            raise ValueError(f"{self.id}: the answer is empty ({self.text})")
        if len(value) > PROMPT_ANSWER_CHARS:
            raise ValueError(f"{self.id}: longer than {PROMPT_ANSWER_CHARS} characters")
        return value


class ObservationPlan(_Table):
    """[observation]: windows in stand time: seconds when still, whole periods when rocking."""

    still_window_s: float = Field(60.0, gt=0)
    """Stand seconds per observation with the stand still."""
    rocking_window_periods: int = Field(10, ge=1)
    """Whole rocking periods per observation while rocking."""
    spacing_s: float = Field(0.0, ge=0)
    """Stand seconds between consecutive windows."""
    correlation_time_s: float | None = Field(None, gt=0)
    """The reading's correlation time 1/mu, s (the exponential model a report fits to a record
    of this compass, Sveshnikov eq 8.89); with it `plan check` states the spacing that makes
    successive observations independent (eqs 8.92-8.94)."""

    def window_ms(self, rocking_period_s: float | None) -> int:
        """Window length in stand milliseconds for a still (None) or rocking series."""
        if rocking_period_s is None:
            return round(self.still_window_s * 1000)
        return round(self.rocking_window_periods * rocking_period_s * 1000)


@dataclass(frozen=True)
class EstimatePlan:
    """Settle by the compass's transient model (Bezvesilna & Gura): observe once the settle point
    estimated from the transient is known within `tolerance_fraction` x the expected
    S{<delta>}_e (Potemkin 1982, eq 2.6) and, method "estimate", the transient left over the
    observations is bounded by `transient_fraction` x S_e; method "compensated" observes at once
    and subtracts the fitted transient from each observation. The undamped period 2 pi / omega0
    and damping ratio xi / omega0 are instrument data. Derived from [settle]
    (`SettlePlan.estimate`)."""

    undamped_period_s: float
    damping_ratio: float
    expected_se_deg: float
    tolerance_fraction: float
    stable_estimates: int
    transient_fraction: float
    compensated: bool = False

    @property
    def tolerance_deg(self) -> float:
        return self.tolerance_fraction * self.expected_se_deg

    @property
    def transient_tolerance_deg(self) -> float:
        return self.transient_fraction * self.expected_se_deg

    @property
    def model(self) -> TransientModel:
        from gyrostand.analysis.transient import TransientModel

        return TransientModel(self.undamped_period_s, self.damping_ratio)


class SettlePlan(_Table):
    """[settle]: when a series may start observing. Method "band": the window means over the
    last `hold_s` stand seconds all lie within +-`band_deg` of their mean and their trend moves
    the reading by at most `drift_deg` over that time. Method "estimate": once the settle point
    estimated from the damped transient is known and the transient left over the observations
    is bounded; "compensated": observe during the transient and subtract it (`EstimatePlan`).
    The band criterion then only measures the time saved. `max_wait_s` bounds all three."""

    band_deg: float = Field(0.02, gt=0)
    """Half-width of the band, deg."""
    drift_deg: float = Field(math.inf, gt=0, json_schema_extra=_no_default)
    """Largest trend over hold_s, deg (default: no trend condition)."""
    hold_s: float = Field(600.0, ge=0)
    """Stand seconds the window means must stay in the band."""
    max_wait_s: float = Field(4 * 3600.0, gt=0)
    """Stand seconds after which an unsettled series fails (>= hold_s)."""
    method: Literal["band", "estimate", "compensated"] = "band"
    """"band", "estimate" or "compensated" (the transient model; need the keys below)."""
    undamped_period_s: float | None = Field(None, gt=0)
    """The compass's undamped precession period 2 pi / omega0, s (instrument data; with "band"
    optional, for the analysis's bound on the transient left in each series)."""
    damping_ratio: float | None = Field(None, ge=0, lt=1)
    """The damping ratio xi / omega0 of the precession (instrument data, as above)."""
    expected_se_deg: float | None = Field(None, gt=0)
    """Estimate: the expected S{<delta>}_e, deg (Potemkin 1982, eq 2.6)."""
    tolerance_fraction: float = Field(0.5, gt=0, le=1)
    """Estimate: tolerance = tolerance_fraction x expected_se_deg."""
    stable_estimates: int = Field(3, ge=2)
    """Estimate: consecutive estimates that must agree within the tolerance."""
    transient_fraction: float = Field(0.05, gt=0, le=1)
    """Estimate: the transient left over the observations (|fit| + 2 SE) must stay within
    transient_fraction x expected_se_deg."""

    @model_validator(mode="after")
    def _consistent(self) -> SettlePlan:
        problems = []
        if self.max_wait_s < self.hold_s:
            problems.append(("max_wait_s", "must be >= hold_s"))
        if self.method == "band":
            given = [
                key
                for key in ESTIMATE_KEYS
                if key in self.model_fields_set and key not in TRANSIENT_KEYS
            ]
            problems += [(key, "does not apply when method = 'band'") for key in given]
            if len([key for key in TRANSIENT_KEYS if getattr(self, key) is not None]) == 1:
                problems.append(("damping_ratio", "give both undamped_period_s and damping_ratio"))
        else:
            required = ESTIMATE_KEYS[:3]
            problems += [(key, "missing") for key in required if getattr(self, key) is None]
        check(problems)
        return self

    @property
    def estimate(self) -> EstimatePlan | None:
        """The transient-model parameters (methods "estimate", "compensated"), else None."""
        if self.method == "band":
            return None
        values = (getattr(self, key) for key in ESTIMATE_KEYS)
        return EstimatePlan(*values, compensated=self.method == "compensated")

    def describe(self) -> str:
        """The criterion in words, as the report states it."""
        give_up = f"a series fails after {self.max_wait_s:g} s unsettled"
        if self.method == "band":
            trend = "" if math.isinf(self.drift_deg) else f", trend <= {self.drift_deg:g} deg"
            return (
                f"band: window means within +-{self.band_deg:g} deg{trend} over "
                f"{self.hold_s:g} s; {give_up}"
            )
        e = self.estimate
        assert e is not None  # method is not "band"
        known = (
            f"the compass's transient (Bezvesilna & Gura; undamped period "
            f"{e.undamped_period_s:g} s, damping ratio {e.damping_ratio:g}) fitted online; the "
            f"settle point known within {e.tolerance_fraction:g} S_e (S_e expected "
            f"{e.expected_se_deg:g} deg, over {e.stable_estimates} estimates)"
        )
        bound = f"the transient left over the N windows within {e.transient_fraction:g} S_e"
        if e.compensated:
            return (
                f"compensated: {known}, then observed during the transient and the fitted "
                f"transient subtracted from each observation (the first series of a run waits "
                f"until {bound}); {give_up}"
            )
        return f"estimate: {known} and {bound}; {give_up}"

    @property
    def transient_model(self) -> TransientModel | None:
        """The compass's transient (Bezvesilna & Gura eq 1) when the plan gives it."""
        if self.undamped_period_s is None or self.damping_ratio is None:
            return None
        from gyrostand.analysis.transient import TransientModel

        return TransientModel(self.undamped_period_s, self.damping_ratio)


class TrackingPlan(_Table):
    """[tracking]: how closely the stand's rocking must follow the command: its own reports while it
    starts, and the motion measured over the rocking series ([inclinometer], else the stand's
    reports), which fails the trial when outside."""

    amplitude_rel: float = Field(0.05, gt=0)
    """Largest relative amplitude error."""
    period_rel: float = Field(0.05, gt=0)
    """Largest relative period error."""
    direction_deg: float = Field(2.0, gt=0)
    """Largest direction error, deg."""
    confirm_s: float = Field(120.0, gt=0)
    """Stand seconds allowed for the stand to reach the commanded motion."""


class TimeoutsPlan(_Table):
    """[timeouts]"""

    ack_s: float = Field(2.0, gt=0)
    """Wall seconds for a command acknowledgement."""
    bus_silence_s: float = Field(5.0, gt=0)
    """Stand seconds without a heading frame."""


class ChecksPlan(_Table):
    """[checks]"""

    max_error_frames: int = Field(10, ge=0)
    """Error frames allowed per series; more fail the trial."""


class BusPlan(_Table):
    """[bus]: where the frames come from: the in-process simulated stand, or a python-can bus
    (interface and channel, or python-can's own configuration when both are left out)."""

    simulated: bool = True
    """The simulated compass and stand on an in-process virtual bus."""
    interface: Interface | None = None
    """python-can interface, e.g. "socketcan" (not with simulated = true)."""
    channel: Channel | None = None
    """python-can channel, e.g. "can0"."""
    bitrate: int | None = Field(None, ge=1)
    """Bit rate, bit/s."""
    timing: Timing = Field("realtime", json_schema_extra=_no_default)
    """"virtual": stand time follows the acquisition (repeatable, full speed); "realtime": the
    wall clock. Default: virtual when simulated, realtime otherwise."""
    speedup: float = Field(1.0, gt=0)
    """Stand seconds per wall second: the simulated stand with timing = "realtime" only."""
    seed: int = Field(0, ge=0)
    """Random seed of the simulated stand."""
    simulator: SimulatorTables = Field(default_factory=SimulatorTables)  # type: ignore[valid-type]
    """Overrides of the simulated stand's parameters (tables compass, noise, faults, stand)."""
    queue_size: int = Field(200_000, ge=1)
    """Frames the receive queue holds."""

    @model_validator(mode="before")
    @classmethod
    def _default_timing(cls, data: Any) -> Any:
        if isinstance(data, dict) and "timing" not in data:
            simulated = data.get("simulated", True) is True
            return {**data, "timing": "virtual" if simulated else "realtime"}
        return data

    @model_validator(mode="after")
    def _consistent(self) -> BusPlan:
        problems = []
        if self.simulated and self.interface is not None:
            problems.append(("interface", "must be absent when simulated = true"))
        if not self.simulated and self.speedup != 1.0:
            problems.append(("speedup", "only applies when simulated = true"))
        elif self.timing == "virtual" and self.speedup != 1.0:
            virtual = 'only applies with timing = "realtime" (virtual time runs at full speed)'
            problems.append(("speedup", virtual))
        if self.simulated and not problems:
            try:
                simulator_config(
                    self.simulator, speedup=self.speedup, seed=self.seed, timing=self.timing
                )
            except SimConfigError as exc:
                problems += [(f"simulator.{key}", message) for key, message in exc.problems]
        check(problems)
        return self


HeadingProtocol = Literal["gyrostand", "dbc", "nmea2000", "iec61162", "cia406"]
_CAN_KEYS = ("interface", "channel", "bitrate")
_SERIAL_KEYS = ("port", "baud")
_CIA406_KEYS = (
    "node_id",
    "counts_per_revolution",
    "zero_counts",
    "direction",
    "heartbeat_ms",
    "eds",
)


def _iso_name(value: Any) -> str:
    """An ISO 11783-5 NAME (64 bits) as 16 hexadecimal digits (TOML integers stop at 2^63)."""
    if not isinstance(value, str) or not re.fullmatch(r"(0x)?[0-9A-Fa-f]{1,16}", value):
        raise ValueError('must be the 64-bit NAME in hexadecimal, e.g. "0x00A0F2C2C2200F00"')
    return f"0x{int(value, 16):016X}"


class CompassPlan(_Table):
    """[compass]: the heading source (docs/instruments.md). "gyrostand" and "dbc": the heading
    frame of the stand's DBC (shipped, or the lab's [protocol] dbc_path), on the stand's bus;
    "nmea2000": PGN 127250 on CAN (the stand's bus, or its own with interface/channel);
    "iec61162": HDT/THS sentences on a serial port; "cia406": an absolute encoder on CANopen."""

    protocol: HeadingProtocol = "gyrostand"
    """How the compass sends its heading."""
    interface: Interface | None = None
    """The compass's own CAN bus, python-can interface (default: the stand's [bus])."""
    channel: Channel | None = None
    """Its channel, e.g. "can1"."""
    bitrate: int | None = Field(None, ge=1)
    """Its bit rate, bit/s (NMEA 2000: 250000)."""
    port: Text | None = None
    """Serial port of an IEC 61162 compass, e.g. "/dev/ttyUSB0"."""
    baud: int = Field(4800, ge=1)
    """Its baud rate (IEC 61162-1: 4800; IEC 61162-2: 38400)."""
    name: Annotated[str, BeforeValidator(_iso_name)] | None = None
    """NMEA 2000: the compass's NAME (address claim, hexadecimal); default: the device whose
    product information (PGN 126996) gives [instrument] model and serial."""
    node_id: int | None = Field(None, ge=1, le=127)
    """cia406: the encoder's CANopen node id (its TPDO1 0x180 + id, EMCY, heartbeat)."""
    counts_per_revolution: int | None = Field(None, ge=2)
    """cia406: measuring units per revolution, the encoder's 0x6001 (default: its EDS's)."""
    zero_counts: int = Field(0, ge=0)
    """cia406: the position value (counts) the encoder reads at heading 0."""
    direction: Literal["clockwise", "counterclockwise"] = "clockwise"
    """cia406: how the counts run as the heading increases (seen from above the card)."""
    heartbeat_ms: int | None = Field(None, ge=0)
    """cia406: the encoder's producer heartbeat time 0x1017, ms; a heartbeat missing for three
    periods is an event (default: its EDS's, else 0: not supervised)."""
    eds: Text | None = None
    """cia406: the encoder's EDS (the maker's): the TPDO that maps the position 0x6004, its
    resolution 0x6001 and total range 0x6002 (default: TPDO1, 32 bits from byte 0)."""

    @model_validator(mode="after")
    def _consistent(self) -> CompassPlan:
        given = self.model_fields_set
        problems = []
        encoder = [k for k in _CIA406_KEYS if k in given] if self.protocol != "cia406" else []
        problems += [(k, f'not with protocol = "{self.protocol}" (cia406)') for k in encoder]
        if self.protocol in ("gyrostand", "dbc"):
            unused = [k for k in (*_CAN_KEYS, *_SERIAL_KEYS, "name") if k in given]
            why = "the heading frame is in the stand's DBC, on the stand's bus"
            problems += [(k, f'not with protocol = "{self.protocol}" ({why})') for k in unused]
        elif self.protocol == "iec61162":
            unused = [k for k in (*_CAN_KEYS, "name") if k in given]
            problems += [(k, 'not with protocol = "iec61162" (a serial port)') for k in unused]
        else:
            unused = [k for k in _SERIAL_KEYS if k in given]
            if self.protocol != "nmea2000" and "name" in given:
                unused.append("name")
            problems += [(k, f'not with protocol = "{self.protocol}" (CAN)') for k in unused]
            if self.channel is not None and self.interface is None:
                problems.append(("interface", "missing (the compass's own bus needs one)"))
            if self.interface is not None and self.channel is None:
                problems.append(("channel", 'missing (the compass\'s own bus, e.g. "can1")'))
        if self.protocol == "cia406":
            if self.node_id is None:
                problems.append(("node_id", 'missing (protocol = "cia406")'))
            if self.counts_per_revolution is None and self.eds is None:
                why = 'missing (protocol = "cia406" without an eds: the encoder\'s 0x6001)'
                problems.append(("counts_per_revolution", why))
        check(problems)
        return self

    def encoder(self) -> Encoder | None:
        """The CiA 406 encoder (None for other protocols): the plan's keys over its EDS's
        defaults (PlanError naming an EDS gyrostand cannot use)."""
        if self.protocol != "cia406" or self.node_id is None:
            return None
        sign = 1 if self.direction == "clockwise" else -1
        if self.eds is None:
            assert self.counts_per_revolution is not None  # (validated)
            heartbeat_ms = self.heartbeat_ms or 0
            return Encoder(
                self.node_id, self.counts_per_revolution, None, self.zero_counts, sign,
                heartbeat_ms=heartbeat_ms,
            )  # fmt: skip
        try:
            return encoder_from_eds(
                Path(self.eds),
                self.node_id,
                counts_per_revolution=self.counts_per_revolution,
                zero_counts=self.zero_counts,
                sign=sign,
                heartbeat_ms=self.heartbeat_ms,
            )
        except EncoderError as exc:
            raise PlanError([f"[compass] eds: {exc}"]) from None

    @property
    def own_bus(self) -> bool:
        """The compass on a CAN bus of its own (not the stand's)."""
        return self.interface is not None

    @property
    def bus_label(self) -> str:
        """Its own bus in messages, e.g. "the compass's bus (socketcan can1)"."""
        return f"the compass's bus ({self.interface} {self.channel})"


InclinometerProtocol = Literal["cia410", "j1939"]
CIA410_STEP_DEG = 0.01  # CiA 410 slope in 0.01 deg (resolution 0x6000 = 10, its usual setting)


class InclinometerPlan(_Table):
    """[inclinometer]: an inclinometer on the roll platform that measures the roll the stand
    really makes (docs/instruments.md), on the stand's bus. "cia410": a CANopen CiA 410
    inclinometer sending its slopes in TPDO1 (event timer or SYNC), heard without SDO access;
    "j1939": a J1939 one sending Slope Sensor Information 2 (PGN 61481)."""

    protocol: InclinometerProtocol
    """How the inclinometer sends its slope."""
    node_id: int | None = Field(None, ge=1, le=127)
    """cia410: its CANopen node id (TPDO1 0x180 + node id, EMCY 0x80 + node id)."""
    source_address: int | None = Field(None, ge=0, le=253)
    """j1939: its source address."""
    axis: Literal["x", "y"] = "x"
    """The slope that follows the roll: "x" (cia410: slope long16, 0x6010, first in TPDO1;
    j1939: pitch) or "y" (cia410: slope lateral16, 0x6020, second; j1939: roll)."""
    scale: float = Field(CIA410_STEP_DEG, json_schema_extra=_no_default)
    """cia410: degrees per count of the slope (its resolution 0x6000 in 0.001 deg: 10 = 0.01
    deg), negative when mounted reversed; j1939: +1 or -1 times the standard 1/32768 deg."""
    interface: Interface | None = None
    """Its own CAN bus: not supported yet (the inclinometer sits on the stand's bus)."""
    channel: Channel | None = None
    """Its own bus's channel: not supported yet."""

    @model_validator(mode="before")
    @classmethod
    def _default_scale(cls, data: Any) -> Any:
        if isinstance(data, dict) and "scale" not in data:
            return {**data, "scale": 1.0 if data.get("protocol") == "j1939" else CIA410_STEP_DEG}
        return data

    @model_validator(mode="after")
    def _consistent(self) -> InclinometerPlan:
        given = self.model_fields_set
        problems = []
        if self.protocol == "cia410":
            if "node_id" not in given:
                problems.append(("node_id", 'missing (protocol = "cia410")'))
            if "source_address" in given:
                problems.append(("source_address", 'not with protocol = "cia410" (j1939\'s)'))
        else:
            if "source_address" not in given:
                problems.append(("source_address", 'missing (protocol = "j1939")'))
            if "node_id" in given:
                problems.append(("node_id", 'not with protocol = "j1939" (cia410\'s)'))
            if abs(self.scale) != 1.0:
                problems.append(("scale", "j1939: +1 or -1 (the slope's unit is the standard's)"))
        if self.scale == 0 or not math.isfinite(self.scale):
            problems.append(("scale", "must be a non-zero number"))
        for key in ("interface", "channel"):
            if key in given:
                problems.append(
                    (
                        key,
                        "an inclinometer on a bus of its own is not supported yet: put it on "
                        "the stand's bus",
                    )
                )
        check(problems)
        return self


StandProtocol = Literal["gyrostand", "cia402"]
K_PROMPT = "k_trial"  # the id of the prompt to set K by hand before trial N: k_trialN
_CIA402_KEYS = (
    "eds",
    "node_id",
    "counts_per_degree",
    "cycle_ms",
    "ramp_s",
    "drive_timeout_ms",
    "drive_heartbeat_ms",
)


class StandPlan(_Table):
    """[stand]: how the stand is commanded, and its limits, outside which it refuses a command;
    every trial must lie within them. With the simulated stand the simulator's limits
    ([bus.simulator.stand], default 50 cm, 2 to 20 s) apply as well: a key left out here is the
    simulator's (`Plan.stand_limits`). "gyrostand": a stand controller speaking gyrostand's
    STAND_COMMAND/STAND_MOTION frames; "cia402": a servo drive on CANopen (CiA 402) that
    gyrostand commands itself (docs/instruments.md)."""

    protocol: StandProtocol = "gyrostand"
    """How the stand is commanded."""
    max_amplitude_cm: float | None = Field(None, gt=0)
    """Largest amplitude A the stand accepts, cm."""
    min_period_s: float | None = Field(None, gt=0)
    """Shortest rocking period tau the stand accepts, s."""
    max_period_s: float | None = Field(None, gt=0)
    """Longest rocking period tau the stand accepts, s."""
    eds: Text | None = None
    """cia402: the drive's EDS file (the lab's, from the drive's maker)."""
    node_id: int | None = Field(None, ge=1, le=127)
    """cia402: the drive's CANopen node id."""
    counts_per_degree: float | None = Field(None, gt=0)
    """cia402: drive position units (0x607A/0x6064) per degree of roll of the platform."""
    arm_length_cm: float | None = Field(None, gt=0)
    """The arm at which the amplitude A is measured (A = arm x roll angle, rad), cm: for a
    cia402 stand, and for any stand with an [inclinometer] (which measures the roll angle)."""
    cycle_ms: int = Field(10, ge=1, le=250)
    """cia402: the SYNC cycle (cyclic synchronous position: one target per cycle), ms; at most
    250 (the interpolation period 0x60C2 is a byte of ms: drives take up to 255)."""
    ramp_s: float = Field(10.0, gt=0)
    """cia402: the smooth start and stop ramps of the roll's amplitude, s."""
    drive_timeout_ms: int = Field(300, ge=200, le=65535)
    """cia402: the drive's consumer time of gyrostand's heartbeat (0x1016, written at start;
    gyrostand beats every `drive_heartbeat_ms`): a gyrostand silent this long is taken for dead
    and the drive quick-stops, ms."""
    drive_heartbeat_ms: int = Field(100, ge=10, le=65535)
    """cia402: the heartbeat producer period of gyrostand and of the drive (its 0x1017, written
    at start), ms; the drive's heartbeat missing for 3 periods is an event and fails the
    rocking."""

    @model_validator(mode="after")
    def _consistent(self) -> StandPlan:
        low, high = self.min_period_s, self.max_period_s
        problems = []
        if low is not None and high is not None and high < low:
            problems.append(("max_period_s", "must be >= min_period_s"))
        given = self.model_fields_set
        if self.protocol == "cia402":
            needed = ("eds", "node_id", "counts_per_degree", "arm_length_cm")
            problems += [(k, 'missing (protocol = "cia402")') for k in needed if k not in given]
            if self.drive_timeout_ms <= self.drive_heartbeat_ms:  # (CiA 301: consumer > producer)
                problems.append(("drive_timeout_ms", "must be > drive_heartbeat_ms"))
        else:
            problems += [
                (k, f'not with protocol = "{self.protocol}" (a CiA 402 drive\'s)')
                for k in _CIA402_KEYS
                if k in given
            ]
        check(problems)
        return self


@dataclass(frozen=True)
class StandLimit:
    """One limit of the stand a plan's trials must respect, and where it comes from."""

    value: float
    source: Literal["stand", "simulator"]
    """"stand": the plan's [stand]; "simulator": the simulated stand's [bus.simulator.stand]."""


_STAND_LIMITS = (  # trial key, StandLimits field, whether a maximum, unit
    ("amplitude_cm", "max_amplitude_cm", True, "cm"),
    ("period_s", "min_period_s", False, "s"),
    ("period_s", "max_period_s", True, "s"),
)


@dataclass(frozen=True)
class StandLimits:
    """The binding limits of the stand that runs a plan (None: not known, not checked)."""

    max_amplitude_cm: StandLimit | None
    min_period_s: StandLimit | None
    max_period_s: StandLimit | None

    def broken(
        self, motion: TrialPlan | RollingPoint
    ) -> list[tuple[str, str, StandLimit, bool, str]]:
        """The limits a motion (amplitude_cm, period_s) breaks: (its key, the limit's field,
        the limit, whether a maximum, the unit)."""
        out = []
        for key, limit_key, maximum, unit in _STAND_LIMITS:
            limit: StandLimit | None = getattr(self, limit_key)
            value = getattr(motion, key)
            if limit is not None and (value > limit.value if maximum else value < limit.value):
                out.append((key, limit_key, limit, maximum, unit))
        return out


class ProtocolPlan(_Table):
    """[protocol]"""

    dbc_path: Text | None = None
    """The lab's DBC file (default: the shipped stand/gyrostand.dbc)."""


class AcceptancePlan(_Table):
    """[acceptance]: optional acceptance by excursions (Sveshnikov, section 8.3): the reading
    must stay within +-`tolerance_deg` of its mean for `duration_s` stand seconds, with a
    probability of at least one excursion of at most `max_risk`."""

    tolerance_deg: float = Field(gt=0)
    """Half-width of the tolerance band, deg."""
    duration_s: float = Field(gt=0)
    """Stand seconds the reading must stay within it."""
    max_risk: float = Field(gt=0, lt=1)
    """Largest acceptable probability of an excursion."""


class ReportPlan(_Table):
    """[report]: what the stand report identifies besides the campaign (the items of ISO/IEC
    17025, 7.8.2); a key left out is printed "not stated" (for a simulated stand, what does
    not apply says so). A report lacking its number, laboratory, customer, the instrument's
    manufacturer, the dates of the trials or its sign-offs is a DRAFT."""

    number: Text | None = None
    """Report number the laboratory assigns (`gyrostand report --number` overrides it)."""
    laboratory: Text | None = None
    """Laboratory: name and address, and where the trials were made if elsewhere."""
    customer: Text | None = None
    """Customer: name and address."""
    stand: Text | None = None
    """Rolling stand: make, model, serial number."""
    stand_calibration: Text | None = None
    """Stand calibration: certificate, date, next due."""
    reference_heading: Text | None = None
    """Reference heading: its source and uncertainty."""
    environment: Text | None = None
    """Environmental conditions during the trials (temperature, humidity, supply)."""
    dates: Text | None = None
    """Dates of the trials when the campaign does not record them (imported data)."""


_SIGNALS_SCHEMA = {
    "properties": {name: {"type": "string"} for name in _SIGNALS},
    "additionalProperties": False,
}


class Plan(_Table):
    """A campaign plan (gyrostand): instrument, site, analysis, the trials of the design and how
    to acquire them. `text` is the TOML as submitted (stored with the campaign)."""

    model_config = ConfigDict(title="gyrostand campaign plan")

    campaign: CampaignPlan
    instrument: InstrumentPlan
    site: SitePlan
    analysis: AnalysisPlan
    forecast: ForecastPlan
    trials: tuple[TrialPlan, ...] = Field(strict=False, json_schema_extra={"minItems": 1})
    """The design, in order; at least 3 trials have role "fit" (at least one when [campaign]
    acquisition_only = true)."""
    observation: ObservationPlan = Field(default_factory=ObservationPlan)
    settle: SettlePlan = Field(default_factory=SettlePlan)
    tracking: TrackingPlan = Field(default_factory=TrackingPlan)
    timeouts: TimeoutsPlan = Field(default_factory=TimeoutsPlan)
    checks: ChecksPlan = Field(default_factory=ChecksPlan)
    bus: BusPlan = Field(default_factory=BusPlan)
    compass: CompassPlan = Field(default_factory=CompassPlan)
    stand: StandPlan = Field(default_factory=StandPlan)
    inclinometer: InclinometerPlan | None = None
    protocol: ProtocolPlan = Field(default_factory=ProtocolPlan)
    signals: Signals = Field(default_factory=dict, json_schema_extra=_SIGNALS_SCHEMA)
    """The lab's DBC signals, "MESSAGE.SIGNAL" per quantity (docs/protocol.md)."""
    acceptance: AcceptancePlan | None = None
    report: ReportPlan = Field(default_factory=ReportPlan)
    prompt: tuple[PromptPlan, ...] = Field((), strict=False)
    """Questions to the operator before the campaign or a trial ([[prompt]])."""
    procedure: tuple[ProcedurePlan, ...] = Field((), strict=False)
    """The standard's own tests ([[procedure]]), run before the trials."""
    reference: ReferencePlan | None = None
    standard: StandardPlan = Field(default_factory=StandardPlan)
    _text: str = PrivateAttr("")

    @field_validator("trials")
    @classmethod
    def _design(cls, trials: tuple[TrialPlan, ...]) -> tuple[TrialPlan, ...]:
        if not trials:
            raise ValueError("must list at least one trial")
        if not any(t.role == "fit" for t in trials):
            raise ValueError("at least one trial must have role 'fit'")
        return trials

    @model_validator(mode="after")
    def _number_trials(self) -> Plan:
        for number, trial in enumerate(self.trials, start=1):
            trial._index = number
        return self

    @model_validator(mode="after")
    def _direction_prompts(self) -> Plan:
        """A CiA 402 stand rolls about one axis: the direction K is set by turning the compass
        on the platform by hand. Before each trial whose K differs from the one before (and
        the first), a prompt asks the operator to set it and confirm (`k_trialN`)."""
        if self.stand.protocol != "cia402":
            return self
        asked, previous = [], None
        for trial in self.trials:
            if trial.direction_deg != previous:
                text = (
                    f"turn the compass on the platform to K = {trial.direction_deg:g} deg "
                    "(the direction of roll) and confirm"
                )
                prompt = PromptPlan(id=f"{K_PROMPT}{trial.index}", text=text, before=trial.index)
                asked.append(prompt)
            previous = trial.direction_deg
        object.__setattr__(self, "prompt", self.prompt + tuple(asked))  # (a frozen model)
        return self

    @model_validator(mode="after")
    def _feasible(self) -> Plan:
        """The rules across tables, once every table is valid: a design the analysis can fit
        (or an acquisition-only campaign), every trial within the stand's limits, every series
        within the stand time allowed. (A ValidationError, which pydantic passes on as it is,
        to name each problem's table and key.)"""
        errors = (
            self._unanalysable()
            + self._beyond_stand()
            + self._too_long()
            + self._bad_prompts()
            + self._bad_compass()
            + self._bad_inclinometer()
            + self._bad_procedures()
        )
        if errors:
            raise ValidationError.from_exception_data(type(self).__name__, errors)
        return self

    @property
    def stand_limits(self) -> StandLimits:
        """The limits each trial must respect: the tighter of [stand] and, for the simulated
        stand, the simulator's ([bus.simulator.stand] over its defaults); [stand] on a tie."""
        simulator = None
        if self.bus.simulated:
            bus = self.bus
            simulator = simulator_config(
                bus.simulator, speedup=bus.speedup, seed=bus.seed, timing=bus.timing
            ).stand

        def limit(key: str, maximum: bool) -> StandLimit | None:
            given = []
            if (value := getattr(self.stand, key)) is not None:
                given.append(StandLimit(value, "stand"))
            if simulator is not None:
                given.append(StandLimit(getattr(simulator, key), "simulator"))
            if not given:
                return None
            return (min if maximum else max)(given, key=lambda g: g.value)

        return StandLimits(
            limit("max_amplitude_cm", True),
            limit("min_period_s", False),
            limit("max_period_s", True),
        )

    def _unanalysable(self) -> list[InitErrorDetails]:
        fit = sum(t.role == "fit" for t in self.trials)
        if fit >= MIN_FIT_TRIALS or self.campaign.acquisition_only:
            return []
        message = (
            f"{fit} fit trial{'s' if fit > 1 else ''}, but the analysis needs at least "
            f"{MIN_FIT_TRIALS} (m + 1 for the m = {FIT_PARAMETERS} parameters C and T: the "
            "adequacy test needs n - m >= 1 degrees of freedom); add fit trials, or set "
            "[campaign] acquisition_only = true to acquire without analysing"
        )
        return [_error("design", ("trials",), message)]

    def _beyond_stand(self) -> list[InitErrorDetails]:
        limits = self.stand_limits
        errors = []
        for row, trial in enumerate(self.trials):
            for key, limit_key, limit, maximum, unit in limits.broken(trial):
                value = getattr(trial, key)
                # the simulator's limit is "the simulated stand's" when [stand] states another
                simulated = limit.source == "simulator" and limit_key in self.stand.model_fields_set
                message = (
                    f"{_number(value)} {'exceeds' if maximum else 'is below'} "
                    f"the {'simulated stand' if simulated else 'stand'}'s limit "
                    f"{_number(limit.value)} {unit}"
                )
                errors.append(_error("stand_limit", ("trials", row, key), message))
        return errors

    def _too_long(self) -> list[InitErrorDetails]:
        observation = self.observation
        window_ms = max(
            observation.window_ms(period) for period in [None, *(t.period_s for t in self.trials)]
        )
        spacing_ms = round(observation.spacing_s * 1000)
        series_ms = self.n_obs * (window_ms + spacing_ms)
        if series_ms <= MAX_SERIES_STAND_DAYS * 86_400_000:
            return []
        message = (
            f"{self.n_obs} x ({_number(window_ms / 1000)} s window + "
            f"{_number(spacing_ms / 1000)} s spacing) = {series_ms / 86_400_000:.1f} days of stand "
            f"time in the longest series; a series may take at most {MAX_SERIES_STAND_DAYS} days"
        )
        return [_error("stand_time", ("campaign", "n_obs"), message)]

    def _bad_prompts(self) -> list[InitErrorDetails]:
        errors, seen = [], set()
        for row, prompt in enumerate(self.prompt):
            if prompt.id in seen:
                errors.append(_error("prompt", ("prompt", row, "id"), f"{prompt.id!r} twice"))
            seen.add(prompt.id)
            if isinstance(prompt.before, int) and prompt.before > len(self.trials):
                message = f"trial {prompt.before}, but the plan has {len(self.trials)} trials"
                errors.append(_error("prompt", ("prompt", row, "before"), message))
        return errors

    def _bad_compass(self) -> list[InitErrorDetails]:
        compass, errors = self.compass, []
        if compass.protocol == "dbc" and self.protocol.dbc_path is None:
            message = 'protocol = "dbc" needs the lab\'s DBC ([protocol] dbc_path)'
            errors.append(_error("compass", ("compass", "protocol"), message))
        if (
            compass.protocol in ("nmea2000", "cia406", "iec61162")
            and not self.bus.simulated
            and self.bus.timing == "virtual"
        ):
            message = (
                'a compass timed by reception needs timing = "realtime" on a real bus (a stand '
                "in virtual time there runs unrelated to the reception clock)"
            )
            errors.append(_error("compass", ("compass", "protocol"), message))
        if self.bus.simulated and compass.own_bus and compass.interface != "virtual":
            message = (
                "beside the simulated stand the compass's own bus is \"virtual\" (python-can's "
                "in-process bus: the simulated compass on a bus of its own)"
            )
            errors.append(_error("compass", ("compass", "interface"), message))
        same = (compass.interface, compass.channel) == (self.bus.interface, self.bus.channel)
        if compass.own_bus and same:
            message = (
                "the stand's bus ([bus]): leave interface and channel out for a compass on the "
                "stand's bus"
            )
            errors.append(_error("compass", ("compass", "channel"), message))
        return errors

    def _bad_inclinometer(self) -> list[InitErrorDetails]:
        if self.inclinometer is None or self.stand.arm_length_cm is not None:
            return []
        message = "missing: the inclinometer measures the roll angle; A is arm x angle (rad)"
        return [_error("inclinometer", ("stand", "arm_length_cm"), message)]

    def _bad_procedures(self) -> list[InitErrorDetails]:
        """One procedure of each kind, those following the settling run-up with one, and the
        rolling points within the stand's limits unless forecast."""
        errors = [
            _error("procedure", ("procedure", row), message)
            for row, message in duplicated(self.procedure) + needs(self.procedure)
        ]
        if self.procedure and not self.bus.simulated:
            errors += self._bad_procedures_on_a_real_bus()
        if self.procedure and self.settle.transient_model is None:
            message = (
                "the standard's procedures need the compass's precession: [settle] "
                "undamped_period_s and damping_ratio (instrument data)"
            )
            errors.append(_error("procedure", ("settle", "undamped_period_s"), message))
        limits = self.stand_limits
        for row, proc in enumerate(self.procedure):
            if proc.points is None or proc.beyond_stand == "forecast":
                continue
            for n, point in enumerate(proc.points):
                for key, _, limit, maximum, unit in limits.broken(point):
                    value = getattr(point, key)
                    message = (
                        f"rolling point {n + 1} (K {_number(point.direction_deg)} deg, A "
                        f"{_number(point.amplitude_cm)} cm, tau {_number(point.period_s)} s): "
                        f"{_number(value)} {unit} {'exceeds' if maximum else 'is below'} the "
                        f"stand's limit {_number(limit.value)} {unit}; the stand cannot reach it "
                        '(beyond_stand = "forecast" forecasts it by model 1.1 instead)'
                    )
                    errors.append(_error("stand_limit", ("procedure", row, "points"), message))
        return errors

    def _bad_procedures_on_a_real_bus(self) -> list[InitErrorDetails]:
        """On a real bus the procedures run in real time on a compass on CAN and a stand of
        gyrostand's protocol, the compass switched by the operator (the stand's protocol has no
        power control gyrostand could command)."""
        errors = [
            _error("procedure", ("procedure", row, "power"), message)
            for row, proc in enumerate(self.procedure)
            if proc.kind in ("settling", "repeatability") and proc.power == "stand"
            for message in (
                f'{proc.kind}: power = "stand" on a real bus: gyrostand cannot switch the '
                'compass there (its stand protocol has no power control); power = "manual": '
                "the operator switches it, prompted",
            )
        ]
        unsupported = (
            (
                self.bus.timing == "virtual",
                ("bus", "timing"),
                'timing = "virtual" (they run in real time: timing = "realtime")',
            ),
            (
                self.compass.protocol == "iec61162",
                ("compass", "protocol"),
                "a compass on a serial line (not yet: a compass on CAN)",
            ),
            (
                self.stand.protocol == "cia402",
                ("stand", "protocol"),
                "a CiA 402 stand (not yet: a stand of gyrostand's protocol or a lab DBC)",
            ),
        )
        for broken, loc, what in unsupported:
            if broken:
                message = f"the standard's procedures on a real bus: not with {what}"
                errors.append(_error("procedure", loc, message))
        return errors

    @property
    def heading_source(self) -> tuple[str, str | None, tuple[str, str], Encoder | None]:
        """The compass as `devices.decoder.frame_decoder` takes it: [compass] protocol and name,
        [instrument] model and serial (NMEA 2000 product information), the CiA 406 encoder."""
        instrument = (self.instrument.model, self.instrument.serial)
        return self.compass.protocol, self.compass.name, instrument, self.compass.encoder()

    @property
    def inclinometer_mount(self) -> tuple[str, int, str, float] | None:
        """The [inclinometer] as `devices.inclinometer.Mount` takes it: protocol, node id or
        source address, axis, scale."""
        incl = self.inclinometer
        if incl is None:
            return None
        address = incl.node_id if incl.protocol == "cia410" else incl.source_address
        assert address is not None
        return incl.protocol, address, incl.axis, incl.scale

    def prompts_before(self, before: str | int) -> tuple[PromptPlan, ...]:
        """The prompts asked before the campaign ("campaign") or before trial `before`."""
        return tuple(p for p in self.prompt if p.before == before)

    @property
    def text(self) -> str:
        return self._text

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.text.encode()).hexdigest()

    @property
    def operator(self) -> str:
        return self.campaign.operator

    @property
    def n_obs(self) -> int:
        return self.campaign.n_obs

    @property
    def residual_dof(self) -> int:
        """n - m: the fit trials less the parameters C and T (the dof of S^2_r, eq 2.7)."""
        return sum(t.role == "fit" for t in self.trials) - FIT_PARAMETERS

    @property
    def database(self) -> str:
        return self.campaign.database

    @property
    def raw_log_format(self) -> Literal["blf", "asc"]:
        return self.campaign.raw_log_format

    @property
    def raw_log_dir(self) -> str:
        """The folder the plan names, else `raw` beside the database file."""
        if self.campaign.raw_log_dir is not None:
            return self.campaign.raw_log_dir
        if "://" in self.database:
            return "runs/raw"
        return str(Path(self.database).parent / "raw")

    @property
    def on_trial_failure(self) -> Literal["continue", "pause"]:
        return self.campaign.on_trial_failure

    @property
    def dbc_path(self) -> str | None:
        return self.protocol.dbc_path


class OperatorPlan(_Table):
    """[campaign] of the partial form: who made the measurements."""

    operator: Text
    """Who made the measurements."""


class PartialPlan(_Table):
    """The partial form of a plan: no campaign to run, only what describes the data and their
    analysis. Without [analysis] or [forecast] the analysis takes the example values of
    Potemkin (1982) and says so."""

    model_config = ConfigDict(title="gyrostand plan, partial form")

    campaign: OperatorPlan | None = None
    instrument: InstrumentPlan
    site: SitePlan
    analysis: AnalysisPlan | None = None
    forecast: ForecastPlan | None = None
    report: ReportPlan = Field(default_factory=ReportPlan)


def _error(kind: str, loc: tuple[str | int, ...], message: str) -> InitErrorDetails:
    """One problem of a cross-table rule, at its place in the plan."""
    return InitErrorDetails(
        type=PydanticCustomError(kind, "{message}", {"message": message}), loc=loc, input=None
    )


# ------------------------------------------------------------------------------ reading


def parse_plan(text: str) -> Plan:
    """Validate a plan given as TOML text; raise `PlanError` listing every problem."""
    return _validate(Plan, _document(text), text)


def load_plan(path: Path) -> Plan:
    """Read and validate a plan file; unreadable files raise `PlanError` too."""
    return parse_plan(read_text(path))


def parse_any_plan(text: str) -> Plan | PartialPlan:
    """A whole plan, or the partial form when it has no [[trials]] (PlanError as `parse_plan`)."""
    document = _document(text)
    if "trials" in document:
        return _validate(Plan, document, text)
    return _validate(PartialPlan, document, text)


def load_any_plan(path: Path) -> Plan | PartialPlan:
    """`parse_any_plan` of a file."""
    return parse_any_plan(read_text(path))


def read_text(path: Path) -> str:
    """A plan file's text (PlanError when it cannot be read)."""
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise PlanError([f"cannot read the file ({reason})"]) from None


def revised(plan: Plan, text: str | None = None, **tables: Mapping[str, Any]) -> Plan:
    """The plan with some keys changed, per table (``revised(plan, bus={"seed": 2})``), and
    validated as the file is; `text` stays the file's unless given (the text to store)."""
    document = plan.model_dump(exclude_unset=True)
    for table, changes in tables.items():
        document[table] = {**document.get(table, {}), **changes}
    return _validate(Plan, document, plan.text if text is None else text)


def schema() -> dict[str, Any]:
    """The JSON Schema of a plan file (TOML read as JSON), with every field's description."""
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **Plan.model_json_schema()}


def _document(text: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise PlanError([f"TOML syntax: {exc}"]) from None


_M = TypeVar("_M", Plan, PartialPlan)


def _validate(model: type[_M], document: dict[str, Any], text: str) -> _M:
    try:
        plan = model.model_validate(document)
    except ValidationError as exc:
        raise PlanError(problems(model, exc.errors(include_url=False))) from None
    if isinstance(plan, Plan):
        plan._text = text
    return plan
