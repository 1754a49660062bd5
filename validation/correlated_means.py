"""SD of trial means over their reported standard error, with correlated observations.

Campaigns of the paper's design (six fit trials, C = 6e7 g cm^2 s^-2, T = 1.15 s) whose every
series holds N observations with AR(1) correlation rho between successive ones (rho^k at lag k,
the correlation of window means of an exponentially correlated reading); each is analysed twice:
with the paper's S^2{<delta>} = S^2/N (eq 2.3) and with N_eff = N/f from the known correlation
(`analysis.effective`). Printed per case: the SD of each trial's <delta_i> over the campaigns
divided by the mean of its reported SE sqrt(var_mean), averaged over the trials (target
1.00 +- 0.05 with N_eff), and the coverage of the 95 % interval <delta_i> +- t(0.975; nu_i) SE_i,
nu_i the trial's dof (target 93-97 %).

These are synthetic readings, not the simulated stand: the stand's own check needs its
campaigns (minutes each) and is not run here.

Run: .venv/bin/python validation/correlated_means.py [--campaigns 300] [--seed 34]

Measured (100 campaigns per case, seed 34; rho, N: SD/SE paper -> N_eff, coverage paper ->
N_eff): 0, 12: 0.993 -> 0.993, 94.8 -> 94.8 %; 0.3, 12: 1.372 -> 0.999, 84.2 -> 96.0 %;
0.54, 12: 1.901 -> 1.010, 70.8 -> 97.3 %; 0.54, 5: 2.047 -> 1.076, 71.2 -> 99.7 %; 0.7, 20:
2.498 -> 1.007, 56.5 -> 98.2 %. SD/SE meets its target but at N_eff ~ 2; the intervals
over-cover (dof N_eff1 + N_eff2 - 2 rounded down is conservative for the variance of S^2).
"""

import argparse

import numpy as np
from scipy.stats import t as student_t

from gyrostand.analysis import paper_example as paper
from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.effective import variance_inflation
from gyrostand.analysis.gyro_model import RollingErrorModel
from gyrostand.analysis.synthetic import Design, synthetic_trials

TRUE = {"C_gcm2s2": 6e7, "T_s": 1.15}
DESIGN = Design(
    direction_deg=np.array([30.0, 60, 120, 150, 45, 135]),
    amplitude_cm=np.array([20.0, 24, 22, 18, 21, 23]),
    period_s=np.array([3.5, 4.5, 5.5, 6.5, 6.0, 7.0]),
)
CASES = ((0.0, 12), (0.3, 12), (0.54, 12), (0.54, 5), (0.7, 20))  # (rho, N)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--campaigns", type=int, default=300)
    parser.add_argument("--seed", type=int, default=34)
    args = parser.parse_args()
    alpha = RollingErrorModel(paper.CONSTANTS)(DESIGN.conditions, **TRUE)
    print(f"{args.campaigns} campaigns of 6 trials per case (seed {args.seed})")
    print("rho    N  N_eff   SD/SE paper  SD/SE N_eff   coverage paper  coverage N_eff")
    for rho, n in CASES:
        f = variance_inflation(rho ** np.arange(1, n), n)
        inflation = {i: (f, f) for i in range(1, alpha.size + 1)}
        rng = np.random.default_rng(args.seed)
        deltas = []
        se = {"paper": [], "n_eff": []}
        covered = {"paper": [], "n_eff": []}
        for _ in range(args.campaigns):
            trials = synthetic_trials(
                paper.CONSTANTS,
                DESIGN,
                ["fit"] * 6,
                **TRUE,
                sigma_deg=0.05,
                n_obs=n,
                rng=rng,
                rho=rho,
            )
            for name, given in (("paper", None), ("n_eff", inflation)):
                a = analyze_campaign(trials, paper.CONSTANTS, start=paper.START, inflation=given)
                errors = np.sqrt([s.var_mean_deg2 for s in a.trials])
                se[name].append(errors)
                half = student_t.ppf(0.975, [s.dof for s in a.trials]) * errors
                covered[name] += list(np.abs([s.delta_deg for s in a.trials] - alpha) <= half)
            deltas.append([s.delta_deg for s in a.trials])
        spread = np.std(deltas, axis=0, ddof=1)
        ratio = {k: float(np.mean(spread / np.mean(v, axis=0))) for k, v in se.items()}
        print(
            f"{rho:<4} {n:>3} {n / f:6.2f} {ratio['paper']:12.3f} {ratio['n_eff']:12.3f}"
            f" {np.mean(covered['paper']):15.1%} {np.mean(covered['n_eff']):15.1%}"
        )
    print("targets with N_eff: SD/SE 1.00 +- 0.05, coverage 93-97 %")


if __name__ == "__main__":
    main()
