"""The standard's own tests in a plan, beside the paper's trials: ``[[procedure]]`` (settling,
settle point, repeatability, rolling), the stand's ``[reference]`` heading, and ``[standard]``,
the compliance profile whose procedures give the defaults.

A key left out is the profile's (the standard's procedure); a key given is the plan's and, where
it differs from the profile's, a departure that the report states (`report.procedures`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from pydantic import BaseModel, Field, StringConstraints, model_validator

from gyrostand.stand.tables import TABLE_CONFIG, check

Kind = Literal["settling", "settle_point", "repeatability", "rolling"]
KINDS: tuple[Kind, ...] = ("settling", "settle_point", "repeatability", "rolling")
Text = Annotated[str, StringConstraints(pattern=r"\S")]

_KEYS: dict[str, tuple[str, ...]] = {  # the keys each kind takes, besides kind
    "settling": ("band_deg", "max_wait_s", "fit_from_s", "power"),
    "settle_point": ("readings", "interval_s"),
    "repeatability": ("runups", "off_s", "readings", "interval_s", "power"),
    "rolling": ("points", "beyond_stand", "wait_s", "readings", "interval_s"),
}


class _Table(BaseModel):
    model_config = TABLE_CONFIG


class RollingPoint(_Table):
    """One point of the rolling envelope the stand rocks at."""

    direction_deg: float = Field(ge=0, lt=360)
    """Rocking direction K, deg (the intercardinal courses: 45, 135, 225, 315)."""
    amplitude_cm: float = Field(gt=0)
    """Rocking amplitude A, cm."""
    period_s: float = Field(gt=0)
    """Rocking period tau, s."""


class ProcedurePlan(_Table):
    """[[procedure]]: one of the standard's tests; keys left out are the profile's."""

    kind: Kind
    """settling (from switch-on), settle_point (readings after settling), repeatability (the
    settle points of several run-ups), rolling (the error at the envelope's points)."""
    band_deg: float | None = Field(None, gt=0)
    """settling: width of the band the reading must stay within, deg (profile: 0.7)."""
    max_wait_s: float | None = Field(None, gt=0)
    """settling: how long the run-up is recorded from switch-on, s (profile: its limit)."""
    fit_from_s: float | None = Field(None, ge=0)
    """settling: the record fitted starts this long after switch-on, s (default: a quarter of
    the compass's undamped precession period, [settle] undamped_period_s)."""
    readings: int | None = Field(None, ge=2)
    """settle_point, repeatability, rolling: readings taken (profile: 10)."""
    interval_s: float | None = Field(None, gt=0)
    """settle_point, repeatability, rolling: seconds between readings (profile: 1200)."""
    runups: int = Field(3, ge=2)
    """repeatability: run-ups, each from switch-on (the first is the settling run-up's)."""
    off_s: float = Field(600.0, gt=0)
    """repeatability: how long the compass stays off between run-ups, s."""
    power: Literal["stand", "manual"] = "stand"
    """settling, repeatability: who switches the compass on and off: the stand's power control
    (the simulated stand's; a real stand's protocol has none: refused on a real bus), or the
    operator by hand, prompted (at the station, on the terminal or `--answer`)."""
    points: tuple[RollingPoint, ...] | None = Field(None, strict=False)
    """rolling: the envelope's points (default: the profile's envelope periods at its largest
    horizontal acceleration, K = 45 deg)."""
    beyond_stand: Literal["refuse", "forecast"] = "refuse"
    """rolling: a point the stand cannot reach refuses the plan, or is forecast by model 1.1
    from the paper's trials (labelled a forecast)."""
    wait_s: float = Field(5400.0, ge=0)
    """rolling: stand seconds of rocking before the readings (the transient to the new
    equilibrium)."""

    @model_validator(mode="after")
    def _keys_of_kind(self) -> ProcedurePlan:
        allowed = set(_KEYS[self.kind]) | {"kind"}
        check(
            [
                (key, f"not a key of a {self.kind} procedure")
                for key in sorted(self.model_fields_set - allowed)
            ]
        )
        return self


class ReferencePlan(_Table):
    """[reference]: the stand's reference (true) heading of the compass's lubber line."""

    heading_deg: float = Field(ge=0, lt=360)
    """The reference heading, deg."""
    uncertainty_deg: float = Field(gt=0)
    """Its standard uncertainty, deg."""
    source: Text | None = None
    """How it was established (e.g. "theodolite to the lab's meridian mark, 2026-05-04")."""


class StandardPlan(_Table):
    """[standard]: the compliance profile whose procedures and limits apply."""

    profile: Text = "imo-a424"
    """A shipped profile's name or a profile file (as `gyrostand report --profile`)."""


def duplicated(procedures: tuple[ProcedurePlan, ...]) -> list[tuple[int, str]]:
    """(row, message) for each procedure whose kind an earlier row already has."""
    seen: set[str] = set()
    out = []
    for row, proc in enumerate(procedures):
        if proc.kind in seen:
            out.append((row, f"a second {proc.kind} procedure (one of each kind)"))
        seen.add(proc.kind)
    return out


def needs(procedures: tuple[ProcedurePlan, ...]) -> list[tuple[int, str]]:
    """(row, message) for a procedure that needs another: settle_point and rolling follow the
    settling run-up."""
    kinds = {p.kind for p in procedures}
    return [
        (row, f"a {p.kind} procedure needs a settling procedure (it follows that run-up)")
        for row, p in enumerate(procedures)
        if p.kind in ("settle_point", "repeatability", "rolling") and "settling" not in kinds
    ]


@dataclass(frozen=True)
class ResolvedProcedure:
    """A procedure with every key filled (the plan's or the profile's) and the plan's
    departures from the profile's procedure, in words (empty: the standard's procedure)."""

    plan: ProcedurePlan
    departures: tuple[str, ...]

    @property
    def kind(self) -> Kind:
        return self.plan.kind
