"""Monte-Carlo validation of the analysis (Potemkin 1982) on synthetic trials (issue 3, section 7).

Simulates campaigns with known C, T and Gaussian reading noise (analysis.synthetic), runs each
through `analyze_campaign`, and prints per parameter: bias, the SD of the estimates against the
mean (and RMS) reported standard error and the Cramer-Rao bound sigma_delta^2 (J^T J)^-1 at the
true values, the coverage of the 95 % t confidence intervals and of the 95 % prediction intervals
(eqs 2.10-2.11) for fresh control trials, and the rejection rates of Cochran's test and of the
adequacy F test on both error bases (all of which should be near q = 5 %, except the paper's
single-observation basis, which is conservative by design).

Targets for the main design: SD within 5 % of the bound, coverage 93.5-96.5 %. A second,
paper-like design (4 trials, 2 residual dof) is printed for information: there the linearisation
behind the intervals is strained and the figures show by how much.

Run: .venv/bin/python validation/monte_carlo.py [--replicates 2000] [--seed 1]
"""

import argparse
import time
from dataclasses import dataclass

import numpy as np
from scipy import stats

from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.gyro_model import RollingErrorModel
from gyrostand.analysis.paper_example import CONSTANTS
from gyrostand.analysis.synthetic import Design, synthetic_trials

TRUE = {"C_gcm2s2": 6e7, "T_s": 1.15}
START = (7e7, 0.55)


@dataclass(frozen=True)
class Scenario:
    name: str
    design: Design
    roles: list[str]
    sigma_deg: float
    n_obs: int


def main_scenario() -> Scenario:
    """12 fitted trials over 4 directions and 6 periods, 3 control trials; N = 5 readings."""
    fit_k = np.tile([30.0, 60.0, 120.0, 150.0], 3)
    fit_a = np.tile([18.0, 24.0, 21.0], 4)
    fit_tau = np.repeat([3.5, 4.5, 5.5, 6.5, 7.5, 8.0], 2)
    return Scenario(
        "12 fit + 3 control trials, sigma = 0.01 deg, N = 5",
        Design(
            np.concatenate([fit_k, [45.0, 135.0, 20.0]]),
            np.concatenate([fit_a, [20.0, 23.0, 17.0]]),
            np.concatenate([fit_tau, [5.0, 6.0, 4.0]]),
        ),
        ["fit"] * 12 + ["control"] * 3,
        0.01,
        5,
    )


def paper_scenario() -> Scenario:
    """The paper's design (trials 1-4 fitted, 5-6 control), its S_e, N = 5."""
    return Scenario(
        "paper-like: 4 fit + 2 control trials, sigma = 0.0108 deg, N = 5",
        Design(
            np.array([332.0, 18.0, 316.0, 346.0, 31.0, 346.0]),
            np.array([24.0, 24.0, 23.0, 17.8, 23.5, 17.8]),
            np.array([8.0, 6.3, 5.5, 3.5, 6.2, 5.5]),
        ),
        ["fit"] * 4 + ["control"] * 2,
        np.sqrt(2.35e-4 / 2),
        5,
    )


def cramer_rao_sd(scenario: Scenario) -> np.ndarray:
    """sqrt(diag(sigma_delta^2 (J^T J)^-1)) at the true values, sigma_delta^2 = 2 sigma^2 / N."""
    fit = np.array([r == "fit" for r in scenario.roles])
    d = scenario.design
    x = Design(d.direction_deg[fit], d.amplitude_cm[fit], d.period_s[fit]).conditions
    jac = RollingErrorModel(CONSTANTS).jacobian(x, **TRUE)
    var_delta = 2 * scenario.sigma_deg**2 / scenario.n_obs
    return np.sqrt(np.diag(var_delta * np.linalg.inv(jac.T @ jac)))


