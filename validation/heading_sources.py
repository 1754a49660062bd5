"""The paper campaign with each runnable heading source: C and T as with gyrostand's frame.

Runs examples/paper.toml (the campaign of Potemkin 1982 on the simulated stand, virtual time) as
`gyrostand campaign run` does, once per heading source ([compass] protocol) with the same
simulator seed, i.e. the same compass physics and noise; analyses each as `gyrostand analyze`
does, and prints C and T with their standard errors and the difference to the gyrostand-protocol
run in units of that run's SE. Target: |difference| < 1 SE (the sources differ only in the
heading's resolution, 0.001 deg vs 1e-4 rad = 0.0057 deg for NMEA 2000, 360/65536 = 0.0055 deg
for the CiA 406 encoder (its EDS, devices/data/sim-encoder.eds, read counter-clockwise from a
zero) and 0.01 deg for IEC 61162 THS sentences at 4800 baud through a pseudo-terminal pair, and
in their timing by reception).

Run: .venv/bin/python validation/heading_sources.py [--seeds 1,2,3]
A paper campaign takes ~20 s of one core per source (stand time ~15 h, virtual time).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "examples" / "paper.toml"
EDS = ROOT / "devices" / "data" / "sim-encoder.eds"
SOURCES = {  # protocol -> the rest of its [compass] table
    "gyrostand": "",
    "nmea2000": "",
    "iec61162": "",
    "cia406": f'node_id = 5\neds = "{EDS}"\nzero_counts = 1200\ndirection = "counterclockwise"\n',
}


def campaign(folder: Path, protocol: str, seed: int) -> dict[str, dict[str, float]]:
    """Run and analyse the paper campaign with one heading source; the fit's estimates and
    standard errors."""
    text = re.sub(r"(?m)^seed = \d+", f"seed = {seed}", PLAN.read_text(), count=1)
    plan = folder / f"{protocol}.toml"
    plan.write_text(text + f'\n[compass]\nprotocol = "{protocol}"\n{SOURCES[protocol]}')
    db = folder / f"{protocol}.sqlite"
    gyrostand = [sys.executable, "-m", "gyrostand"]
    run = [*gyrostand, "campaign", "run", str(plan), "--db", str(db), "--quiet"]
    done = subprocess.run(run, cwd=folder, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{protocol}, seed {seed}: {done.stderr.strip()}")
    analyze = [*gyrostand, "analyze", "1", "--db", str(db), "--json"]
    out = subprocess.run(analyze, check=True, cwd=folder, capture_output=True, text=True).stdout
    fit = json.loads(out)["fit"]
    return {"estimates": fit["estimates"], "std_errors": fit["std_errors"]}


def print_against_gyrostand(seed: int, fits: dict[str, dict]) -> float:
    """One row per heading source: C and T with their SE, and the difference from the
    gyrostand-protocol run in its SE; the largest |difference|."""
    ref, worst = fits["gyrostand"], 0.0
    for protocol, fit in fits.items():
        c, t = fit["estimates"]["C_gcm2s2"], fit["estimates"]["T_s"]
        se_c, se_t = fit["std_errors"]["C_gcm2s2"], fit["std_errors"]["T_s"]
        dc = (c - ref["estimates"]["C_gcm2s2"]) / ref["std_errors"]["C_gcm2s2"]
        dt = (t - ref["estimates"]["T_s"]) / ref["std_errors"]["T_s"]
        worst = max(worst, abs(dc), abs(dt))
        print(
            f"{seed:>4} {protocol:<10} {c / 1e7:8.4f} {se_c / 1e7:7.4f} {t:7.4f} {se_t:7.4f}"
            f"  {dc:+.3f} {dt:+.3f}"
        )
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1,2,3", help="simulator seeds, comma-separated")
    args = parser.parse_args()
    print(f"{'seed':>4} {'source':<10} {'C e7':>8} {'SE':>7} {'T s':>7} {'SE':>7}  dC/SE  dT/SE")
    worst = 0.0
    for seed in (int(s) for s in args.seeds.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            fits = {p: campaign(Path(tmp), p, seed) for p in SOURCES}
            wall = time.perf_counter() - t0
        worst = max(worst, print_against_gyrostand(seed, fits))
        print(f"     ({wall:.0f} s wall for the {len(SOURCES)} campaigns)")
    verdict = "within" if worst < 1.0 else "OUTSIDE"
    print(f"largest |difference| {worst:.3f} SE: {verdict} the target of 1 SE")


if __name__ == "__main__":
    main()
