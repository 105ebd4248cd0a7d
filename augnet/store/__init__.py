"""The store: SQLAlchemy 2 models, Alembic migrations, and the queries services and console run.

`open_store(url)` migrates the schema and returns a session factory; SQLite (`sqlite:///augnet.sqlite`) by
default, PostgreSQL by URL (`postgresql://user@host/db`).
"""

from augnet.store.db import DEFAULT_URL, StoreError, make_engine, migrate, open_store

__all__ = ["DEFAULT_URL", "StoreError", "make_engine", "migrate", "open_store"]
