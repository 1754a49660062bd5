"""The schema on both database back ends (SQLite and the session's PostgreSQL server): the
migrations up to head match the ORM, go down to nothing and up again, and the ORM's
constraints hold."""

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import inspect

from gyrostand.db.models import Base
from gyrostand.db.session import alembic_config, open_database

HEAD = ScriptDirectory.from_config(alembic_config()).get_current_head()


def test_migrations_go_up_down_and_up_again(db_url: str) -> None:
    sessions = open_database(db_url)
    engine = sessions.kw["bind"]
    with engine.connect() as connection:
        context = MigrationContext.configure(connection, opts={"compare_type": True})
        assert context.get_current_heads() == (HEAD,)
        assert compare_metadata(context, Base.metadata) == []
    config = alembic_config()
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.downgrade(config, "base")
    with engine.connect() as connection:
        assert set(inspect(connection).get_table_names()) <= {"alembic_version"}
    engine.dispose()
    engine = open_database(db_url).kw["bind"]
    with engine.connect() as connection:
        assert MigrationContext.configure(connection).get_current_heads() == (HEAD,)
        tables = set(inspect(connection).get_table_names())
    assert {"campaign", "campaign_label", "observation", "analysis_run"} <= tables
    engine.dispose()
