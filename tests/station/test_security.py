"""The station's defences against the real server: `gyrostand station` (uvicorn) in a process of
its own, spoken to over a socket (http.client: every header as sent, nothing normalised). A
foreign Host is refused before anything else (DNS rebinding), an Origin must match scheme, host
and port, an invalid file name is one 404, and with a certificate the station speaks TLS only."""

import http.client
import re
import shutil
import sqlite3
import ssl
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app as cli
from gyrostand.station.security import host_name, host_names

from .test_browser import free_port

OPENSSL = shutil.which("openssl")


@contextmanager
def serving(station_db: Path, folder: Path, *options: str) -> Iterator[int]:
    """`gyrostand station` on loopback on a copy of `station_db` in `folder` (a report file of
    campaign 1 in its reports folder); its port, once it listens."""
    db = folder / "db.sqlite"
    with sqlite3.connect(station_db) as src, sqlite3.connect(db) as dst:
        src.backup(dst)
    (folder / "reports").mkdir(parents=True)
    (folder / "reports" / "campaign-1.html").write_text("the report")
    port = free_port()
    command = [sys.executable, "-m", "gyrostand", "station", "--db", str(db), "--port", str(port)]
    command += ["--reports", str(folder / "reports"), *options]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stderr.readline()  # printed once the socket listens
        assert f":{port}/" in line, line + process.stderr.read()
        yield port
    finally:
        process.terminate()
        process.wait(30)
        process.stderr.close()


@pytest.fixture(scope="module")
def plain(station_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    folder = tmp_path_factory.mktemp("plain")
    with serving(station_db, folder, "--allow-host", "Gyro.Lab") as port:
        yield port


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A self-signed certificate for localhost and 127.0.0.1, and its key (openssl)."""
    if OPENSSL is None:
        pytest.skip("no openssl command: install Debian's openssl (tools/system-deps)")
    folder = tmp_path_factory.mktemp("tls")
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(
        [OPENSSL, "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1"]
        + ["-nodes", "-days", "2", "-subj", "/CN=localhost", "-keyout", str(key)]
        + ["-out", str(cert), "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1"],
        check=True,
        capture_output=True,
    )
    return cert, key


@pytest.fixture(scope="module")
def tls(
    station_db: Path, certificate: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[int]:
    folder = tmp_path_factory.mktemp("served-tls")
    cert, key = certificate
    with serving(station_db, folder, "--tls-cert", str(cert), "--tls-key", str(key)) as port:
        yield port


def request(
    port: int,
    path: str,
    *,
    host: str | None = None,
    body: str | None = None,
    origin: str | None = None,
    tls: Path | None = None,
) -> tuple[int, str]:
    """Status and body of a GET (a form POST with `body`); Host 127.0.0.1:PORT unless `host`;
    over TLS trusting the certificate `tls`."""
    if tls is None:
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    else:
        context = ssl.create_default_context(cafile=str(tls))
        conn = http.client.HTTPSConnection("127.0.0.1", port, timeout=60, context=context)
    headers = {"Host": f"127.0.0.1:{port}" if host is None else host}
    if origin is not None:
        headers["Origin"] = origin
    if body is not None:
        headers["Content-Type"] = "application/x-www-form-urlencoded"
    conn.request("GET" if body is None else "POST", path, body=body, headers=headers)
    response = conn.getresponse()
    found = response.status, response.read().decode(errors="replace")
    conn.close()
    return found


def page_csrf(port: int, tls: Path | None = None) -> str:
    status, page = request(port, "/campaigns/1", tls=tls)
    assert status == 200
    found = re.search(r'name="csrf" value="([^"]+)"', page)
    assert found is not None
    return found.group(1)


def test_the_names_a_station_answers_to() -> None:
    import socket

    loopback = {"localhost", "127.0.0.1", "::1"}
    assert host_names("127.0.0.1") == loopback
    assert host_names("::1", ["Gyro.Lab", "[fd00::7]"]) == loopback | {"gyro.lab", "fd00::7"}
    assert host_names("192.0.2.9") == loopback | {"192.0.2.9"}
    everywhere = host_names("0.0.0.0")
    assert loopback | {socket.gethostname().lower()} <= everywhere
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:  # the routed address
        try:
            probe.connect(("192.0.2.1", 9))  # (UDP: nothing is sent)
        except OSError:
            return  # no route off this machine: no other address to see
        assert probe.getsockname()[0] in everywhere


def test_host_names_are_parsed_strictly() -> None:
    assert host_name("127.0.0.1:8000") == "127.0.0.1" and host_name("[::1]:8000") == "::1"
    assert host_name("LocalHost") == "localhost" and host_name("gyro.lab") == "gyro.lab"
    for bad in ("", "evil@127.0.0.1", "127.0.0.1/x", "127.0.0.1:http", "[::1", "127.0.0.1?"):
        assert host_name(bad) == "", bad


def test_a_foreign_host_is_refused_before_any_page_or_token(plain: int) -> None:
    """DNS rebinding: evil.example resolved to 127.0.0.1 gets no page (no CSRF token) and
    writes nothing, even with the token and a matching Origin; loopback's names (any case,
    with the port) and --allow-host's are served."""
    csrf = page_csrf(plain)
    sign = f"csrf={csrf}&role=tested_by&name=Mallory"
    for host in (f"evil.example:{plain}", "evil.example", f"127.0.0.1.evil.example:{plain}", ""):
        for path in ("/", "/campaigns/1", "/static/station.js"):
            status, body = request(plain, path, host=host)
            assert status == 400 and "is not a name of this station" in body, (host, path)
            assert csrf not in body
        origin = f"http://{host}"
        assert request(plain, "/campaigns/1/signoff", host=host, body=sign, origin=origin)[0] == 400
    assert "Mallory" not in request(plain, "/campaigns/1")[1]
    for host in (f"127.0.0.1:{plain}", f"LOCALHOST:{plain}", f"[::1]:{plain}", "gyro.lab"):
        assert request(plain, "/", host=host)[0] == 200, host


