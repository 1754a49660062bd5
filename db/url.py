"""The one printable form of a database's URL: never its password. Imports nothing heavy, so
every command (and the error boundary) can use it."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

DB_ENV = "GYROSTAND_DB"
"""The environment variable the commands' --db default is read from: the station hands its
database to the commands it starts this way, so that a URL's password never shows in the
process list (`ps` lists every process's arguments to every user)."""

if TYPE_CHECKING:
    from sqlalchemy.engine import URL

_PASSWORD_PARAMETER = re.compile(r"([?&]password=)[^&]*", re.IGNORECASE)


def shown_url(url: str | URL) -> str:
    """The database as it may be printed, written or stored (messages, hints, reports, events):
    a URL with its password as ***, in its user part or a `password=` parameter; a file path
    as given. (SQLAlchemy's render_as_string(hide_password=True) shows the tail of a password
    with an unencoded "@" and fails on a URL it cannot parse: here everything between the
    user's ":" and the last "@" is hidden.)"""
    text = url if isinstance(url, str) else url.render_as_string(hide_password=True)
    if "://" not in text:
        return text
    scheme, _, rest = text.partition("://")
    userinfo, at, place = rest.rpartition("@")
    if at and ":" in userinfo:
        rest = f"{userinfo.partition(':')[0]}:***@{place}"
    return _PASSWORD_PARAMETER.sub(r"\1***", f"{scheme}://{rest}")
