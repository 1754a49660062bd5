"""Bad input as a new user gives it: one line on stderr naming what is wrong, exit code 2, and
the database byte-identical (or not created). Stored strings reach the terminal as text, never as
rich markup or raw control characters; unexpected failures are one line and a traceback file."""

from __future__ import annotations

import random
import re
import tempfile
from pathlib import Path

import pytest
from sqlalchemy import select
from typer.testing import CliRunner

from gyrostand import SOFTWARE_VERSION
from gyrostand.cli import app
from gyrostand.db.models import Campaign, Event, Trial
from gyrostand.db.queries import CampaignHeader, new_campaign
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.logfile import BatchBLFWriter, read_raw_frames

from ..acquisition.harness import ROOT
from .cases import Case, Make, check, folder, ids, invoke, text_file
from .conftest import Stand, checkpointed, db_state, write_plan

BLF_HEADER = 144  # bytes of a BLF file header


def small_container_blf(stand: Stand, path: Path) -> Path:
    """The campaign's raw log rewritten in 4 KiB containers (many containers to cut between)."""
    writer = BatchBLFWriter(path, max_container_size=4096)
    for raw in read_raw_frames(stand.blf):
        writer.write_frames(raw)
    writer.stop()
    return path


def container_starts(data: bytes) -> list[int]:
    """Byte offsets of the LOG_CONTAINER objects of one of our BLF files."""
    return [m.start() for m in re.finditer(b"LOBJ", data) if m.start() >= BLF_HEADER]


def torn_first_container(stand: Stand, folder: Path) -> Path:
    data = small_container_blf(stand, folder / "whole.blf").read_bytes()
    path = folder / "torn.blf"
    path.write_bytes(data[: container_starts(data)[0] + 100])
    return path


def header_only(stand: Stand, folder: Path) -> Path:
    path = folder / "header.blf"
    path.write_bytes(stand.blf.read_bytes()[:BLF_HEADER])
    return path


