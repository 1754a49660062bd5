"""Power and false-alarm rate of the fleet statistics (analysis/fleet.py) over repeated
simulated fleets: k groups of n units, each unit's true C and T drawn from the type's normal
distribution, estimated with a measurement error whose SE varies from unit to unit (as the
campaigns' fits give them); in half the fleets nothing is shifted (false alarms), in the
other half one group's T (and C) is shifted (power).

    .venv/bin/python validation/fleet_power.py [--fleets 4000] [--q 0.05]

Prints, per parameter: the F test's false-alarm rate (target 4-6 % at q = 0.05) and power,
how often the shifted group alone is set apart, Smirnov's rates, and how often a fleet without an
odd unit shows a unit outside the type's prediction interval."""

from __future__ import annotations

import argparse

import numpy as np

from gyrostand.analysis.fleet import FleetUnit, analyze_fleet

GROUPS, UNITS = ("A", "B", "C"), 5
C_MEAN, C_SD, C_SE = 6.0e7, 0.03 * 6.0e7, 0.02 * 6.0e7  # type's scatter, typical SE (g·cm²·s⁻²)
T_MEAN, T_SD, T_SE = 1.1, 0.03, 0.03  # s
SHIFT = 2.0  # the shifted group's offset, in units of the type's SD


def simulated_fleet(rng: np.random.Generator, shifted: bool) -> list[FleetUnit]:
    units = []
    for g, group in enumerate(GROUPS):
        offset = SHIFT if shifted and g == len(GROUPS) - 1 else 0.0
        for i in range(UNITS):
            c_se = C_SE * rng.uniform(0.5, 1.5)  # each campaign's own precision
            t_se = T_SE * rng.uniform(0.5, 1.5)
            c = C_MEAN + C_SD * (rng.standard_normal() + offset) + c_se * rng.standard_normal()
            t = T_MEAN + T_SD * (rng.standard_normal() + offset) + t_se * rng.standard_normal()
            units.append(FleetUnit(len(units) + 1, f"{group}-{i}", group, c, c_se, t, t_se))
    return units


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fleets", type=int, default=4000)
    parser.add_argument("--q", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=2026)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    counts = {
        (shifted, p, what): 0
        for shifted in (False, True)
        for p in ("C", "T")
        for what in ("F", "alone", "smirnov", "outside")
    }
    for _ in range(args.fleets):
        for shifted in (False, True):
            analysis = analyze_fleet(simulated_fleet(rng, shifted), factor="factory", q=args.q)
            for p in analysis.parameters:
                apart = [g.group for g in p.groups if g.differs]
                counts[shifted, p.symbol, "F"] += p.anova.groups_differ
                counts[shifted, p.symbol, "alone"] += apart == ([GROUPS[-1]] if shifted else [])
                counts[shifted, p.symbol, "smirnov"] += any(s.differs for s in p.smirnov)
                counts[shifted, p.symbol, "outside"] += bool(p.outliers)
    n = args.fleets
    print(
        f"{n} fleets without and {n} with a shifted group: {len(GROUPS)} groups x {UNITS} units, "
        f"type SD C {C_SD / C_MEAN:.0%}, T {T_SD} s, SE about C {C_SE / C_MEAN:.0%}, T {T_SE} s, "
        f"shift {SHIFT} type SD, q = {args.q}"
    )
    for p in ("C", "T"):
        rate = {key: counts[key] / n for key in counts if key[1] == p}
        print(
            f"{p}: F test false alarm {rate[False, p, 'F']:.1%}, power {rate[True, p, 'F']:.1%}; "
            f"shifted group alone set apart {rate[True, p, 'alone']:.1%} "
            f"(none set apart without a shift {rate[False, p, 'alone']:.1%}); "
            f"Smirnov false alarm {rate[False, p, 'smirnov']:.1%}, power "
            f"{rate[True, p, 'smirnov']:.1%}; a unit outside the prediction interval without "
            f"a shift {rate[False, p, 'outside']:.1%}"
        )


if __name__ == "__main__":
    main()
