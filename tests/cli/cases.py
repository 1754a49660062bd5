"""The table-driven bad-input suite's machinery: a `Case` is a command line with what must come
of it (one line on stderr naming the problem, its exit code), `check` runs it in process and
asserts that, and that neither the database nor the file given changed (nor a database was
created)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from typer.testing import CliRunner

from gyrostand.cli import app

from .conftest import Stand, db_state

Make = Callable[[Stand, Path], Path]


def invoke(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.stdout, result.stderr


def text_file(name: str, content: bytes) -> Make:
    def make(_stand: Stand, folder: Path) -> Path:
        path = folder / name
        path.write_bytes(content)
        return path

    return make


def folder(name: str) -> Make:
    def make(_stand: Stand, tmp: Path) -> Path:
        path = tmp / name
        path.mkdir()
        return path

    return make


@dataclass(frozen=True)
class Case:
    """`args` may name {db} (a copy of the stand's database), {newdb} (no file there), {plan}
    (the stand's plan), {blf} (its raw log), {file} (made by `make` in the test's folder) and
    {tmp} (that folder). `code`: 2 for bad input, 1 for an environment that refuses."""

    id: str
    args: tuple[str, ...]
    message: str
    code: int = 2
    make: Make | None = field(default=None, compare=False)


def ids(cases: list[Case]) -> list[str]:
    assert len({c.id for c in cases}) == len(cases), "two cases with one id"
    return [c.id for c in cases]


def args_of(
    case: Case, stand: Stand, tmp: Path, db: Path, **more: object
) -> tuple[list[str], Path]:
    """The command line (`more`: other names it may use), and the file `make` made (a path
    that does not exist otherwise)."""
    file = case.make(stand, tmp) if case.make is not None else tmp / "unused"
    values = {
        "db": db,
        "newdb": tmp / "new.sqlite",
        "plan": stand.plan,
        "blf": stand.blf,
        "file": file,
        "tmp": tmp,
        **more,
    }
    return [arg.format(**{k: str(v) for k, v in values.items()}) for arg in case.args], file


def state(path: Path) -> object:
    """What a command could change at `path`: a database's bytes (and its WAL's), a folder's
    entries and their bytes, nothing when there is nothing."""
    if path.is_dir():
        return sorted((p.name, p.read_bytes() if p.is_file() else None) for p in path.iterdir())
    return db_state(path)


def check(case: Case, stand: Stand, tmp: Path, db: Path, extra: tuple[str, ...] = ()) -> str:
    """Run the case; assert one line naming the problem, the exit code, nothing changed.
    Returns the line."""
    args, file = args_of(case, stand, tmp, db)
    args += list(extra)
    before = state(db), state(file)
    code, _, err = invoke(*args)
    lines = err.splitlines()
    assert len(lines) == 1, f"{args}: stderr is {err!r}"
    assert lines[0].startswith("gyrostand: error: "), lines[0]
    assert "Traceback" not in err and "internal error" not in err, err
    assert case.message in lines[0], lines[0]
    assert code == case.code, (code, lines[0])
    assert state(db) == before[0], f"{args} changed the database"
    assert state(file) == before[1], f"{args} changed {file}"
    assert not (tmp / "new.sqlite").exists(), f"{args} created a database"
    return lines[0]
