"""Alembic environment: runs on the connection passed in `config.attributes["connection"]`."""

from alembic import context

from gyrostand.db.models import Base

connection = context.config.attributes["connection"]
context.configure(
    connection=connection,
    target_metadata=Base.metadata,
    render_as_batch=True,  # ALTER on SQLite goes through table copies
    transactional_ddl=True,  # db.session emits BEGIN itself, so SQLite DDL is transactional
    compare_type=True,
)
with context.begin_transaction():
    context.run_migrations()
