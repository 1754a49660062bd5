"""Opening a database: engine, SQLite pragmas, schema version check and Alembic upgrade.

Any SQLAlchemy URL works; only `_configure_sqlite` is SQLite-specific and it is attached only for
the SQLite dialect. The schema is owned by the Alembic migrations in `db/migrations`.

Alembic is imported only to migrate (or refuse) a database whose schema is not `SCHEMA_HEAD`:
opening a current one reads `alembic_version` with SQLAlchemy alone (a command that only reads,
`campaign status`, starts without Alembic's import and its reading of every migration file).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Connection, Engine, create_engine, event, inspect, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError, DBAPIError, NoSuchModuleError
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.url import shown_url
from gyrostand.db.wal import checkpoint_at_exit

if TYPE_CHECKING:
    from alembic.config import Config

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
# The latest migration's revision, the schema this code reads and writes: a constant so that
# opening a current database needs no Alembic (tests/db/test_session.py checks that it is the
# head of MIGRATIONS_DIR; a new migration changes it).
SCHEMA_HEAD = "0023"
VERSION_TABLE = "alembic_version"  # Alembic's own, one row per head
BUSY_TIMEOUT_MS = 10_000
IMMEDIATE = "gyrostand_begin_immediate"  # execution option: SQLite write transactions
MIGRATION_LOCK = 0x67796D6967  # PostgreSQL advisory lock key of migrations ("gymig")


def writer(sessions: sessionmaker[Session]) -> sessionmaker[Session]:
    """The same database's sessions for transactions that write: on SQLite they BEGIN IMMEDIATE,
    so processes writing one file at once (two stands, one lab file) queue instead of failing.
    Readers keep deferred transactions and never hold up a writer (WAL)."""
    engine = sessions.kw["bind"]
    return sessionmaker(engine.execution_options(**{IMMEDIATE: True}), expire_on_commit=False)


class DatabaseVersionError(Exception):
    """The database's schema is not the one this code uses and cannot (or may not) be upgraded."""


class DatabaseBehind(DatabaseVersionError):
    """The database is empty or its schema older than the code's, and was not to be upgraded.
    `current`: its schema revisions (none: empty)."""

    def __init__(self, message: str, current: tuple[str, ...]) -> None:
        super().__init__(message)
        self.current = current


class DatabaseUnusable(Exception):
    """The database cannot be opened or written. `bad_input`: what was given is no database
    gyrostand can use (a folder, a file that is not SQLite or is damaged, a URL that does not
    parse or names an unknown dialect); otherwise the environment is at fault (permissions, a
    read-only or full disk, a missing driver, a server that does not answer)."""

    def __init__(self, message: str, *, bad_input: bool) -> None:
        super().__init__(message)
        self.bad_input = bad_input


_NOT_A_DATABASE = ("SQLITE_NOTADB", "SQLITE_CORRUPT")  # sqlite3 error names (and extended)


POSTGRES_DRIVER = (
    "; gyrostand's PostgreSQL driver is psycopg: pip install 'gyrostand[postgres]' and give a "
    "postgresql+psycopg:// URL"
)


def unusable(exc: DBAPIError, where: str | None = None) -> DatabaseUnusable:
    """What a driver's error says about the database `where` (its file or URL): a file that is
    not a SQLite database or is damaged is bad input; anything else (a read-only folder, a full
    disk, a lock held too long, a server that does not answer) the environment."""
    name = str(getattr(exc.orig, "sqlite_errorname", ""))
    reason = str(exc.orig).strip() or type(exc.orig).__name__
    if name.startswith(_NOT_A_DATABASE):
        what = where or "the database"
        return DatabaseUnusable(
            f"{what} is not a SQLite database or is damaged ({reason})", bad_input=True
        )
    if name.startswith(("SQLITE_CANTOPEN", "SQLITE_READONLY", "SQLITE_PERM")):
        reason += " (SQLite writes the file and, beside it, its journal: is the folder writable?)"
    what = where if where is not None else "the database failed"
    return DatabaseUnusable(f"{what}: {reason}", bad_input=False)


def sqlite_url(path: Path) -> str:
    """The SQLAlchemy URL of a SQLite file (absolute, so it does not depend on the cwd later)."""
    return f"sqlite:///{Path(path).expanduser().resolve()}"


