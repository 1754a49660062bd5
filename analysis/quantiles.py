"""Quantiles and tail areas of Student's t, Fisher's F and chi-square for code that needs no
other distribution (the report rebuilt from a stored analysis, the fleet analysis): the
scipy.special functions scipy.stats' t, f and chi2 evaluate (the same calls, so the same
numbers), without importing scipy.stats (about 0.85-1 s of CPU in a fresh process against 0.2 s
for scipy.special)."""

import math

from gyrostand.analysis.t_table import T_DOF_MAX, T_QUANTILES


def t_quantile(p: float, dof: float) -> float:
    """t(p; dof), the p quantile of Student's t with `dof` degrees of freedom: from `t_table`
    for the usual levels and whole degrees of freedom (the same numbers), else scipy.special."""
    row = T_QUANTILES.get(p)
    if row is not None and float(dof).is_integer() and 1 <= dof <= T_DOF_MAX:
        return row[int(dof) - 1]
    from scipy.special import stdtrit

    return float(stdtrit(dof, p))


def f_quantile(p: float, dof_num: float, dof_den: float) -> float:
    """F(p; dof_num, dof_den), the p quantile of Fisher's F (scipy.stats.f.ppf); dof_den
    infinite (a denominator variance known): χ²(p; dof_num) / dof_num."""
    from scipy.special import fdtri

    if math.isinf(dof_den):
        return chi2_quantile(p, dof_num) / dof_num
    return float(fdtri(dof_num, dof_den, p))


def f_sf(x: float, dof_num: float, dof_den: float) -> float:
    """P(F > x) of Fisher's F with (dof_num, dof_den) degrees of freedom (scipy.stats.f.sf);
    dof_den infinite: P(χ²(dof_num) > dof_num x)."""
    from scipy.special import fdtrc, gammaincc

    if math.isinf(dof_den):
        return float(gammaincc(dof_num / 2.0, dof_num * x / 2.0))  # Q(ν/2, νx/2)
    return float(fdtrc(dof_num, dof_den, x))


def f_cdf(x: float, dof_num: float, dof_den: float) -> float:
    """P(F <= x) (scipy.stats.f.cdf), dof_den as `f_sf`."""
    from scipy.special import fdtr, gammainc

    if math.isinf(dof_den):
        return float(gammainc(dof_num / 2.0, dof_num * x / 2.0))  # P(ν/2, νx/2)
    return float(fdtr(dof_num, dof_den, x))


def chi2_quantile(p: float, dof: float) -> float:
    """χ²(p; dof), the p quantile of chi-square, `dof` degrees of freedom (scipy.stats.chi2.ppf)."""
    from scipy.special import gammaincinv

    return 2.0 * float(gammaincinv(dof / 2.0, p))  # χ²_p = 2 P⁻¹(ν/2, p), P the regularised Γ


def dof_text(dof: float) -> str:
    """Degrees of freedom as printed: "∞" when infinite, one decimal below 100 unless whole."""
    if math.isinf(dof):
        return "∞"
    return f"{dof:.0f}" if float(dof).is_integer() or dof >= 100 else f"{dof:.1f}"
