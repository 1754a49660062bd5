"""The station's web application (Starlette): pages, actions and the update stream.

Routes: `/` campaigns (filter by status and text), `/campaigns/new` start form, POST
`/campaigns` start, `/campaigns/{id}` campaign page, `/campaigns/{id}/stream` its updates as
server-sent events, POST `/campaigns/{id}/stop|resume|answer|report|signoff`, and
`/campaigns/{id}/files/{name}` its report files."""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
from collections.abc import AsyncIterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

from jinja2 import Environment, PackageLoader, select_autoescape
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import FileResponse, RedirectResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.templating import Jinja2Templates

from gyrostand.db.lease import held_elsewhere
from gyrostand.db.models import CAMPAIGN_STATUSES, Campaign
from gyrostand.db.queries import CampaignFilter, campaign_list, live_watch_of, sign_offs
from gyrostand.db.session import writer
from gyrostand.plan.model import Plan, PlanError, load_plan, parse_plan
from gyrostand.plan.summary import describe, design_warning
from gyrostand.station.operator import (
    FIELD,
    ActionRefused,
    answer,
    request_stop,
    start_answers,
    unit_values,
    waiting_for,
    with_unit,
)
from gyrostand.station.processes import Processes, ProcessRefused
from gyrostand.station.security import (
    Access,
    CrossSite,
    HostMiddleware,
    TokenMiddleware,
    action_form,
)
from gyrostand.station.signoff import SignOffRefused, sign_off
from gyrostand.station.state import (
    fingerprint,
    live_file,
    live_state,
    read_live,
    report_decision,
    report_files,
)

TICK_S = 0.1
"""The update stream checks the database's fingerprint of the campaign this often and pushes
the campaign's state when it changed."""
IDLE_TICK_S = 1.0
"""... and this often while nothing acquires (a run started elsewhere is seen within it)."""
REPORT_FORMATS = {"html": "html,json", "html+pdf": "html,pdf,json"}
"""The report formats offered, each with the JSON the page reads the report's decision from."""
STATIC = Path(__file__).parent / "static"
ID_MAX = 2**63 - 1  # the largest id a database stores (SQLite INTEGER, PostgreSQL BIGINT)


@dataclass(frozen=True)
class Station:
    """What the routes share: the database, the processes, the secrets, the report folder."""

    sessions: sessionmaker[Session]
    processes: Processes
    access: Access
    reports: Path
    templates: Jinja2Templates

    def page(self, request: Request, name: str, code: int = 200, **context: Any) -> Response:
        context.update(csrf=self.access.csrf)
        return self.templates.TemplateResponse(request, name, context, status_code=code)

    def read(self, query: Any, *args: Any) -> Any:
        with self.sessions() as session:
            return query(session, *args)

    def write(self, action: Any, *args: Any) -> Any:
        """A short write transaction, queued behind another writer (a running campaign)."""
        with writer(self.sessions).begin() as session:
            return action(session, *args)

    def acquiring(self, campaign_id: int) -> bool:
        """A process acquires into the campaign now: one of ours, or whoever holds its lease."""
        return self.processes.running(campaign_id) or held_elsewhere(self.sessions, campaign_id)


def compact(value: Any) -> str:
    """JSON on one line (an SSE data line)."""
    return json.dumps(value, separators=(",", ":"))


def problems_by_field(problems: list[str]) -> list[tuple[str, str]]:
    """PlanError's "[table] key: message" lines as (field, message)."""
    pairs = []
    for problem in problems:
        where, sep, message = problem.partition(": ")
        pairs.append((where, message) if sep and where.startswith("[") else ("", problem))
    return pairs


