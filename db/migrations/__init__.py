"""Alembic migrations of the gyrostand schema, run programmatically by `db.session.migrate`.

To add a revision after changing `db/models.py` (developers):

    .venv/bin/python -c "from alembic import command; from db.session import *; \
engine = open_database('sqlite:////tmp/head.sqlite').kw['bind']; \
c = alembic_config(); c.attributes['connection'] = engine.connect(); \
command.revision(c, message='what changed', autogenerate=True)"

then review the new file in `versions/` (names `NNNN_*.py`, ruff-formatted).
"""