def test_an_origin_must_match_the_scheme_too(plain: int) -> None:
    form = f"csrf={page_csrf(plain)}"
    for origin in (f"https://127.0.0.1:{plain}", f"http://127.0.0.1:{plain + 1}", "null"):
        status, body = request(plain, "/campaigns/1/stop", body=form, origin=origin)
        assert status == 403 and "cross-site request" in body, origin
    same = f"http://127.0.0.1:{plain}"
    assert request(plain, "/campaigns/1/stop", body=form, origin=same)[0] == 303


def test_an_invalid_file_name_is_one_404(plain: int) -> None:
    assert request(plain, "/campaigns/1/files/campaign-1.html") == (200, "the report")
    for path in (
        "/campaigns/1/files/campaign-1%00.html",
        "/campaigns/1/files/campaign-1" + "a" * 5000 + ".html",
        "/campaigns/1/files/campaign-1%ff",
        "/campaigns/1/files/campaign-1%2F..%2F..%2Fdb.sqlite",
        "/campaigns/99999999999999999999999/files/campaign-1.html",
        "/static/station%00.js",
    ):
        status, body = request(plain, path)
        assert status == 404 and "\n" not in body.strip(), path


def test_with_a_certificate_the_station_speaks_tls_only(
    tls: int, certificate: tuple[Path, Path]
) -> None:
    cert = certificate[0]
    status, page = request(tls, "/", tls=cert)
    assert status == 200 and 'href="/campaigns/1"' in page
    form = f"csrf={page_csrf(tls, cert)}"
    http_origin, https_origin = f"http://127.0.0.1:{tls}", f"https://127.0.0.1:{tls}"
    assert request(tls, "/campaigns/1/stop", body=form, origin=http_origin, tls=cert)[0] == 403
    assert request(tls, "/campaigns/1/stop", body=form, origin=https_origin, tls=cert)[0] == 303
    with pytest.raises((http.client.HTTPException, OSError)):  # clear HTTP: not served
        request(tls, "/")


def test_tls_options_are_checked_in_one_line(tmp_path: Path, certificate: tuple[Path, Path]):
    cert, key = certificate
    garbage = tmp_path / "garbage.pem"
    garbage.write_text("not a certificate\n")
    db = ["--db", str(tmp_path / "s.db"), "--port", str(free_port())]
    for options, says in (
        (["--tls-cert", str(cert)], "--tls-cert and --tls-key go together"),
        (["--tls-cert", str(garbage), "--tls-key", str(key)], "not a PEM certificate"),
        (["--tls-cert", str(cert), "--tls-key", str(tmp_path / "no.pem")], "cannot read"),
    ):
        result = CliRunner().invoke(cli, ["station", *db, *options])
        assert result.exit_code == 2, result.output
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and says in lines[0], lines