def database_url(url_or_path: str) -> str:
    """A SQLAlchemy URL as given (`dialect://...`), or the SQLite URL of a file path."""
    return url_or_path if "://" in url_or_path else sqlite_url(Path(url_or_path))


def alembic_config(script_location: Path = MIGRATIONS_DIR) -> Config:
    """An Alembic config without an ini file; env.py takes the connection from its attributes."""
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(script_location))
    return config


def open_database(url: str, *, upgrade: bool = True, create: bool = True) -> sessionmaker[Session]:
    """Open (and create or upgrade) the database at `url`; return its session factory.

    A SQLite file's folder is created if needed. With `create=False` a SQLite file that does not
    exist is refused, and with `upgrade=False` also one that is empty or behind the code; a
    database ahead of the code, or one that has tables but no Alembic version, is always refused
    (DatabaseVersionError). Anything that is no usable database (a folder, a file that is not
    SQLite, an unknown dialect, a server that does not answer) is DatabaseUnusable."""
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError):  # (ValueError: a port that is no number)
        raise DatabaseUnusable(
            f"{shown_url(url)!r} is neither a file path nor a database URL (dialect://...)",
            bad_input=True,
        ) from None
    where = shown_url(url)
    sqlite_file = parsed.get_backend_name() == "sqlite" and parsed.database not in (None, "")
    if sqlite_file and parsed.database != ":memory:" and "mode=memory" not in str(parsed.query):
        path = Path(parsed.database)
        where = str(path)
        if path.is_dir():
            raise DatabaseUnusable(f"{path} is a folder, not a database file", bad_input=True)
        if not (upgrade and create) and not path.exists():
            raise DatabaseVersionError(f"no database at {path}")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DatabaseUnusable(
                f"{path}: cannot make its folder ({exc.strerror or exc})",
                bad_input=False,
            ) from None
    try:
        engine = create_engine(url)
    except NoSuchModuleError:
        raise DatabaseUnusable(
            f"{where}: unknown database dialect {parsed.drivername!r}", bad_input=True
        ) from None
    except ImportError as exc:
        raise DatabaseUnusable(
            f"{where}: the database driver for {parsed.drivername} is not installed ({exc})"
            + (POSTGRES_DRIVER if parsed.get_backend_name() == "postgresql" else ""),
            bad_input=False,
        ) from None
    if engine.dialect.name == "sqlite":
        _configure_sqlite(engine)
    try:
        migrate(engine, upgrade=upgrade)
        if engine.dialect.name == "sqlite":
            _enable_wal(engine)
            checkpoint_at_exit(engine)
    except DBAPIError as exc:
        engine.dispose()
        problem = unusable(exc, where)
        if f'database "{parsed.database}" does not exist' in str(exc.orig):  # PostgreSQL's
            problem = DatabaseUnusable(
                f"{problem}; gyrostand makes its tables, not the database: create it first "
                f"(createdb {parsed.database}, as a role allowed to)",
                bad_input=False,
            )
        raise problem from None
    except BaseException:
        engine.dispose()
        raise
    return sessionmaker(engine, expire_on_commit=False)


def _configure_sqlite(engine: Engine) -> None:
    """Per-connection pragmas (foreign keys, busy timeout, synchronous) and real transactions
    (BEGIN emitted by SQLAlchemy).

    pysqlite's legacy mode (Python < 3.12) does not BEGIN before DDL or SELECT; SQLAlchemy's
    documented recipe (dialects/sqlite, "Transactions with SQLite") makes the migrations and an
    import one atomic transaction each."""

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
        cursor.execute("PRAGMA synchronous=FULL")  # a committed observation survives power loss
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(connection: Connection) -> None:
        # A writer takes the write lock at BEGIN and so waits (busy_timeout) for another writer;
        # a deferred BEGIN that later writes gets SQLITE_BUSY at once when another process
        # committed in between (no busy wait for that case: "database is locked").
        immediate = connection.get_execution_options().get(IMMEDIATE, False)
        connection.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")


