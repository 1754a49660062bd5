"""The standard's procedures of a campaign plan ([[procedure]]): resolved against the plan's
compliance profile ([standard] profile), run before the trials on the simulated compass (in
virtual time) or on the plan's real bus (in real time, the compass switched by the operator),
and stored with the campaign; a resumed campaign keeps the stored results. The frames they hear
go into their raw log beside the campaign's first (`procedures_log_path`), from which a replay
re-derives them (the simulated compass's)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from gyrostand.errors import fail

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping
    from pathlib import Path
    from threading import Event
    from typing import IO

    from gyrostand.acquisition.operator import OperatorLink
    from gyrostand.acquisition.procedures import Progress, ReplayedProcedures
    from gyrostand.acquisition.store import CampaignStore
    from gyrostand.analysis.procedures import ProcedureResults
    from gyrostand.plan.model import Plan
    from gyrostand.plan.procedures import ResolvedProcedure


def resolved(plan: Plan) -> tuple[ResolvedProcedure, ...]:
    """The plan's procedures filled from its profile (one-line error: no such profile)."""
    from gyrostand.report.compliance import load_profile
    from gyrostand.report.errors import ReportError
    from gyrostand.report.procedures import resolve

    try:
        return resolve(plan, load_profile(plan.standard.profile))
    except ReportError as exc:
        fail(f"[standard] profile: {exc}")


def describe(procedure: ResolvedProcedure) -> str:
    """One procedure in one line: its parameters and departures."""
    p = procedure.plan
    if p.kind == "settling":
        text = (
            f"settling: from switch-on, band {p.band_deg:g} deg, recorded {p.max_wait_s:g} s, "
            f"fitted from {p.fit_from_s:g} s"
        )
    elif p.kind == "rolling":
        text = (
            f"rolling: {len(p.points or ())} envelope points, {p.readings} readings "
            f"{p.interval_s:g} s apart after {p.wait_s:g} s, beyond the stand: {p.beyond_stand}"
        )
    else:
        runs = (
            f"{p.runups} run-ups, off {p.off_s:g} s between, " if p.kind == "repeatability" else ""
        )
        text = f"{p.kind}: {runs}{p.readings} readings {p.interval_s:g} s apart after settling"
    if p.power == "manual":
        how = "on" if p.kind == "settling" else "off and on"
        text += f", switched {how} by hand (the operator is prompted)"
    departs = "; ".join(procedure.departures)
    return text + (f" (departs from the standard: {departs})" if departs else "")


def run_procedures_of(
    plan: Plan,
    store: CampaignStore,
    quiet: bool,
    stop: Event,
    answers: Mapping[str, str] | None = None,
    terminal: IO[str] | None = None,
) -> bool:
    """Run and store the plan's procedures unless the campaign has them already; the stages an
    interrupted run did are kept, the one interrupted is redone. A compass powered by hand is
    switched when the operator answers the prompts (`answers`, the station or `terminal`).
    False: stopped part-way (by `stop` at the end of a stage, or a stop request while a prompt
    waits; the stages done are kept for `campaign resume`)."""
    if not plan.procedure:
        return True
    from rich.console import Console

    from gyrostand.acquisition.operator import OperatorLink
    from gyrostand.acquisition.procedures import (
        ProcedureLog,
        Progress,
        RunUp,
        procedures_log_path,
        run_procedures,
        save_progress,
        store_procedures,
        stored_progress,
    )
    from gyrostand.acquisition.runner import raw_log_path
    from gyrostand.db.queries import raw_log_segments
    from gyrostand.frames.logfile import BatchBLFWriter, sha256_of
    from gyrostand.plan.switching import power_prompts

    complete, done = stored_progress(store.sessions, store.campaign_id)
    if complete:
        return True
    inputs = procedure_inputs(plan)
    config, procedures = inputs[0], inputs[1]
    if done:
        kept = ", ".join(
            [k for k in done if not k.endswith("_s")]
            + [f"the switch-on of run-up {k}" for k in done.get("switch_on_s", {})]
        )
        store.run_event("procedures", "info", f"the standard's procedures resumed: kept {kept}")

    def saved(stages: dict[str, object]) -> None:
        save_progress(store.sessions, store.campaign_id, stages, path)
        if stop.is_set():
            raise Stopped

    prompts = power_prompts(plan)
    console = None if quiet else Console(stderr=True)
    link = OperatorLink(store, plan, stop, answers or {}, terminal, console)

    def prompted(k: int) -> None:
        for prompt in prompts.get(k, ()):
            if link.ask(prompt, "the standard's procedures") is not None:
                raise Stopped

    with store.sessions() as session:
        segments = raw_log_segments(session, store.campaign_id)
    # beside the trials' first raw log, named as the trials' run will name it (none yet);
    # a resumed run writes it anew, the kept stages heard again (the same frames)
    path = procedures_log_path(segments[0].path if segments else raw_log_path(store, plan, []))
    save_progress(store.sessions, store.campaign_id, done, path)  # (named before it holds any)
    progress = Progress(done, saved)
    if plan.bus.simulated:
        log = BatchBLFWriter(path)
        try:
            results = run_procedures(
                *inputs, progress, prompted, runups=lambda k, at_s: RunUp(config, k, at_s, log)
            )
        except Stopped:
            return False
        finally:
            log.stop()
        frames = log.object_count
    else:
        on_bus = _on_the_bus(plan, store, inputs, progress, prompted, link, path)
        if on_bus is None:
            return False
        results, path, frames = on_bus
    raw_log = ProcedureLog(str(path), frames, sha256_of(path))
    store_procedures(store.sessions, store.campaign_id, results, raw_log)
    kinds = ", ".join(p.kind for p in procedures)
    store.run_event("procedures", "info", f"the standard's procedures run and stored: {kinds}")
    store.run_event(
        "raw log",
        "info",
        f"the standard's procedures' frames in {path} ({raw_log.frames} frames, "
        f"sha256 {raw_log.sha256})",
    )
    if not quiet:
        print(f"campaign {store.campaign_id}: the standard's procedures done ({kinds})")
    return True


