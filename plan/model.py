"""The campaign plan: a TOML file read with tomllib and validated in full before anything runs.

Every problem is reported with its field path (``trials[3].period_s: must be > 0``) in one
`PlanError`, so an operator fixes the whole file at once and the bus and database stay untouched.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from gyrostand.stand.simconfig import TIMINGS

Role = Literal["fit", "control"]


class PlanError(ValueError):
    """A plan that cannot run; `problems` lists every defect as ``path: message``."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        super().__init__("invalid plan: " + "; ".join(problems))


@dataclass(frozen=True)
class InstrumentPlan:
    """The compass under test and its known constants B (seed 000 eq 1.1)."""

    model: str
    serial: str
    lp_gcm2s2: float
    h1_gcm2s: float


@dataclass(frozen=True)
class SitePlan:
    latitude_deg: float
    earth_rate_rad_s: float
    gravity_cm_s2: float


@dataclass(frozen=True)
class TrialPlan:
    """One row of the design: rocking direction K, amplitude A, period tau, fit or control."""

    index: int  # 1-based
    direction_deg: float
    amplitude_cm: float
    period_s: float
    role: Role


@dataclass(frozen=True)
class ObservationPlan:
    """Observation windows in stand time: seconds when still, whole rocking periods when rocking."""

    still_window_s: float
    rocking_window_periods: int
    spacing_s: float

    def window_ms(self, rocking_period_s: float | None) -> int:
        """Window length in stand milliseconds for a still (None) or rocking series."""
        if rocking_period_s is None:
            return round(self.still_window_s * 1000)
        return round(self.rocking_window_periods * rocking_period_s * 1000)


@dataclass(frozen=True)
class SettlePlan:
    """Settled (method "band") when the window means over the last `hold_s` stand seconds all
    lie within +-`band_deg` of their mean and their least-squares trend moves the reading by at
    most `drift_deg` over that time (a damped transient that is not over yet, seed 003). Method
    "estimate" settles by `estimate` instead; the band criterion then only measures the time
    saved. `max_wait_s` bounds both."""

    band_deg: float
    drift_deg: float
    hold_s: float
    max_wait_s: float
    method: Literal["band", "estimate"] = "band"
    estimate: EstimatePlan | None = None  # set when method = "estimate"


@dataclass(frozen=True)
class EstimatePlan:
    """Early settle (seed 003): observe once the settle point estimated from the transient is
    stable. The transient's undamped period 2 pi / omega0 and damping ratio xi / omega0 are
    instrument data; the tolerance is `tolerance_fraction` x the expected S{<delta>}_e of
    seed 000 eq 2.6."""

    undamped_period_s: float
    damping_ratio: float
    expected_se_deg: float
    tolerance_fraction: float
    stable_estimates: int

    @property
    def tolerance_deg(self) -> float:
        return self.tolerance_fraction * self.expected_se_deg

    @property
    def omega_rad_s(self) -> float:
        """Damped angular frequency omega = sqrt(omega0^2 - xi^2) (seed 003 eq 2)."""
        return 2.0 * math.pi / self.undamped_period_s * math.sqrt(1.0 - self.damping_ratio**2)

    @property
    def damping_per_s(self) -> float:
        """xi of seed 003 eq 1."""
        return 2.0 * math.pi / self.undamped_period_s * self.damping_ratio


@dataclass(frozen=True)
class TrackingPlan:
    """How closely the stand's measured rocking must follow the command, and for how long."""

    amplitude_rel: float
    period_rel: float
    direction_deg: float
    confirm_s: float  # stand seconds allowed for the stand to reach the commanded motion


@dataclass(frozen=True)
class ChecksPlan:
    max_error_frames: int  # per series; more fails the trial


@dataclass(frozen=True)
class TimeoutsPlan:
    ack_s: float  # wall seconds for a command acknowledgement
    bus_silence_s: float  # stand seconds without a heading frame


@dataclass(frozen=True)
class AcceptancePlan:
    """Optional acceptance by excursions (seed 004 eqs 8.79-8.88): the reading must stay within
    +-`tolerance_deg` of its mean for `duration_s` stand seconds, with probability of at least
    one excursion at most `max_risk`."""

    tolerance_deg: float
    duration_s: float
    max_risk: float


@dataclass(frozen=True)
class BusPlan:
    """Where the frames come from: the in-process simulated stand, or a python-can bus."""

    simulated: bool
    interface: str | None = None
    channel: str | None = None
    bitrate: int | None = None
    timing: Literal["virtual", "realtime"] = "realtime"  # virtual: stand.virtual_time
    speedup: float = 1.0
    seed: int = 0
    simulator: Mapping[str, Any] = field(default_factory=dict)
    queue_size: int = 200_000