def corrupt_blocks(stand: Stand, folder: Path) -> Path:
    data = bytearray(small_container_blf(stand, folder / "whole.blf").read_bytes())
    starts = container_starts(bytes(data))
    middle = starts[len(starts) // 2]
    for i in range(middle + 64, middle + 400, 7):  # inside the zlib stream of that container
        data[i] ^= 0x5A
    path = folder / "corrupt.blf"
    path.write_bytes(bytes(data))
    return path


def cut_header(stand: Stand, folder: Path) -> Path:
    path = folder / "random.blf"
    path.write_bytes(stand.blf.read_bytes()[: BLF_HEADER // 2])
    return path


def plan_file(**kw: object) -> Make:
    """The stand's kind of plan written in the test's folder, with `plan_text` keywords."""

    def make(_stand: Stand, tmp: Path) -> Path:
        return write_plan(tmp, "bad.toml", **kw)

    return make


def raw_dir_under_a_file(_stand: Stand, tmp: Path) -> Path:
    """A plan whose raw log folder would sit inside a regular file."""
    (tmp / "afile").write_text("not a folder\n")
    return write_plan(tmp, "bad.toml", raw_dir=str(tmp / "afile" / "raw"))


def raw_dir_is_a_file(_stand: Stand, tmp: Path) -> Path:
    (tmp / "afile").write_text("not a folder\n")
    return write_plan(tmp, "bad.toml", raw_dir=str(tmp / "afile"))


def paper_with(*changes: tuple[bytes, bytes]) -> Make:
    """examples/paper.csv with some substitutions (old, new)."""

    def make(_stand: Stand, tmp: Path) -> Path:
        data = PAPER_CSV.read_bytes()
        for old, new in changes:
            assert old in data
            data = data.replace(old, new)
        path = tmp / "paper.csv"
        path.write_bytes(data)
        return path

    return make


PAPER_CSV = ROOT / "examples" / "paper.csv"
PAPER_HEADER = (
    b"trial,role,direction_deg,amplitude_cm,period_s,delta_mean_deg,delta_var_deg2,n_obs\n"  # noqa: E501
)
RANDOM_BYTES = bytes(random.Random(18).randrange(256) for _ in range(4096))
GARBAGE_ASC = b"hello\nthis is not a CAN log at all\n"
BINARY_ASC = bytes(range(128, 256)) * 20
BAD_TRIALS_CSV = b"a,b\n1,2\n"
BROKEN_TOML = b"x = ["


REPLAY = [
    Case(
        "replay torn before first container",
        ("replay", "{file}"),
        "truncated",
        2,
        torn_first_container,
    ),
    Case("replay header-only blf", ("replay", "{file}"), "no CAN frames", 2, header_only),
    Case(
        "replay garbage asc",
        ("replay", "{file}"),
        "no CAN frames",
        2,
        text_file("garbage.asc", GARBAGE_ASC),
    ),
    Case(
        "replay binary asc",
        ("replay", "{file}"),
        "garbage.asc",
        2,
        text_file("garbage.asc", BINARY_ASC),
    ),
    Case("replay corrupt blocks", ("replay", "{file}"), "corrupt", 2, corrupt_blocks),
    Case(
        "replay text as blf",
        ("replay", "{file}"),
        "not a BLF file",
        2,
        text_file("notes.blf", b"just some notes\n" * 20),
    ),
    Case(
        "replay empty blf", ("replay", "{file}"), "not a BLF file", 2, text_file("empty.blf", b"")
    ),
    Case(
        "replay unknown log format",
        ("replay", "{file}"),
        "notes.txt",
        2,
        text_file("notes.txt", b"notes\n"),
    ),
    Case("replay missing log", ("replay", "{tmp}/none.blf"), "no log file", 2),
    Case("replay folder as log", ("replay", "{file}"), "no log file", 2, folder("log.blf")),
    Case("replay empty asc", ("replay", "{file}"), "no CAN frames", 2, text_file("e.asc", b"")),
    Case(
        "replay random bytes as blf",
        ("replay", "{file}"),
        "not a BLF file",
        2,
        text_file("random.blf", RANDOM_BYTES),
    ),
    Case("replay blf cut in its header", ("replay", "{file}"), "random.blf", 2, cut_header),
]

CASES = [
    # usage errors: one line, not a box
    Case("unknown command", ("frobnicate",), "No such command"),
    Case(
        "unknown option", ("campaign", "status", "1", "--db", "{db}", "--colour"), "No such option"
    ),
    Case(
        "campaign id not a number",
        ("campaign", "status", "x", "--db", "{db}"),
        "valid integer",
    ),
    Case("report campaign not a number", ("report", "abc", "--db", "{db}"), "valid integer"),
    Case("export unknown format", ("export", "1", "--db", "{db}", "-f", "pdf"), "'pdf'"),
    Case(
        "replay without its log", ("replay", "--plan", "{plan}", "--db", "{db}"), "Missing argument"
    ),
    Case(
        "speedup not a number",
        ("campaign", "run", "{plan}", "--db", "{db}", "--speedup", "x"),
        "valid number",
    ),
    # labels and the campaign list's filters
    Case(
        "run tag without value",
        ("campaign", "run", "{plan}", "--db", "{db}", "--tag", "factory"),
        "--tag: label 'factory' is not key=value (e.g. factory=A)",
    ),
    Case(
        "run tag bad key",
        ("campaign", "run", "{plan}", "--db", "{db}", "--tag", "Fac tory=A"),
        "--tag: label key 'Fac tory': use lower-case letters, digits and _",
    ),
    Case(
        "import tag twice",
        ("import", str(PAPER_CSV), "--db", "{db}", "--tag", "lot=1", "--tag", "lot=2"),
        "--tag: label lot given twice",
    ),
    Case(
        "import tag empty value",
        ("import", str(PAPER_CSV), "--db", "{db}", "--tag", "lot="),
        "--tag: label lot: the value must be 1 to 200 printable characters",
    ),
    Case(
        "list unknown status",
        ("campaign", "list", "--db", "{db}", "--status", "done"),
        "--status must be one of planned, running, paused, completed, failed, stopped",
    ),
    Case(
        "list date not a date",
        ("campaign", "list", "--db", "{db}", "--since", "yesterday"),
        "'yesterday' does not match the formats '%Y-%m-%d'",
    ),
    Case(
        "list until before since",
        ("campaign", "list", "--db", "{db}", "--since", "2026-02-01", "--until", "2026-01-01"),
        "--until is before --since",
    ),
    Case(
        "list two stands",
        ("campaign", "list", "--db", "{db}", "--stand", "S1", "--tag", "stand=S2"),
        "--stand and --tag stand=... name different stands",
    ),
    Case("list no database", ("campaign", "list", "--db", "{newdb}"), "no database at"),
    # unknown campaigns, missing databases
    Case("status unknown campaign", ("campaign", "status", "99", "--db", "{db}"), "no campaign 99"),
    Case("status no database", ("campaign", "status", "1", "--db", "{newdb}"), "no database at"),
    Case("resume unknown campaign", ("campaign", "resume", "99", "--db", "{db}"), "no campaign 99"),
    Case(
        "report unknown campaign", ("report", "99", "--db", "{db}", "-f", "json"), "no campaign 99"
    ),
    Case("report no database", ("report", "1", "--db", "{newdb}"), "no database at"),
    Case("analyze unknown campaign", ("analyze", "99", "--db", "{db}"), "no campaign 99"),
    Case(
        "analyze signal unknown campaign",
        ("analyze", "99", "--signal", "--db", "{db}"),
        "no campaign 99",
    ),
    Case("export unknown campaign", ("export", "99", "--db", "{db}"), "no campaign 99"),
    # bad formats and options
    Case("report unknown format", ("report", "1", "--db", "{db}", "-f", "doc"), "--format"),
    Case(
        "report unknown profile",
        ("report", "1", "--db", "{db}", "--profile", "nosuch"),
        "no compliance profile",
    ),
    Case(
        "report broken profile",
        ("report", "1", "--db", "{db}", "--profile", "{file}"),
        "not valid TOML",
        2,
        text_file("profile.toml", BROKEN_TOML),
    ),
    Case(
        "report out is a file",
        ("report", "1", "--db", "{db}", "-f", "json", "--out", "{file}"),
        "cannot write the report",
        2,
        text_file("taken", b"x"),
    ),
    Case(
        "run unknown timing",
        ("campaign", "run", "{plan}", "--db", "{db}", "--timing", "warp"),
        "--timing must be one of",
    ),
    Case(
        "run zero speedup",
        ("campaign", "run", "{plan}", "--db", "{db}", "--speedup", "0"),
        "--speedup must be > 0",
    ),
    Case(
        "run speedup on a real bus",
        ("campaign", "run", "{plan}", "--db", "{db}", "--interface", "virtual", "--speedup", "5"),
        "--speedup and --seed apply",
    ),
    Case("run missing plan", ("campaign", "run", "{tmp}/none.toml", "--db", "{db}"), "cannot read"),
    Case(
        "run broken plan",
        ("campaign", "run", "{file}", "--db", "{db}"),
        "invalid plan",
        2,
        text_file("broken.toml", BROKEN_TOML),
    ),
    Case("analyze missing csv", ("analyze", "--csv", "{tmp}/none.csv"), "cannot read"),
    Case(
        "analyze csv that is prose",  # pandas's message ends with a newline: not shown as \\n
        ("analyze", "--csv", "{file}"),
        "Expected 1 fields in line 3, saw 4)",
        make=text_file("README.md", b"Title\nplain text\ntext, with, some, commas\n"),
    ),
    Case(
        "analyze csv without columns",
        ("analyze", "--csv", "{file}"),
        "missing column",
        2,
        text_file("bad.csv", BAD_TRIALS_CSV),
    ),
    Case("analyze no source", ("analyze",), "no source given"),
    Case("analyze log without signal", ("analyze", "--log", "{tmp}/x.blf"), "go with --signal"),
    Case(
        "analyze campaign and csv",
        ("analyze", "1", "--db", "{db}", "--csv", "{file}"),
        "not both",
        2,
        text_file("bad.csv", BAD_TRIALS_CSV),
    ),
    Case(
        "analyze signal missing log",
        ("analyze", "--signal", "--log", "{tmp}/none.blf"),
        "not found",
    ),
    Case(
        "analyze signal unknown log format",
        ("analyze", "--signal", "--log", "{file}"),
        "cannot read",
        2,
        text_file("notes.txt", b"notes\n"),
    ),
    Case(
        "analyze signal corrupt log",
        ("analyze", "--signal", "--log", "{file}"),
        "corrupt",
        2,
        corrupt_blocks,
    ),
    Case("import missing file", ("import", "{tmp}/none.csv", "--db", "{newdb}"), "cannot read"),
    Case(
        "import bad table",
        ("import", "{file}", "--db", "{db}"),
        "bad.csv",
        2,
        text_file("bad.csv", BAD_TRIALS_CSV),
    ),
    Case(
        "simulate bad step", ("simulate", "--step", "rock 1 2", "--log", "{tmp}/x.blf"), "bad step"
    ),
    Case(
        "simulate bad log suffix",
        ("simulate", "--step", "still 5", "--log", "{tmp}/x.txt"),
        "ending in .blf or .asc",
    ),
    Case(
        "simulate log folder missing",
        ("simulate", "--step", "still 5", "--log", "{tmp}/none/x.blf"),
        "does not exist",
    ),
    Case(
        "plan schema unwritable",
        ("plan", "schema", "--out", "{tmp}/none/schema.json"),
        "cannot write",
    ),
]


RUN = ("campaign", "run", "{plan}", "--db", "{db}", "--quiet")
RESUME = ("campaign", "resume", "1", "--db", "{db}", "--quiet")
BUS = [  # nothing may be written when the bus or the raw log folder cannot be used
    Case("run unknown interface", (*RUN, "--interface", "nosuchiface"), "'nosuchiface'"),
    Case("resume unknown interface", (*RESUME, "--interface", "nosuchiface"), "'nosuchiface'"),
    Case("run empty interface", (*RUN, "--interface", ""), "[bus] interface"),
    Case(
        "run missing socketcan channel",
        (*RUN, "--interface", "socketcan", "--channel", "doesnotexist0"),
        "'doesnotexist0'",
        1,
    ),
    Case(
        "resume missing socketcan channel",
        (*RESUME, "--interface", "socketcan", "--channel", "doesnotexist0"),
        "'doesnotexist0'",
        1,
    ),
    Case("run negative seed", (*RUN, "--seed", "-1"), "[bus] seed: must be >= 0"),
    Case("resume negative seed", (*RESUME, "--seed", "-1"), "[bus] seed: must be >= 0"),
    Case("resume unknown timing", (*RESUME, "--timing", "warp"), "--timing must be one of"),
    Case("resume zero speedup", (*RESUME, "--speedup", "0"), "--speedup must be > 0"),
    Case(
        "run raw log folder inside a file",
        ("campaign", "run", "{file}", "--db", "{db}", "--quiet"),
        "cannot write raw CAN logs in",
        1,
        raw_dir_under_a_file,
    ),
    Case(
        "run raw log folder is a file",
        ("campaign", "run", "{file}", "--db", "{db}", "--quiet"),
        "cannot write raw CAN logs in",
        1,
        raw_dir_is_a_file,
    ),
    Case(
        "run raw log folder inside a file, new db",
        ("campaign", "run", "{file}", "--db", "{newdb}", "--quiet"),
        "cannot write raw CAN logs in",
        1,
        raw_dir_under_a_file,
    ),
]

IMPORT = [
    Case(
        "import json file",
        ("import", "{file}", "--db", "{db}"),
        "unsupported file type '.json'",
        2,
        text_file("data.json", b'{"trial": 1}'),
    ),
    Case(
        "import empty csv",
        ("import", "{file}", "--db", "{db}"),
        "no header row",
        2,
        text_file("empty.csv", b""),
    ),
    Case(
        "import header-only csv",
        ("import", "{file}", "--db", "{db}"),
        "no data rows",
        2,
        text_file("header.csv", PAPER_HEADER),
    ),
    Case(
        "import garbage xlsx",
        ("import", "{file}", "--db", "{db}"),
        "cannot read it",
        2,
        text_file("data.xlsx", RANDOM_BYTES),
    ),
    Case(
        "import truncated xlsx",
        ("import", "{file}", "--db", "{db}"),
        "cannot read it",
        2,
        text_file("data.xlsx", b"PK\x03\x04"),
    ),
    Case(
        "import garbage parquet",
        ("import", "{file}", "--db", "{db}"),
        "cannot read it",
        2,
        text_file("data.parquet", RANDOM_BYTES),
    ),
    Case(
        "import csv not utf-8",
        ("import", "{file}", "--db", "{db}"),
        "cannot read it",
        2,
        text_file("latin.csv", "trial,r\u00f4le\n".encode("latin-1")),
    ),
    Case(
        "import folder", ("import", "{file}", "--db", "{db}"), "cannot read it", 2, folder("d.csv")
    ),
    Case(
        "import unknown role",
        ("import", "{file}", "--db", "{db}"),
        "role = 'fitt' is not fit or control",
        2,
        paper_with((b",fit,", b",fitt,")),
    ),
    Case(
        "import direction out of range",
        ("import", "{file}", "--db", "{db}"),
        "direction_deg = 412.0 is not in [0, 360)",
        2,
        paper_with((b"1,fit,332,", b"1,fit,412,")),
    ),
    Case(
        "import row with a field too many",
        ("import", "{file}", "--db", "{db}"),
        "9 fields, the header has 8",
        2,
        paper_with((b"1,fit,332,", b"1,fit,332,0,")),
    ),
    Case(
        "import empty operator",
        ("import", str(PAPER_CSV), "--db", "{db}", "--operator", " "),
        "operator = ' ' is not non-empty text",
    ),
    Case(
        "import plan not valid",
        ("import", str(PAPER_CSV), "--db", "{newdb}", "--plan", "{file}"),
        "[campaign] n_obs: must be >= 2",
        2,
        plan_file(n_obs=1),
    ),
    Case(
        "import plan missing",
        ("import", str(PAPER_CSV), "--db", "{db}", "--plan", "{tmp}/none.toml"),
        "cannot read the file",
    ),
]

OPTIONS = [
    *(
        Case(f"{' '.join(command)} negative id", (*command, "-1", "--db", "{db}"), "No such option")
        for command in (("campaign", "status"), ("campaign", "resume"), ("analyze",))
    ),
    *(
        Case(f"{command} negative id", (command, "-1", "--db", "{db}"), "No such option")
        for command in ("export", "report")
    ),
    *(
        Case(
            f"{' '.join(command)} id beyond any column",
            (*command, str(10**20), "--db", "{db}"),
            "Input should be less than or equal to 2147483647",
        )
        for command in (
            ("campaign", "status"),
            ("campaign", "resume"),
            ("analyze",),
            ("export",),
            ("report",),
        )
    ),
    Case(
        "status id after -- negative",
        ("campaign", "status", "--db", "{db}", "--", "-1"),
        "Input should be greater than or equal to 1",
    ),
    Case(
        "status id zero",
        ("campaign", "status", "0", "--db", "{db}"),
        "Input should be greater than or equal to 1",
    ),
    Case("status db empty string", ("campaign", "status", "1", "--db", ""), "is a folder"),
    Case(
        "status db not a url",
        ("campaign", "status", "1", "--db", "://"),
        "neither a file path nor a database URL",
    ),
    Case(
        "status db driver not installed",
        ("campaign", "status", "1", "--db", "nosuchdriverdb+nosuch://u@localhost/db"),
        "unknown database dialect",
    ),
    Case(
        "analyze signal empty span",
        ("analyze", "--signal", "--log", "{blf}", "--from", "100", "--to", "50"),
        "empty stand-time span",
    ),
    Case(
        "analyze csv of two fit trials",
        ("analyze", "--csv", "{file}"),
        "need at least 3",
        2,
        paper_with((b"3,fit,", b"3,control,"), (b"4,fit,", b"4,control,")),
    ),
    Case(
        "run virtual timing with speedup",
        (*RUN, "--timing", "virtual", "--speedup", "2"),
        "excludes --timing virtual",
    ),
    Case(
        "simulate fault bits beyond the frame",
        ("simulate", "--step", "still 5", "--log", "{tmp}/x.blf", "--compass-fault-bits", "300"),
        "compass_fault_bits would put 300 in GYRO_STATUS.FAULT_BITS",
    ),
    Case(
        "simulate heading rate beyond ms",
        ("simulate", "--step", "still 5", "--log", "{tmp}/x.blf", "--heading-rate-hz", "1e9"),
        "heading_rate_hz must be <= 1000",
    ),
    Case(
        "export out inside a file",
        ("export", "1", "--db", "{db}", "--out", "{file}/x.csv"),
        "cannot write",
        2,
        text_file("afile", b"x"),
    ),
]

TABLES = CASES + BUS + IMPORT + OPTIONS


@pytest.mark.parametrize("case", TABLES, ids=ids(TABLES))
def test_bad_input_is_one_line_and_touches_nothing(case: Case, stand: Stand, tmp_path: Path):
    check(case, stand, tmp_path, stand.db_copy(tmp_path))


@pytest.mark.parametrize("existing", [True, False], ids=["existing db", "new db"])
@pytest.mark.parametrize("case", REPLAY, ids=ids(REPLAY))
def test_unreadable_log_replays_nothing(case: Case, existing: bool, stand: Stand, tmp_path: Path):
    db = stand.db_copy(tmp_path) if existing else tmp_path / "new.sqlite"
    check(case, stand, tmp_path, db, ("--plan", str(stand.plan), "--db", str(db)))
    assert existing or not db.exists()


def test_truncated_log_is_replayed_with_an_event_and_never_resumed(stand: Stand, tmp_path: Path):
    data = small_container_blf(stand, tmp_path / "whole.blf").read_bytes()
    starts = container_starts(data)
    log = tmp_path / "cut.blf"
    log.write_bytes(data[: starts[len(starts) // 2] + 100])  # half the containers, one torn
    frames = sum(len(raw) for raw in read_raw_frames(log))
    db = stand.db_copy(tmp_path)
    code, out, err = invoke("replay", str(log), "--plan", str(stand.plan), "--db", str(db))
    assert code == 1, err  # the log ends before the campaign does
    assert "campaign 2 stopped" in out and "resume" not in out + err
    sessions = open_database(sqlite_url(db))
    with sessions() as session:
        campaign = session.get_one(Campaign, 2)
        assert campaign.source == "replay"
        messages = session.scalars(select(Event.message).where(Event.campaign_id == 2)).all()
    assert any(f"truncated after {frames} frames" in m for m in messages), messages
    sessions.kw["bind"].dispose()

    before = db_state(checkpointed(db))
    code, out, err = invoke("campaign", "resume", "2", "--db", str(db))
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1 and "replay" in lines[0], err
    assert out == "" and db_state(db) == before

    code, out, _ = invoke("campaign", "status", "2", "--db", str(db))
    assert code == 0 and "(replay)" in out and "next:" not in out


MARKUP_OPERATOR = "[/]"
MARKUP_MODEL = "[/model]\x1b[31m\x00"
MARKUP_REASON = "[bold]red[/bold] :smile: \x1b]0;title\x07"


def markup_campaign(db: Path) -> int:
    """A campaign whose stored strings are rich markup, emoji codes and control characters."""
    sessions = open_database(sqlite_url(db))
    with sessions.begin() as session:
        header = CampaignHeader(
            model=MARKUP_MODEL,
            serial="[i]S-1[/i]",
            lp_gcm2s2=6.57e6,
            h1_gcm2s=1.55e8,
            latitude_deg=46.5,
            earth_rate_rad_s=7.3e-5,
            gravity_cm_s2=981.0,
            plan_toml="# not a plan [/]\n",
            operator=MARKUP_OPERATOR,
            n_obs=3,
            software_version=SOFTWARE_VERSION,
        )
        campaign = new_campaign(session, header, status="paused", source="stand")
        trial = Trial(
            campaign=campaign,
            index=1,
            role="fit",
            cmd_direction_deg=45.0,
            cmd_amplitude_cm=24.0,
            cmd_period_s=6.0,
            status="failed",
            failure_reason=MARKUP_REASON,
        )
        session.add(trial)
        session.flush()
        session.add(Event(campaign=campaign, kind="fault", severity="error", message=MARKUP_REASON))
        session.flush()
        campaign_id = campaign.id
    sessions.kw["bind"].dispose()
    return campaign_id


def test_status_prints_stored_strings_as_text(tmp_path: Path) -> None:
    db = tmp_path / "markup.sqlite"
    campaign_id = markup_campaign(db)
    before = db_state(db)
    result = CliRunner().invoke(app, ["campaign", "status", str(campaign_id), "--db", str(db)])
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "operator [/]" in out
    assert r"[/model]\x1b[31m\x00" in out
    assert "[i]S-1[/i]" in out
    assert r"[bold]red[/bold] :smile: \x1b]0;title\x07" in out  # failure reason and event
    assert out.count(":smile:") == 2
    assert not re.search(r"[\x00-\x08\x0b-\x1f\x7f]", out), repr(out)
    assert result.stderr == ""
    assert db_state(db) == before


def test_unexpected_error_is_one_line_and_a_traceback_file(
    stand: Stand, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from gyrostand import cmd_campaign

    def broken(*_args: object, **_kw: object) -> None:
        raise RuntimeError("the \x1b[31mdisk[/] fell off")

    monkeypatch.setattr(cmd_campaign, "open_db", broken)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    code, out, err = invoke("campaign", "status", "1", "--db", str(stand.db))
    lines = err.splitlines()
    assert code == 1 and out == "" and len(lines) == 1, err
    match = re.fullmatch(
        r"gyrostand: internal error: RuntimeError: (.*); traceback written to (.*)", lines[0]
    )
    assert match, lines[0]
    assert match[1] == r"the \x1b[31mdisk[/] fell off"
    written = Path(match[2])
    assert written.parent == tmp_path
    text = written.read_text()
    assert "Traceback (most recent call last)" in text and "RuntimeError" in text
    assert "campaign status 1" in text  # the command line
