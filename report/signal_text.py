"""Section 10 (`SignalSection`) as plain text for the terminal (`gyrostand analyze --signal`).
Formats the section's numbers only; the JSON form is `SignalSection.to_dict`."""

from gyrostand.report.signal import TIME_SAVED_NOTE, SignalSection


def _num(value: float | None, spec: str = ".4g") -> str:
    return "-" if value is None else format(value, spec)


def render_signal_text(section: SignalSection) -> str:
    """The section as text blocks: record, correlation, harmonics, Allan deviation, sampling
    and independence, settle points, acceptance by excursions."""
    out = ["SIGNAL ANALYSIS OF THE READING (Sveshnikov, §8.3)"]
    r, n = section.record, section.noise
    if r is not None:
        out.append(f"record: {r.source}")
        out.append(
            f"  {r.reading_deg.size} readings every {r.dt_s:g} s ({r.duration_s:.1f} s) from "
            f"{r.frames} valid heading frames, {r.filled} interpolated"
            + (
                f"; linear trend {section.trend_deg_per_h:+.4f} deg/h removed"
                if section.trend_deg_per_h is not None
                else ""
            )
        )
    out.append(f"  {section.record_note}")
    if n is None:
        out.append(f"noise not characterised: {section.noise_error or section.record_note}")
    else:
        out += ["", "CORRELATION (eqs 8.92, 8.89)"]
        out.append(
            f"  {'model':<12}{'sigma^2, deg^2':>16}{'mu, 1/s':>10}{'beta, rad/s':>13}"
            f"{'tau_k, s':>10}{'white, deg^2':>14}"
        )
        for name, m in (("exponential", n.exponential), ("smooth", n.smooth)):
            out.append(
                f"  {name:<12}{m.variance:>16.4e}{m.decay_per_s:>10.4g}"
                f"{_num(m.frequency_rad_s, '.3g'):>13}{m.correlation_time_s:>10.4g}"
                f"{m.white_variance:>14.4e}"
            )
        h = n.harmonics
        out += [
            "",
            f"HIDDEN HARMONICS (eqs 8.90-8.91): false-alarm level {h.false_alarm:g}, "
            f"Welch dof {h.dof:.1f}",
        ]
        for c in h.harmonics:
            out.append(
                f"  {c.frequency_hz:.5f} Hz: amplitude {c.amplitude:.4f} deg (spectral peak), "
                f"{c.amplitude_from_correlation:.4f} deg (correlation), peak/background "
                f"{c.peak_to_background:.3g}, false-alarm probability "
                f"{c.false_alarm_probability:.2g}"
            )
        if not h.harmonics:
            out.append("  none detected")
        out += ["", "ALLAN DEVIATION", f"  {'tau, s':>10}{'sigma, deg':>14}"]
        out += [
            f"  {tau:>10.4g}{dev:>14.4e}"
            for tau, dev in zip(n.allan.tau_s, n.allan.deviation, strict=True)
        ]
        s = n.sampling
        ok = "within" if section.reading_interval_ok else "COARSER than"
        out += [
            "",
            "SAMPLING INTERVAL AND INDEPENDENCE (eqs 8.92-8.94)",
            f"  recommended reading interval {s.interval_s:.3g} s (sampled estimate's variance "
            f"within {s.factor:g}x the continuous one); the record's {r.dt_s:g} s is {ok} it",
        ]
        for o in section.observations:
            verdict = "CORRELATED" if o.correlated else "independent"
            out.append(
                f"  trial {o.trial} j = {o.j}: windows {o.window_s:.4g} s every {o.step_s:.4g} s, "
                f"successive observations correlate {o.correlation:+.3f}: {verdict}"
            )
        if section.correlated_observations:
            count = sum(o.correlated for o in section.observations)
            out.append(
                f"  WARNING: observations within a series are correlated ({count} of "
                f"{len(section.observations)} series, |rho| > {s.max_correlation:g}): Cochran's "
                "and Fisher's tests assume independent observations"
            )
    out += ["", "SETTLE POINTS"]
    if section.settle:
        out.append(
            f"  {'trial':>5}{'j':>3}{'from, s':>10}{'at, s':>10}{'took, s':>9}  {'by':<9}"
            f"{'estimate, deg':>14}{'SE, deg':>9}{'mean-est.':>10}{'band, s':>9}{'saved, s':>13}"
        )
        for row in section.settle:
            saved = _num(row.saved_s, ".1f")
            if row.saved_s is None:
                saved = "unknown" if row.criterion else "not recorded"
            out.append(
                f"  {row.trial:>5}{row.j:>3}"
                f"{_num(None if row.started_ms is None else row.started_ms / 1000, '.1f'):>10}"
                f"{_num(None if row.done_ms is None else row.done_ms / 1000, '.1f'):>10}"
                f"{_num(row.settle_s, '.1f'):>9}  {row.criterion or '-':<9}"
                f"{_num(row.estimate_deg, '.4f'):>14}{_num(row.standard_error_deg, '.4f'):>9}"
                f"{_num(row.offset_deg, '+.4f'):>10}{_num(row.band_s, '.1f'):>9}{saved:>13}"
            )
        if section.time_saved_s is not None:
            saved = section.time_saved_s
            out.append(
                f"  stand time saved: {saved:.1f} s"
                if saved >= 0
                else f"  stand time lost: {-saved:.1f} s (later than the band criterion)"
            )
        out.append(f"  {TIME_SAVED_NOTE}")
    else:
        out.append("  not recorded")
    out += ["", "ACCEPTANCE BY EXCURSIONS (eqs 8.79-8.88)"]
    a = section.acceptance
    if a is None:
        out.append(f"  {section.acceptance_note}")
    else:
        e, c = a.excursions, a.criterion
        eps = a.tolerance_for_max_risk_deg
        out.append(
            f"  band mean +-{c.tolerance_deg:g} deg, control time {c.duration_s:g} s, "
            f"allowed risk {c.max_risk:g}"
        )
        if e.rice is not None:
            out += [
                f"  sigma {e.sigma:.4g} deg, sigma_v {e.rice.sigma_dot:.4g} deg/s; expected "
                f"excursions (Rice) {e.rice.mean_excursions:.4g}; bandwidth q "
                f"{e.rice.bandwidth:.3g}",
                f"  Poisson e^(-n) {e.rice.p_poisson:.6f}; Vanmarcke {e.rice.p_vanmarcke:.6f}",
            ]
        out += [
            f"  P(start inside) {e.p_start_inside:.6f}; P(none) "
            f"{'>= ' if e.is_bound else ''}{e.p_no_excursion:.6f} by {e.method}; risk "
            f"{'<= ' if e.is_bound else ''}{a.risk:.4g}",
            "  tolerance for the allowed risk: "
            + ("none (control time too short)" if eps is None else f"+-{eps:.4f} deg"),
            f"  verdict: {a.verdict}. {a.detail}",
            f"  {section.acceptance_note}",
        ]
    return "\n".join(out) + "\n"