def _enable_wal(engine: Engine) -> None:
    """Switch the file to WAL (persistent in the file; outside any transaction, hence the raw
    connection). Done after the version check so that a refused file is left byte-identical."""
    raw = engine.raw_connection()
    try:
        raw.driver_connection.execute("PRAGMA journal_mode=WAL")  # type: ignore[union-attr]
    finally:
        raw.close()


def schema_heads(script_location: Path = MIGRATIONS_DIR) -> set[str]:
    """The schema revisions the code writes (one: the latest migration)."""
    from alembic.script import ScriptDirectory

    return set(ScriptDirectory.from_config(alembic_config(script_location)).get_heads())


def migrate(engine: Engine, *, upgrade: bool, script_location: Path = MIGRATIONS_DIR) -> None:
    """Bring the schema to the head revision of `script_location`, or refuse (see open_database)."""
    if script_location == MIGRATIONS_DIR:
        with engine.begin() as connection:  # the common case, a current schema: read only
            if current_revisions(connection) == {SCHEMA_HEAD}:
                return
    from alembic import command
    from alembic.runtime.migration import MigrationContext
    from alembic.script import ScriptDirectory
    from alembic.util import CommandError

    config = alembic_config(script_location)
    script = ScriptDirectory.from_config(config)
    heads = set(script.get_heads())
    with engine.begin() as connection:
        if set(MigrationContext.configure(connection).get_current_heads()) == heads:
            return
    with (
        engine.execution_options(**{IMMEDIATE: True}).connect() as connection,
        _no_cascades(connection),
        connection.begin(),
    ):
        if engine.dialect.name == "postgresql":  # one process migrates at a time (SQLite:
            # BEGIN IMMEDIATE); the lock ends with the transaction
            connection.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": MIGRATION_LOCK})
        current = set(MigrationContext.configure(connection).get_current_heads())
        if current == heads:  # another process migrated while this one waited for the lock
            return
        where = shown_url(engine.url)
        if not current:
            tables = set(inspect(connection).get_table_names()) - {"alembic_version"}
            if tables:
                raise DatabaseVersionError(
                    f"{where} has tables ({', '.join(sorted(tables))}) but no schema version: "
                    "it was not created by gyrostand; refusing to touch it"
                )
        for revision in sorted(current):
            try:
                script.get_revision(revision)
            except CommandError:
                raise DatabaseVersionError(
                    f"{where} has schema version {revision}, newer than this gyrostand "
                    f"(knows up to {', '.join(sorted(heads))}): upgrade gyrostand to open it"
                ) from None
        if not upgrade:
            state = "is empty" if not current else f"has old schema {', '.join(sorted(current))}"
            raise DatabaseBehind(
                f"{where} {state}; schema {', '.join(sorted(heads))} is needed (open it with "
                "upgrade allowed to migrate it)",
                tuple(sorted(current)),
            )
        config.attributes["connection"] = connection
        command.upgrade(config, "heads")
        if engine.dialect.name == "sqlite":
            broken = connection.exec_driver_sql("PRAGMA foreign_key_check").all()
            if broken:
                raise DatabaseVersionError(
                    f"the migration of {where} would leave {len(broken)} rows without the row "
                    f"they refer to (first: {tuple(broken[0])}); nothing was changed"
                )


def current_revisions(connection: Connection) -> set[str]:
    """The database's schema revisions, as Alembic's `MigrationContext.get_current_heads` reads
    them (none: no version table), without importing Alembic."""
    if not inspect(connection).has_table(VERSION_TABLE):
        return set()
    return set(connection.execute(text(f"SELECT version_num FROM {VERSION_TABLE}")).scalars())


@contextmanager
def _no_cascades(connection: Connection) -> Iterator[None]:
    """SQLite: foreign keys off while migrating (outside the transaction, where the pragma
    applies). A migration that alters a table copies it and drops the original, and with foreign
    keys on that DROP would delete every row referring to it (ON DELETE CASCADE); `migrate`
    checks the references itself before it commits."""
    if connection.dialect.name != "sqlite":
        yield
        return
    raw = connection.connection.driver_connection
    raw.execute("PRAGMA foreign_keys=OFF")  # type: ignore[union-attr]
    try:
        yield
    finally:
        raw.execute("PRAGMA foreign_keys=ON")  # type: ignore[union-attr]