def _on_the_bus(
    plan: Plan,
    store: CampaignStore,
    inputs: tuple,
    progress: Progress,
    prompted: Callable[[int], None],
    link: OperatorLink,
    first_log: Path,
) -> tuple[ProcedureResults, Path, int] | None:
    """The procedures on the plan's real bus, in real time (`procedures_live`): the results,
    the raw log written and its frames; None when stopped (the stages done are kept). Each
    run-up starts at the stand time of the first frame heard after the operator's answer to its
    switch-on; a resumed run goes on with the run-ups under way, fed the frames of the stopped
    runs' logs first, and writes a log of its own beside them (-resumeN)."""
    from gyrostand.acquisition.bus import LiveBus
    from gyrostand.acquisition.procedures import (
        procedures_run_log,
        procedures_run_logs,
        run_procedures,
    )
    from gyrostand.acquisition.procedures_live import BusHeadings, LiveRunUp
    from gyrostand.acquisition.runner import _stop_on_signals
    from gyrostand.plan.codec import codec_for

    earlier = procedures_run_logs(first_log)
    path = procedures_run_log(first_log, len(earlier))

    def check() -> None:
        if link.stop_requested() is not None:
            raise Stopped

    def runup(k: int, _at_s: float) -> LiveRunUp:
        switched = dict(progress.done.get("switch_on_s", {}))
        if str(k) not in switched:
            switched[str(k)] = heard.next_heard_s()
            progress.save("switch_on_s", switched)
            store.run_event(
                "procedures",
                "info",
                f"run-up {k} switched on at stand time {switched[str(k)]:g} s (the first frame "
                "heard after the operator's answer)",
            )
        return LiveRunUp(heard, k, switched[str(k)])

    live = LiveBus(plan, codec_for(plan), path)
    heard = BusHeadings(plan, live, check)
    link.waiting = heard.poll  # (the frames keep coming while the operator is asked)
    try:
        with _stop_on_signals(link.stop):
            heard.earlier(earlier)
            results = run_procedures(*inputs, progress, prompted, runups=runup)
    except Stopped:
        return None
    finally:
        try:
            heard.stop_rocking()
        finally:
            live.close()
    if earlier:
        logs = ", ".join(str(p) for p in earlier)
        store.run_event("raw log", "info", f"the standard's procedures' earlier frames in {logs}")
    return results, path, live.recorder.logged


def replay_procedures_log(plan: Plan, first_log: Path) -> ReplayedProcedures | None:
    """The plan's procedures (None: it has none) re-derived from their raw log beside the
    campaign's first raw log (`procedures_log_path`); ReplayLogError when it is missing, cut
    short, or not what the plan's procedures heard."""
    if not plan.procedure:
        return None
    if not plan.bus.simulated:
        from gyrostand.acquisition.runner import ReplayLogError

        raise ReplayLogError(
            f"{first_log}: the standard's procedures of a campaign on a real bus are not "
            "re-derived from their log yet (their run-ups start at the operator's answers)"
        )
    from gyrostand.acquisition.procedures import (
        ProcedureLog,
        ProcedureLogError,
        ReplayedProcedures,
        procedures_log_path,
        replay_procedures,
    )
    from gyrostand.acquisition.runner import ReplayLogError, check_replay_log

    path = procedures_log_path(first_log)
    if not path.is_file():
        raise ReplayLogError(
            f"{path}: no such file: the plan has the standard's procedures, whose frames are in "
            f"this log beside {first_log.name}"
        )
    log = check_replay_log(path)
    if log.truncated is not None:
        raise ReplayLogError(f"{path}: {log.truncated}: the procedures cannot be re-derived")
    try:
        results = replay_procedures(*procedure_inputs(plan), path)
    except ProcedureLogError as exc:
        raise ReplayLogError(str(exc)) from exc
    return ReplayedProcedures(results, ProcedureLog(str(path.resolve()), log.frames, log.sha256))


def procedure_inputs(plan: Plan) -> tuple:
    """What `run_procedures` and `replay_procedures` take from the plan, in their order: the
    simulated compass, the resolved procedures, the reference, the transient model, the stand's
    limits and the site's latitude."""
    from gyrostand.stand.simconfig import simulator_config

    bus = plan.bus
    config = simulator_config(bus.simulator, speedup=bus.speedup, seed=bus.seed, timing=bus.timing)
    model = plan.settle.transient_model
    assert model is not None  # the plan's check
    limits, latitude = plan.stand_limits, plan.site.latitude_deg
    return config, resolved(plan), plan.reference, model, limits, latitude


class Stopped(Exception):
    """A stop asked for while the procedures ran (raised once a stage is saved)."""
