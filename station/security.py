"""Who may use the station: anyone on the machine when it listens on loopback; beyond it, only
who presents the token (printed at start, or GYROSTAND_STATION_TOKEN). Every request must name
the station by one of its own host names (no DNS rebinding), and every action (POST) must come
from the station's own page: a same-origin request carrying the page's CSRF token."""

from __future__ import annotations

import hmac
import ipaddress
import secrets
import socket
from collections.abc import Iterable
from dataclasses import dataclass
from urllib.parse import parse_qsl, urlencode, urlsplit

import ifaddr
from starlette.datastructures import FormData
from starlette.requests import HTTPConnection, Request
from starlette.responses import PlainTextResponse, RedirectResponse, Response
from starlette.types import ASGIApp, Receive, Scope, Send

TOKEN_ENV = "GYROSTAND_STATION_TOKEN"
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
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


def host_names(host: str, allowed: Iterable[str] = ()) -> frozenset[str]:
    """The names a browser may use for a station bound to `host` (the Host header's name,
    lower case, without port or brackets): loopback's; beyond it the bound address, and for
    every address (0.0.0.0, ::) this machine's names and its interfaces' addresses; plus
    `allowed`."""
    names = set(LOOPBACK_NAMES) if is_loopback(host) else {host, *LOOPBACK_NAMES}
    if host in ("0.0.0.0", "::", ""):  # every interface's addresses (ifaddr: IPv6 as tuples)
        names |= {socket.gethostname(), socket.getfqdn()}
        names |= {
            ip.ip if isinstance(ip.ip, str) else ip.ip[0]
            for adapter in ifaddr.get_adapters()
            for ip in adapter.ips
        }
    return frozenset(n.strip("[]").lower() for n in (*names, *allowed))


@dataclass(frozen=True)
class Access:
    """The station's secrets: `token` (None: loopback, no token needed) and the CSRF token its
    pages carry in every form; and `hosts`, the names it answers to (`host_names`)."""

    token: str | None
    csrf: str
    hosts: frozenset[str]

    @classmethod
    def for_host(cls, host: str, token: str | None, allowed: Iterable[str] = ()) -> Access:
        """Loopback needs no token; any other address the given one or a new one."""
        hosts = host_names(host, allowed)
        if is_loopback(host):
            return cls(None, secrets.token_urlsafe(24), hosts)
        return cls(token or secrets.token_urlsafe(24), secrets.token_urlsafe(24), hosts)

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
            response.set_cookie(
                TOKEN_COOKIE,
                given,
                httponly=True,
                samesite="strict",
                secure=conn.url.scheme == "https",  # over TLS, never sent in clear
            )
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


def host_name(header: str) -> str:
    """The name of a Host header (`name[:port]`, `[v6]:port`), lower case, without brackets;
    "" for anything else (user info, a path, a port that is no number)."""
    try:
        parts = urlsplit(f"//{header}")
        parts.port  # noqa: B018 -- raises on a port that is no number
    except ValueError:  # (and an unclosed "[")
        return ""
    return (parts.hostname or "") if parts.netloc == header and "@" not in header else ""


class HostMiddleware:
    """Refuses (400) a request whose Host header is not one of the station's names, before
    anything else reads it: a page of another site whose name was made to resolve to this
    machine (DNS rebinding) reaches no page, token or action. Starlette's TrustedHostMiddleware
    does the same but answers only "Invalid host header": the operator who opened the station
    by a name it does not know needs that name and the option that adds it."""

    def __init__(self, app: ASGIApp, access: Access) -> None:
        self.app = app
        self.access = access

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket"):
            given = HTTPConnection(scope).headers.get("host", "")
            if host_name(given) not in self.access.hosts:
                shown = given.encode("unicode_escape").decode()[:100]
                response = PlainTextResponse(
                    f"Host {shown!r} is not a name of this station: open the address it "
                    "printed at its start (gyrostand station --allow-host NAME adds a name)",
                    status_code=400,
                )
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
        own = f"{request.url.scheme}://{request.headers.get('host', '')}"
        if origin.lower() != own.lower():  # scheme, host and port
            raise CrossSite(f"cross-site request from {origin} refused")
    elif request.headers.get("sec-fetch-site", "same-origin") not in ("same-origin", "none"):
        raise CrossSite("cross-site request refused")
    form = await request.form()
    given = form.get(CSRF_FIELD)
    if not isinstance(given, str) or not hmac.compare_digest(given.encode(), access.csrf.encode()):
        raise CrossSite("the form does not carry the station's token: reload the page")
    return form