def create_app(
    db: str, sessions: sessionmaker[Session], access: Access, reports: Path
) -> Starlette:
    """The station on database `db` (its session factory `sessions`), writing reports under
    `reports`."""
    env = Environment(
        loader=PackageLoader("gyrostand.station", "templates"),
        autoescape=select_autoescape(default=True, default_for_string=True),
    )
    station = Station(sessions, Processes(db), access, reports, Jinja2Templates(env=env))

    def campaign_id(request: Request) -> int:
        cid = int(request.path_params["campaign_id"])
        with sessions() as session:
            if cid > ID_MAX or session.get(Campaign, cid) is None:
                raise HTTPException(404, f"no campaign {cid} in the database")
        return cid

    async def campaigns(request: Request) -> Response:
        status = request.query_params.get("status", "")
        text = request.query_params.get("q", "")
        where = CampaignFilter(status=status or None, text=text or None)
        rows = await run_in_threadpool(
            lambda: [  # newest first
                replace(r, status="interrupted")
                if r.status == "running" and not station.acquiring(r.campaign_id)
                else r
                for r in reversed(station.read(campaign_list, where))
            ]
        )
        return station.page(
            request,
            "campaigns.html.j2",
            rows=rows,
            status=status,
            q=text,
            statuses=CAMPAIGN_STATUSES,
        )

    def start_page(
        request: Request,
        code: int = 200,
        path: str = "",
        plan: Plan | None = None,
        problems: list[str] | None = None,
        form: Any = None,
    ) -> Response:
        """The start form: a plan to check; once checked, its summary, the device under test,
        the operator and the prompts before the campaign, and Start."""
        form = form or {}
        return station.page(
            request,
            "start.html.j2",
            code,
            plan=path,
            checked=plan,
            summary=None if plan is None else describe(plan),
            warning=None if plan is None else design_warning(plan),
            unit={} if plan is None else unit_values(plan, form),
            problems=problems_by_field(problems or []),
            prompts=() if plan is None else plan.prompts_before("campaign"),
            form={k: v for k, v in form.items() if k.startswith(FIELD)},
        )

    async def new(request: Request) -> Response:
        return start_page(request)

    def uploaded(text: str) -> Path:
        """An uploaded plan (valid) as a file the campaign command reads, named by its hash."""
        folder = station.reports / "plans"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"plan-{hashlib.sha256(text.encode()).hexdigest()[:16]}.toml"
        path.write_text(text, encoding="utf-8")
        return path.resolve()

    async def read_plan(path: str, upload: object) -> tuple[Plan, str]:
        """The plan of the start form (an upload, else a path) and the path to run it from."""
        if isinstance(upload, UploadFile) and upload.filename:
            try:
                text = (await upload.read()).decode("utf-8")
            except UnicodeDecodeError:
                raise PlanError([f"upload: {upload.filename} is not UTF-8 text"]) from None
            plan = parse_plan(text)
            return plan, str(await run_in_threadpool(uploaded, text))
        if not path:
            raise PlanError(["plan: give the path of a plan file on this machine, or upload one"])
        return load_plan(Path(path)), str(Path(path).resolve())

    async def start(request: Request) -> Response:
        """Check the plan (the form without `start`), or start it (with `start`: the answers,
        the device under test and the operator as the checked form gave them)."""
        form = await action_form(request, access)
        path = str(form.get("plan", "")).strip()
        plan: Plan | None = None
        try:
            plan, path = await read_plan(path, form.get("upload"))
            if form.get("start") != "1":
                return start_page(request, path=path, plan=plan)
            answers, problems = start_answers(plan, form)
            text, unit_problems = with_unit(plan, unit_values(plan, form))
            if problems or unit_problems:
                raise PlanError(unit_problems + problems)
            if text != plan.text:  # run as edited, the plan file left as it is
                parse_plan(text)
                path = str(await run_in_threadpool(uploaded, text))
            digest = hashlib.sha256(text.encode()).hexdigest()

            def newest() -> int | None:
                return station.read(
                    lambda s: s.scalar(
                        select(func.max(Campaign.id)).where(Campaign.plan_hash == digest)
                    )
                )

            cid = await station.processes.start(Path(path), newest, answers)
        except (PlanError, ProcessRefused) as exc:
            problems = exc.problems if isinstance(exc, PlanError) else [str(exc)]
            return start_page(request, 400, path, plan, problems, form)
        return RedirectResponse(f"/campaigns/{cid}", status_code=303)

    def state_json(cid: int) -> dict[str, Any]:
        state = station.read(live_state, cid).as_json()
        running = station.processes.running(cid)
        acquiring = station.acquiring(cid)
        if state["status"] == "running" and not acquiring:
            state["status"] = "interrupted"  # its process is gone (killed): resume continues it
        state["acquiring"] = acquiring
        # a stopped, paused or failed run says why in the database (state["reason"]); an error
        # line is shown only for a run that ended without saying (interrupted)
        error = None if running else station.processes.error(cid)
        state["process_error"] = error if state["status"] == "interrupted" else None
        state["prompt"] = station.read(waiting_for, cid) if acquiring else None
        live = read_live(station.read(live_file, cid)) if acquiring else None
        state["live"] = None if state["prompt"] else live  # its series ended: not the current
        job = station.processes.reports.get(cid)
        state["report"] = None if job is None else job.progress()
        state["reports"] = [p.name for p in report_files(station.reports, cid)]
        state["decision"] = report_decision(station.reports, cid)
        return state

    def live_change(path: Path | None, mtime: int | None) -> tuple[int | None, Any]:
        """The live file's modification time, and its snapshot when that is not `mtime`; the
        acquisition is told that a page watches (it then rewrites the file every tick)."""
        try:
            now = None if path is None else path.stat().st_mtime_ns
        except OSError:
            now = None
        if path is not None and now is not None:
            with contextlib.suppress(OSError):  # (unwatched, it is rewritten every 2 s)
                live_watch_of(path).touch()
        return now, (read_live(path) if now is not None and now != mtime else None)

    def changed(cid: int, last: tuple[Any, ...] | None) -> tuple[tuple[Any, ...], bool]:
        """The campaign's fingerprint (with whether a process acquires into it) and whether it
        differs from `last`."""
        job = station.processes.reports.get(cid)
        report = None if job is None else tuple(job.progress().values())
        now = (*station.read(fingerprint, cid), station.acquiring(cid), report)
        return now, now != last

    async def campaign(request: Request) -> Response:
        cid = campaign_id(request)
        state = await run_in_threadpool(state_json, cid)
        signed = await run_in_threadpool(station.read, sign_offs, cid)
        return station.page(
            request,
            "campaign.html.j2",
            state=state,
            signed=signed,
            formats=state["report"]["formats"] if state["report"] else "html,json",
            message=request.query_params.get("message", ""),
        )

    async def stream(request: Request) -> Response:
        cid = campaign_id(request)

        async def updates() -> AsyncIterator[str]:
            """The whole state when the database changed; between, the running
            acquisition's live snapshot whenever it has a new one. When nothing acquires it
            says "end" and keeps watching, slower: a resume (here or elsewhere) streams on."""
            yield "retry: 1000\n\n"
            seen: tuple[Any, ...] | None = None
            path = await run_in_threadpool(station.read, live_file, cid)
            mtime: int | None = None
            acquiring = True
            while not await request.is_disconnected():
                seen, fresh = await run_in_threadpool(changed, cid, seen)
                if fresh:
                    state = await run_in_threadpool(state_json, cid)
                    yield f"event: state\ndata: {compact(state)}\n\n"
                    if acquiring and not state["acquiring"]:
                        yield "event: end\ndata: {}\n\n"
                    acquiring = state["acquiring"]
                    path = await run_in_threadpool(station.read, live_file, cid)  # a new run's
                mtime, snapshot = await run_in_threadpool(live_change, path, mtime)
                if snapshot is not None and not fresh and acquiring:  # (not a killed run's)
                    yield f"event: live\ndata: {compact(snapshot)}\n\n"
                await asyncio.sleep(TICK_S if acquiring else IDLE_TICK_S)

        return StreamingResponse(
            updates(),
            media_type="text/event-stream",
            headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
        )

    def back(cid: int, message: str = "") -> Response:
        suffix = f"?{urlencode({'message': message})}" if message else ""
        return RedirectResponse(f"/campaigns/{cid}{suffix}", status_code=303)

    async def stop(request: Request) -> Response:
        cid = campaign_id(request)
        await action_form(request, access)
        if not await run_in_threadpool(station.acquiring, cid):
            return back(cid, f"campaign {cid} is not being acquired: nothing to stop")
        await run_in_threadpool(station.write, request_stop, cid)
        return back(cid, "stop requested: the stand stops rocking, everything is committed")

    async def answered(request: Request) -> Response:
        cid = campaign_id(request)
        form = await action_form(request, access)
        prompt, value = str(form.get("prompt", "")), str(form.get("answer", ""))
        try:
            await run_in_threadpool(station.write, answer, cid, prompt, value)
        except ActionRefused as exc:
            return back(cid, str(exc))
        return back(cid, f"prompt {prompt}: answer recorded ({value})")

    async def resume(request: Request) -> Response:
        cid = campaign_id(request)
        form = await action_form(request, access)
        retry: list[int] = []
        if "trial" in form:
            try:
                retry = [int(str(form["trial"]))]
            except ValueError:
                return back(cid, f"trial: not a trial number: {form['trial']}")
        try:
            station.processes.resume(cid, retry)
        except ProcessRefused as exc:
            return back(cid, str(exc))
        return back(cid)

    async def report(request: Request) -> Response:
        cid = campaign_id(request)
        form = await action_form(request, access)
        formats = REPORT_FORMATS.get(str(form.get("formats", "html")), REPORT_FORMATS["html"])
        try:  # the same folder as `gyrostand report --out`
            station.processes.report(cid, station.reports, formats)
        except ProcessRefused as exc:
            return back(cid, str(exc))
        return back(cid)

    async def signoff(request: Request) -> Response:
        cid = campaign_id(request)
        form = await action_form(request, access)
        try:
            await run_in_threadpool(
                _write, sessions, cid, str(form.get("role", "")), str(form.get("name", ""))
            )
        except SignOffRefused as exc:
            return back(cid, str(exc))
        return back(cid, "signed")

    async def files(request: Request) -> Response:
        cid = campaign_id(request)
        name = request.path_params["name"]
        found = {p.name: p for p in report_files(station.reports, cid)}
        if name not in found:
            raise HTTPException(404, f"no report file {name!r} for campaign {cid}")
        return FileResponse(found[name])

    async def refused(request: Request, exc: Exception) -> Response:
        return Response(str(exc), status_code=403, media_type="text/plain")

    async def not_found(request: Request, exc: Exception) -> Response:
        assert isinstance(exc, HTTPException)
        return Response(str(exc.detail), status_code=exc.status_code, media_type="text/plain")

    app = Starlette(
        routes=[
            Route("/", campaigns),
            Route("/campaigns/new", new),
            Route("/campaigns", start, methods=["POST"]),
            Route("/campaigns/{campaign_id:int}", campaign),
            Route("/campaigns/{campaign_id:int}/stream", stream),
            Route("/campaigns/{campaign_id:int}/stop", stop, methods=["POST"]),
            Route("/campaigns/{campaign_id:int}/resume", resume, methods=["POST"]),
            Route("/campaigns/{campaign_id:int}/answer", answered, methods=["POST"]),
            Route("/campaigns/{campaign_id:int}/report", report, methods=["POST"]),
            Route("/campaigns/{campaign_id:int}/signoff", signoff, methods=["POST"]),
            Route("/campaigns/{campaign_id:int}/files/{name}", files),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
        ],
        exception_handlers={CrossSite: refused, HTTPException: not_found},
    )
    app.add_middleware(TokenMiddleware, access=access)
    app.add_middleware(HostMiddleware, access=access)  # the outermost: before any token
    app.state.processes = station.processes  # for a host that ends them (the tests)
    return app


def _write(sessions: sessionmaker[Session], cid: int, role: str, name: str) -> None:
    with writer(sessions).begin() as session:
        sign_off(session, cid, role, name)
