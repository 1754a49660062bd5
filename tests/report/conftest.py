"""Fixtures for the report tests, built once per session (the PDF render is the slow part):

- the seed-000 paper example imported from examples/paper.csv into a fresh database (operator
  name with a <script> tag), its report and its rendered files;
- a simulated campaign run on the lockstep simulated stand (tests/acquisition/harness.py) into
  a database through the real `CampaignStore`, with every frame written to a BLF raw log.
"""

import hashlib
import re
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import can
import pytest
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.lockstep import Lockstep
from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.io import SEED_000_METADATA, import_file
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.plan.model import parse_plan
from gyrostand.report.build import Report
from gyrostand.report.compliance import load_profile
from gyrostand.report.stored import campaign_report
from gyrostand.report.writer import write_report
from tests.acquisition.harness import plan_text, quick_config

ROOT = Path(__file__).resolve().parents[2]
PAPER_CSV = ROOT / "examples" / "paper.csv"
OPERATOR = "<script>alert('x')</script> I. Ivanov"
GENERATED = "2026-01-01 00:00:00+00:00"
SIM_TRIALS = [
    (45.0, 24.0, 6.0, "fit"),
    (315.0, 20.0, 5.0, "fit"),
    (30.0, 22.0, 8.0, "fit"),
    (60.0, 18.0, 4.5, "control"),
]


@dataclass(frozen=True)
class Stored:
    """A database holding one campaign."""

    path: Path
    sessions: sessionmaker[Session]
    campaign_id: int

    @property
    def url(self) -> str:
        return str(self.path)

    def report(self, generated_at: str = GENERATED) -> Report:
        return campaign_report(
            self.sessions,
            self.campaign_id,
            database=self.url,
            profile=load_profile(),
            generated_at=generated_at,
        )


def import_paper(folder: Path, operator: str = OPERATOR, plan_toml: str | None = None) -> Stored:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "paper.sqlite"
    sessions = open_database(sqlite_url(path))
    metadata = {**SEED_000_METADATA, "operator": operator, "software_version": "test"}
    if plan_toml is not None:
        metadata["plan_toml"] = plan_toml
    return Stored(path, sessions, import_file(sessions, PAPER_CSV, metadata))


@pytest.fixture(scope="session")
def paper(tmp_path_factory: pytest.TempPathFactory) -> Stored:
    return import_paper(tmp_path_factory.mktemp("paper"))


@pytest.fixture(scope="session")
def paper_report(paper: Stored) -> Report:
    return paper.report()


@dataclass(frozen=True)
class Rendered:
    files: dict[str, Path]
    pdf_text: str
    pdf_pages: int


def pdf_text(pdf: Path, *options: str) -> str:
    """The PDF's text by pdftotext (-layout unless told), without the invisible characters that
    mark where a long word may break (U+200B) or may not (U+2060, before a page number)."""
    out = subprocess.run(
        ["pdftotext", *(options or ("-layout",)), str(pdf), "-"], check=True, capture_output=True
    ).stdout.decode()
    return out.replace("\u200b\n", "").replace("\u200b", "").replace("\u2060", "")


@pytest.fixture(scope="session")
def paper_files(paper_report: Report, tmp_path_factory: pytest.TempPathFactory) -> Rendered:
    files = write_report(paper_report, tmp_path_factory.mktemp("paper-report"))
    text = pdf_text(files["pdf"])
    info = subprocess.run(
        ["pdfinfo", str(files["pdf"])], check=True, capture_output=True
    ).stdout.decode()
    pages = int(next(line for line in info.splitlines() if line.startswith("Pages:")).split()[1])
    return Rendered(files, text, pages)


def watermark_letters(pdf: Path) -> list[str]:
    """Per page, the sorted letters of the text set far larger than any heading: the watermark
    (pdftotext -bbox gives its rotated glyphs as words of a letter or two, each box over 30 pt
    high and over 10 pt wide, an "I" 14 pt; a figure's axis label turned upright is as high,
    but 8 pt wide: one line of 8 pt text)."""
    xml = subprocess.run(["pdftotext", "-bbox", str(pdf), "-"], check=True, capture_output=True)
    pages = xml.stdout.decode().split("<page ")[1:]
    word = re.compile(
        r'xMin="([\d.]+)" yMin="([\d.]+)" xMax="([\d.]+)" yMax="([\d.]+)">([^<]*)</word>'
    )
    return [
        "".join(
            sorted(
                "".join(
                    t
                    for x0, y0, x1, y1, t in word.findall(p)
                    if float(y1) - float(y0) > 30 and float(x1) - float(x0) > 10
                )
            )
        )
        for p in pages
    ]


@dataclass(frozen=True)
class Simulated(Stored):
    log: Path
    stream: tuple[can.Message, ...]


def run_simulated(folder: Path, edit: Callable[[str], str] = str) -> Simulated:
    """The lockstep simulated stand through the real engine and store, frames to a BLF log;
    `edit` changes the plan's TOML text first."""
    path = folder / "sim.sqlite"
    sessions = open_database(sqlite_url(path))
    plan = parse_plan(edit(plan_text(SIM_TRIALS, n_obs=4, database=str(path))))
    store = CampaignStore.create(sessions, plan)
    sim = Lockstep(quick_config(seed=3))
    engine = Engine(plan, store, sim, store.progress())
    sim.run(engine)
    store.set_status(engine.outcome)
    log = folder / "campaign.blf"
    with can.BLFWriter(log) as writer:
        for message in sim.stream:
            writer.on_message_received(message)
    seq = store.open_segment(str(log), "new")
    store.close_segment(seq, len(sim.stream), hashlib.sha256(log.read_bytes()).hexdigest())
    return Simulated(path, sessions, store.campaign_id, log, tuple(sim.stream))


@pytest.fixture(scope="session")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Simulated:
    return run_simulated(tmp_path_factory.mktemp("sim"))


@pytest.fixture(scope="session")
def simulated_report(simulated: Simulated) -> Report:
    return simulated.report()