@dataclass(frozen=True)
class Plan:
    """A validated campaign plan; `text` is the TOML as submitted (stored on the campaign)."""

    text: str
    operator: str
    n_obs: int
    database: str
    raw_log_format: Literal["blf", "asc"]
    raw_log_dir: str
    on_trial_failure: Literal["continue", "pause"]
    instrument: InstrumentPlan
    site: SitePlan
    analysis: Mapping[str, Any]
    forecast: Mapping[str, Any]
    trials: tuple[TrialPlan, ...]
    observation: ObservationPlan
    settle: SettlePlan
    tracking: TrackingPlan
    timeouts: TimeoutsPlan
    checks: ChecksPlan
    bus: BusPlan
    dbc_path: str | None
    signals: Mapping[str, Any]
    acceptance: AcceptancePlan | None = None

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.text.encode()).hexdigest()


class _Fields:
    """Reads one TOML table, recording every problem with its path instead of stopping."""

    def __init__(self, problems: list[str], table: Any, path: str) -> None:
        self.problems = problems
        self.path = path
        self.seen: set[str] = set()
        if not isinstance(table, Mapping):
            problems.append(f"{path}: must be a table")
            table = {}
        self.table = table

    def _where(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def bad(self, key: str, message: str) -> None:
        self.problems.append(f"{self._where(key)}: {message}")

    def _get(self, key: str, default: Any) -> Any:
        self.seen.add(key)
        if key not in self.table:
            if default is _REQUIRED:
                self.bad(key, "missing")
            return default
        return self.table[key]

    def number(
        self,
        key: str,
        default: Any = None,
        *,
        gt: float | None = None,
        ge: float | None = None,
        le: float | None = None,
        lt: float | None = None,
    ) -> float:
        value = self._get(key, default)
        if value is _REQUIRED or value is None:
            return math.nan
        numeric = isinstance(value, int | float) and not isinstance(value, bool)
        if not numeric or not math.isfinite(value):
            self.bad(key, "must be a finite number")
            return math.nan
        for bound, ok, text in (
            (gt, lambda b: value > b, "> "),
            (ge, lambda b: value >= b, ">= "),
            (le, lambda b: value <= b, "<= "),
            (lt, lambda b: value < b, "< "),
        ):
            if bound is not None and not ok(bound):
                self.bad(key, f"must be {text}{bound:g}")
        return float(value)

    def integer(self, key: str, default: Any = None, *, ge: int | None = None) -> int:
        value = self._get(key, default)
        if value is _REQUIRED or value is None:
            return 0
        if isinstance(value, bool) or not isinstance(value, int):
            self.bad(key, "must be an integer")
            return 0
        if ge is not None and value < ge:
            self.bad(key, f"must be >= {ge}")
        return value

    def text(self, key: str, default: Any = None, *, choices: tuple[str, ...] = ()) -> Any:
        value = self._get(key, default)
        if value is None:
            return None
        if value is _REQUIRED:
            return ""
        if not isinstance(value, str) or not value.strip():
            self.bad(key, "must be a non-empty string")
            return ""
        if choices and value not in choices:
            self.bad(key, f"must be one of {', '.join(repr(c) for c in choices)}, not {value!r}")
        return value

    def flag(self, key: str, default: bool) -> bool:
        value = self._get(key, default)
        if not isinstance(value, bool):
            self.bad(key, "must be true or false")
            return default
        return value

    def table_of(self, key: str) -> Mapping[str, Any]:
        value = self._get(key, {})
        if not isinstance(value, Mapping):
            self.bad(key, "must be a table")
            return {}
        return value

    def interval(self, key: str) -> None:
        value = self._get(key, None)
        if value is None:
            return
        ok = (
            isinstance(value, list)
            and len(value) == 2
            and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        )
        if not ok or not 0 < value[0] < value[1]:
            self.bad(key, "must be [low, high] with 0 < low < high")

    def done(self) -> None:
        """Report keys nobody asked for (usually typos)."""
        for key in sorted(set(self.table) - self.seen):
            self.bad(key, "unknown key")


_REQUIRED: Any = object()


def parse_plan(text: str) -> Plan:
    """Validate a plan given as TOML text; raise `PlanError` listing every problem."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise PlanError([f"TOML syntax: {exc}"]) from None
    problems: list[str] = []
    top = _Fields(problems, doc, "")
    for name in ("campaign", "instrument", "site", "analysis", "forecast", "trials"):
        if name not in doc:
            problems.append(f"{name}: missing")

    c = _Fields(problems, top.table_of("campaign"), "campaign")
    operator = c.text("operator", _REQUIRED)
    n_obs = c.integer("n_obs", _REQUIRED, ge=2)
    database = c.text("database", _REQUIRED)
    raw_log_format = c.text("raw_log_format", "blf", choices=("blf", "asc"))
    raw_log_dir = c.text("raw_log_dir", "runs/raw")
    on_failure = c.text("on_trial_failure", "continue", choices=("continue", "pause"))
    c.done()

    i = _Fields(problems, top.table_of("instrument"), "instrument")
    instrument = InstrumentPlan(
        model=i.text("model", _REQUIRED),
        serial=i.text("serial", _REQUIRED),
        lp_gcm2s2=i.number("lp_gcm2s2", _REQUIRED, gt=0),
        h1_gcm2s=i.number("h1_gcm2s", _REQUIRED, gt=0),
    )
    i.done()

    s = _Fields(problems, top.table_of("site"), "site")
    site = SitePlan(
        latitude_deg=s.number("latitude_deg", _REQUIRED, gt=-90, lt=90),
        earth_rate_rad_s=s.number("earth_rate_rad_s", 7.292115e-5, gt=0),
        gravity_cm_s2=s.number("gravity_cm_s2", 981.0, gt=0),
    )
    s.done()

    a = _Fields(problems, top.table_of("analysis"), "analysis")
    a.number("q", 0.05, gt=0, lt=1)
    a.number("start_c", _REQUIRED, gt=0)
    a.number("start_t_s", _REQUIRED, gt=0)
    a.interval("admissible_c")
    a.interval("admissible_t_s")
    a.done()

    f = _Fields(problems, top.table_of("forecast"), "forecast")
    f.number("roll_deg", _REQUIRED, gt=0, lt=90)
    f.number("arm_cm", _REQUIRED, gt=0)
    f.number("period_s", _REQUIRED, gt=0)
    f.number("course_deg", _REQUIRED, ge=0, lt=360)
    f.number("latitude_deg", _REQUIRED, gt=-90, lt=90)
    f.text("motion", "roll", choices=("roll", "pitch"))
    f.done()

    trials = _trials(problems, top._get("trials", []))

    o = _Fields(problems, top.table_of("observation"), "observation")
    observation = ObservationPlan(
        still_window_s=o.number("still_window_s", 60.0, gt=0),
        rocking_window_periods=o.integer("rocking_window_periods", 10, ge=1),
        spacing_s=o.number("spacing_s", 0.0, ge=0),
    )
    o.done()

    st = _Fields(problems, top.table_of("settle"), "settle")
    settle = SettlePlan(
        band_deg=st.number("band_deg", 0.02, gt=0),
        drift_deg=st.number("drift_deg", None, gt=0),
        hold_s=st.number("hold_s", 600.0, ge=0),
        max_wait_s=st.number("max_wait_s", 4 * 3600.0, gt=0),
        method=st.text("method", "band", choices=("band", "estimate")),
    )
    settle = dataclasses.replace(settle, estimate=_estimate(st, settle.method))
    st.done()
    if math.isnan(settle.drift_deg):  # not given: no trend condition
        settle = dataclasses.replace(settle, drift_deg=math.inf)
    if settle.max_wait_s < settle.hold_s:
        problems.append("settle.max_wait_s: must be >= settle.hold_s")

    tr = _Fields(problems, top.table_of("tracking"), "tracking")
    tracking = TrackingPlan(
        amplitude_rel=tr.number("amplitude_rel", 0.05, gt=0),
        period_rel=tr.number("period_rel", 0.05, gt=0),
        direction_deg=tr.number("direction_deg", 2.0, gt=0),
        confirm_s=tr.number("confirm_s", 120.0, gt=0),
    )
    tr.done()

    t = _Fields(problems, top.table_of("timeouts"), "timeouts")
    timeouts = TimeoutsPlan(
        ack_s=t.number("ack_s", 2.0, gt=0),
        bus_silence_s=t.number("bus_silence_s", 5.0, gt=0),
    )
    t.done()

    ch = _Fields(problems, top.table_of("checks"), "checks")
    checks = ChecksPlan(max_error_frames=ch.integer("max_error_frames", 10, ge=0))
    ch.done()

    bus = _bus(problems, top.table_of("bus"))

    p = _Fields(problems, top.table_of("protocol"), "protocol")
    dbc_path = p.text("dbc_path", None)
    p.done()
    signals = top.table_of("signals")
    acceptance = _acceptance(problems, top.table_of("acceptance")) if "acceptance" in doc else None
    top.done()

    if problems:
        raise PlanError(problems)
    return Plan(
        text=text,
        operator=operator,
        n_obs=n_obs,
        database=database,
        raw_log_format=raw_log_format,
        raw_log_dir=raw_log_dir,
        on_trial_failure=on_failure,
        instrument=instrument,
        site=site,
        analysis=dict(doc["analysis"]),
        forecast=dict(doc["forecast"]),
        trials=trials,
        observation=observation,
        settle=settle,
        tracking=tracking,
        timeouts=timeouts,
        checks=checks,
        bus=bus,
        dbc_path=dbc_path,
        signals=dict(signals),
        acceptance=acceptance,
    )


def _trials(problems: list[str], raw: Any) -> tuple[TrialPlan, ...]:
    if not isinstance(raw, list) or not raw:
        problems.append("trials: must be a non-empty array of tables ([[trials]])")
        return ()
    trials = []
    for n, row in enumerate(raw, start=1):
        r = _Fields(problems, row, f"trials[{n}]")
        trials.append(
            TrialPlan(
                index=n,
                direction_deg=r.number("direction_deg", _REQUIRED, ge=0, lt=360),
                amplitude_cm=r.number("amplitude_cm", _REQUIRED, gt=0),
                period_s=r.number("period_s", _REQUIRED, gt=0),
                role=r.text("role", "fit", choices=("fit", "control")),
            )
        )
        r.done()
    if trials and not any(t.role == "fit" for t in trials):
        problems.append("trials: at least one trial must have role 'fit'")
    return tuple(trials)


def _acceptance(problems: list[str], raw: Mapping[str, Any]) -> AcceptancePlan:
    a = _Fields(problems, raw, "acceptance")
    acceptance = AcceptancePlan(
        tolerance_deg=a.number("tolerance_deg", _REQUIRED, gt=0),
        duration_s=a.number("duration_s", _REQUIRED, gt=0),
        max_risk=a.number("max_risk", _REQUIRED, gt=0, lt=1),
    )
    a.done()
    return acceptance


_ESTIMATE_KEYS = (
    "undamped_period_s",
    "damping_ratio",
    "expected_se_deg",
    "tolerance_fraction",
    "stable_estimates",
)


def _estimate(st: _Fields, method: str) -> EstimatePlan | None:
    """The early-settle keys of [settle]: required with method = "estimate", refused with
    "band" (and left alone when the method itself is invalid: that is the one problem)."""
    if method != "estimate":
        for key in [k for k in _ESTIMATE_KEYS if k in st.table]:
            st.seen.add(key)
            if method == "band":
                st.bad(key, "only applies when settle.method = 'estimate'")
        return None
    return EstimatePlan(
        undamped_period_s=st.number("undamped_period_s", _REQUIRED, gt=0),
        damping_ratio=st.number("damping_ratio", _REQUIRED, ge=0, lt=1),
        expected_se_deg=st.number("expected_se_deg", _REQUIRED, gt=0),
        tolerance_fraction=st.number("tolerance_fraction", 0.5, gt=0, le=1),
        stable_estimates=st.integer("stable_estimates", 3, ge=2),
    )


def _bus(problems: list[str], raw: Mapping[str, Any]) -> BusPlan:
    b = _Fields(problems, raw, "bus")
    simulated = b.flag("simulated", True)
    interface = b.text("interface", None)
    channel = b._get("channel", None)
    if channel is not None and not isinstance(channel, str | int):
        b.bad("channel", "must be a string or an integer")
    bitrate = b.integer("bitrate", None, ge=1) or None
    timing = b.text("timing", "virtual" if simulated else "realtime", choices=TIMINGS)
    speedup = b.number("speedup", 1.0, gt=0)
    seed = b.integer("seed", 0, ge=0)
    simulator = b.table_of("simulator")
    queue_size = b.integer("queue_size", 200_000, ge=1)
    b.done()
    if simulated and interface is not None:
        b.bad("interface", "must be absent when bus.simulated = true")
    if not simulated and speedup != 1.0:
        b.bad("speedup", "only applies when bus.simulated = true")
    elif timing == "virtual" and speedup != 1.0:
        b.bad("speedup", 'only applies with timing = "realtime" (virtual time runs at full speed)')
    return BusPlan(
        simulated=simulated,
        interface=interface,
        channel=None if channel is None else str(channel),
        bitrate=bitrate,
        timing=timing,  # type: ignore[arg-type]
        speedup=speedup,
        seed=seed,
        simulator=dict(simulator),
        queue_size=queue_size,
    )


def load_plan(path: Path) -> Plan:
    """Read and validate a plan file; unreadable files raise `PlanError` too."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise PlanError([f"{path}: cannot read ({exc})"]) from None
    return parse_plan(text)