def run(scenario: Scenario, replicates: int, rng: np.random.Generator) -> dict[str, object]:
    names = list(TRUE)
    estimates, std_errors, covered = [], [], []
    pi_hits, cochran_rejects, adequacy_rejects, mean_basis_rejects, failures = [], 0, 0, 0, 0
    for _ in range(replicates):
        trials = synthetic_trials(
            CONSTANTS,
            scenario.design,
            scenario.roles,
            **TRUE,
            sigma_deg=scenario.sigma_deg,
            n_obs=scenario.n_obs,
            rng=rng,
        )
        try:
            a = analyze_campaign(trials, CONSTANTS, start=START)
        except AnalysisError:
            failures += 1
            continue
        theta = np.array([a.fit.estimates[n] for n in names])
        se = np.array([a.fit.std_errors[n] for n in names])
        t_q = float(stats.t.ppf(1 - a.q / 2, a.fit.dof))
        estimates.append(theta)
        std_errors.append(se)
        covered.append(np.abs(theta - np.array(list(TRUE.values()))) <= t_q * se)
        pi_hits += [c.within_interval for c in a.controls]
        cochran_rejects += not a.cochran.homogeneous
        adequacy_rejects += a.adequacy.adequate is False
        mean_basis_rejects += a.adequacy.adequate_mean_basis is False
    done = len(estimates)
    est, ses = np.array(estimates), np.array(std_errors)
    return {
        "done": done,
        "failures": failures,
        "bias": est.mean(axis=0) - np.array(list(TRUE.values())),
        "sd": est.std(axis=0, ddof=1),
        "mean_se": ses.mean(axis=0),
        "rms_se": np.sqrt((ses**2).mean(axis=0)),
        "crb": cramer_rao_sd(scenario),
        "ci_coverage": np.mean(covered, axis=0),
        "pi_coverage": float(np.mean(pi_hits)),
        "cochran_reject": cochran_rejects / done,
        "adequacy_reject": adequacy_rejects / done,
        "mean_basis_reject": mean_basis_rejects / done,
    }


def report(scenario: Scenario, r: dict[str, object], check_targets: bool) -> bool:
    print(f"\n{scenario.name}: {r['done']} replicates fitted, {r['failures']} failed")
    print(
        f"{'parameter':<10} {'true':>10} {'bias':>11} {'SD':>11} {'mean SE':>11} {'RMS SE':>11} "
        f"{'CR bound':>11} {'SD/CRB':>7} {'CI cov':>7}"
    )
    ok = True
    for i, (name, true) in enumerate(TRUE.items()):
        ratio = r["sd"][i] / r["crb"][i]
        cov = r["ci_coverage"][i]
        print(
            f"{name:<10} {true:>10.4g} {r['bias'][i]:>+11.3g} {r['sd'][i]:>11.4g} "
            f"{r['mean_se'][i]:>11.4g} {r['rms_se'][i]:>11.4g} {r['crb'][i]:>11.4g} "
            f"{ratio:>7.3f} {cov:>7.1%}"
        )
        ok &= abs(ratio - 1) <= 0.05 and 0.935 <= cov <= 0.965
    pi = r["pi_coverage"]
    ok &= 0.935 <= pi <= 0.965
    print(f"95 % prediction-interval coverage of control trials (2.10-2.11): {pi:.1%}")
    print(
        f"rejection rates at q = 5 %: Cochran {r['cochran_reject']:.1%}, adequacy F on the "
        f"paper's basis {r['adequacy_reject']:.1%}, on the trial-mean basis "
        f"{r['mean_basis_reject']:.1%}"
    )
    if check_targets:
        print(
            "targets (SD within 5 % of the bound, coverage 93.5-96.5 %): "
            + ("PASS" if ok else "FAIL")
        )
    return ok


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--replicates", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"true C = {TRUE['C_gcm2s2']:g} g cm^2 s^-2, T = {TRUE['T_s']} s; start {START}")
    start = time.perf_counter()
    main_ok = report(main_scenario(), run(main_scenario(), args.replicates, rng), True)
    report(paper_scenario(), run(paper_scenario(), args.replicates, rng), False)
    print(f"\nelapsed {time.perf_counter() - start:.1f} s")
    raise SystemExit(0 if main_ok else 1)


if __name__ == "__main__":
    main()
