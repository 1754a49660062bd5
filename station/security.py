"""Who may use the station: anyone on the machine when it listens on loopback; beyond it, only
who presents the token (printed at start, or GYROSTAND_STATION_TOKEN). Every action (POST)
must come from the station's own page: a same-origin request carrying the page's CSRF token."""

from __future__ import annotations

import hmac
import ipaddress
import secrets
from dataclasses import dataclass
from urllib.parse import parse_qsl, urlencode, urlsplit

from starlette.datastructures import FormData
from starlette.requests import HTTPConnection, Request
from starlette.responses import PlainTextResponse, RedirectResponse, Response
from starlette.types import ASGIApp, Receive, Scope, Send

TOKEN_ENV = "GYROSTAND_STATION_TOKEN"
TOKEN_COOKIE = "gyrostand_station_token"
CSRF_FIELD = "csrf"


def is_loopback(host: str) -> bool:
    """`host` (a bind address) is reachable from this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class Access:
    """The station's secrets: `token` (None: loopback, no token needed) and the CSRF token its
    pages carry in every form."""

    token: str | None
    csrf: str

    @classmethod
    def for_host(cls, host: str, token: str | None) -> Access:
        """Loopback needs no token; any other address the given one or a new one."""
        if is_loopback(host):
            return cls(None, secrets.token_urlsafe(24))
        return cls(token or secrets.token_urlsafe(24), secrets.token_urlsafe(24))

    def admits(self, conn: HTTPConnection) -> bool:
        if self.token is None:
            return True
        header = conn.headers.get("authorization", "")
        given = (
            header.removeprefix("Bearer ").strip()
            if header.startswith("Bearer ")
            else conn.cookies.get(TOKEN_COOKIE, "")
        )
        return hmac.compare_digest(given.encode(), self.token.encode())


class TokenMiddleware:
    """Refuses every request without the token (401) when the station has one. `?token=...` in
    any address sets it as a cookie (HttpOnly, SameSite=Strict) and redirects without it."""

    def __init__(self, app: ASGIApp, access: Access) -> None:
        self.app = app
        self.access = access

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or self.access.token is None:
            await self.app(scope, receive, send)
            return
        conn = HTTPConnection(scope)
        given = conn.query_params.get("token")
        response: Response | None = None
        if given is not None and hmac.compare_digest(given.encode(), self.access.token.encode()):
            rest = [(k, v) for k, v in parse_qsl(conn.url.query) if k != "token"]
            response = RedirectResponse(
                conn.url.path + (f"?{urlencode(rest)}" if rest else ""), status_code=303
            )
            response.set_cookie(TOKEN_COOKIE, given, httponly=True, samesite="strict")
        elif not self.access.admits(conn):
            response = PlainTextResponse(
                "the station needs its token: open the address printed at its start "
                "(…/?token=...) or send 'Authorization: Bearer TOKEN'",
                status_code=401,
            )
        if response is not None:
            await response(scope, receive, send)
            return
        await self.app(scope, receive, send)


class CrossSite(PermissionError):
    """A POST that did not come from the station's own page."""


async def action_form(request: Request, access: Access) -> FormData:
    """The form of an action (POST), once it is known to come from the station's own page: the
    browser's Origin (or Sec-Fetch-Site) says same origin, and the form carries the CSRF
    token (CrossSite otherwise)."""
    origin = request.headers.get("origin")
    if origin is not None:  # "null" (a sandboxed frame, a redirect) is no origin of ours
        if urlsplit(origin).netloc != request.headers.get("host"):
            raise CrossSite(f"cross-site request from {origin} refused")
    elif request.headers.get("sec-fetch-site", "same-origin") not in ("same-origin", "none"):
        raise CrossSite("cross-site request refused")
    form = await request.form()
    given = form.get(CSRF_FIELD)
    if not isinstance(given, str) or not hmac.compare_digest(given.encode(), access.csrf.encode()):
        raise CrossSite("the form does not carry the station's token: reload the page")
    return form
