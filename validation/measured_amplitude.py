"""The measured amplitude against the commanded one, on the paper campaign as shipped
(examples/paper.toml: N = 5, 8-period windows, the transient-model settle, the simulator's
default reading noise), on a stand that rocks at 1.03 x the commanded amplitude while
reporting the command, with a CiA 410 inclinometer on the platform (issue 32's done-when at the
paper's scale; tests/acquisition/test_measured_amplitude_campaign.py is the short, low-noise
version run by the slow test stage).

Prints, per seed, C and T with their SE and (estimate - truth) / SE, analysed with the measured
motion (as `gyrostand analyze` does) and with the commanded one. Run:
    python validation/measured_amplitude.py [SEEDS ...]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from typer.testing import CliRunner

from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.cli import app
from gyrostand.db.queries import load_campaign
from gyrostand.db.session import open_database
from gyrostand.plan.overrides import with_keys
from gyrostand.report.stored import commanded_motion, stored_inputs
from gyrostand.stand.simconfig import CompassParams

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"C_gcm2s2": CompassParams.c_gcm2s2, "T_s": CompassParams.t_s}


def campaign(seed: int, folder: Path, tables: dict[str, dict] | None = None) -> Path:
    """Run the paper campaign with the 3 % amplitude error and an inclinometer, its tables
    overridden key by key by `tables` (the test's short version); its database."""
    db = folder / "c.sqlite"
    keys: dict[str, dict] = {
        "campaign": {"database": str(db)},
        "bus": {"seed": seed},
        "bus.simulator.faults": {"amplitude_factor": 1.03, "amplitude_unreported": True},
        "stand": {"arm_length_cm": 100.0},
        "inclinometer": {"protocol": "cia410", "node_id": 4},
    }
    for table, values in (tables or {}).items():
        keys[table] = keys.get(table, {}) | values
    plan = folder / "plan.toml"
    plan.write_text(with_keys((ROOT / "examples" / "paper.toml").read_text(), keys))
    result = CliRunner().invoke(app, ["campaign", "run", str(plan)])
    if result.exit_code != 0:
        raise SystemExit(f"seed {seed}: the campaign failed: {result.output.strip()}")
    return db


def fits(db: Path) -> dict[str, dict[str, tuple[float, float]]]:
    """C and T (estimate, SE) with the measured and with the commanded motion."""
    with open_database(f"sqlite:///{db}", upgrade=False, create=False)() as session:
        stored = load_campaign(session, 1)
        inputs = stored_inputs(stored)
        commanded = commanded_motion(stored, inputs.trials)
    s = inputs.settings
    out = {}
    for name, trials in (("measured", inputs.trials), ("commanded", commanded)):
        fit = analyze_campaign(
            trials, s.constants, q=s.q, start=s.start, admissible=s.admissible, forecast=s.forecast
        ).fit
        out[name] = {k: (fit.estimates[k], fit.std_errors[k]) for k in TRUTH}
    return out


def main(seeds: list[int]) -> None:
    print("seed  motion     C_gcm2s2 (SE)            z(C)   T_s (SE)          z(T)")
    for seed in seeds:
        with tempfile.TemporaryDirectory() as folder:
            found = fits(campaign(seed, Path(folder)))
        for name, values in found.items():
            (c, c_se), (t, t_se) = values["C_gcm2s2"], values["T_s"]
            zc, zt = (c - TRUTH["C_gcm2s2"]) / c_se, (t - TRUTH["T_s"]) / t_se
            c_text, t_text = f"{c:.4g} ({c_se:.2g})", f"{t:.4f} ({t_se:.2g})"
            print(f"{seed:>4}  {name:<9}  {c_text:<24} {zc:+6.2f}   {t_text:<17} {zt:+6.2f}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", type=int, nargs="*", default=[1], help="simulator seeds (1)")
    main(parser.parse_args().seeds)
