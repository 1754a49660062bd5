"""Alembic migrations of the gyrostand schema, run programmatically by `db.session.migrate`
(no alembic.ini). To add a revision after changing `db/models.py`:

    from alembic import command
    from gyrostand.db.session import alembic_config, open_database

    engine = open_database("sqlite:////tmp/gyrostand-head.sqlite").kw["bind"]  # at head
    config = alembic_config()
    with engine.connect() as connection:
        config.attributes["connection"] = connection
        command.revision(config, message="what changed", autogenerate=True, rev_id="0002")

then review and ruff-format the new file in `versions/`; released revisions are never edited.
"""
