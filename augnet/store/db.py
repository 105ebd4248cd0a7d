"""Opening the store: engine, schema migrations (Alembic) and sessions."""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import create_engine, event
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session, sessionmaker

MIGRATIONS_DIR = Path(__file__).with_name("migrations")
DEFAULT_URL = "sqlite:///augnet.sqlite"


class StoreError(RuntimeError):
    pass


def normalise_url(url: str) -> str:
    """Accept the plain postgresql:// form and use the psycopg 3 driver for it."""
    if url.startswith("postgres://"):
        url = "postgresql://" + url[len("postgres://"):]
    if url.startswith("postgresql://"):
        url = "postgresql+psycopg://" + url[len("postgresql://"):]
    return url


# How long a SQLite connection waits for another's write lock before failing [ms]: the running system
# writes from one thread while the console reads and writes from others.
SQLITE_BUSY_TIMEOUT_MS = 5000


def _sqlite_pragmas(dbapi_conn, _record) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
    # write-ahead log: readers (the console) never wait for the system's writes (a file database only)
    if cur.execute("PRAGMA database_list").fetchone()[2]:
        cur.execute("PRAGMA journal_mode=WAL")
    cur.close()


def make_engine(url: str = DEFAULT_URL) -> Engine:
    url = normalise_url(url)
    if not url.startswith(("sqlite", "postgresql")):
        raise StoreError(f"database URL {url!r}: expected sqlite:///FILE or postgresql://...")
    engine = create_engine(url, pool_pre_ping=True)
    if engine.dialect.name == "sqlite":
        event.listen(engine, "connect", _sqlite_pragmas)
    return engine


def alembic_config(engine: Engine) -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    cfg.attributes["engine"] = engine
    return cfg


def migrate(engine: Engine, revision: str = "head") -> None:
    """Bring the schema up to `revision` (idempotent)."""
    command.upgrade(alembic_config(engine), revision)


def open_store(url: str = DEFAULT_URL) -> sessionmaker[Session]:
    """Engine + migrations + a session factory: the one call services make."""
    engine = make_engine(url)
    migrate(engine)
    return sessionmaker(engine, expire_on_commit=False)
