"""Opening the store: engine, schema migrations (Alembic) and sessions."""

from __future__ import annotations

import os
from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import create_engine, event
from sqlalchemy.engine import Engine, make_url
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


# The store holds password and token hashes: owner read/write only. SQLite gives its -wal, -shm and -journal
# files the database file's own mode (os_unix.c findCreateFileMode, unixOpenSharedMemory), so a database
# file created 0600 keeps them 0600 too; files left by an older, laxer run are narrowed when opened.
PRIVATE_FILE_MODE = 0o600
SQLITE_SIDE_FILES = ("-wal", "-shm", "-journal")


def private_sqlite_file(url: str) -> Path | None:
    """Create the SQLite database file of `url` owner-only (0600) before SQLite does, or narrow an existing
    one and its side files to 0600. Returns its path (None: in memory or a URI filename, nothing to do)."""
    database = make_url(url).database
    if not database or database == ":memory:" or database.startswith("file:"):
        return None
    path = Path(database)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, PRIVATE_FILE_MODE)  # an empty file is an empty database
    try:
        os.fchmod(fd, PRIVATE_FILE_MODE)  # an existing file keeps its mode through O_CREAT
    finally:
        os.close(fd)
    for suffix in SQLITE_SIDE_FILES:
        side = path.with_name(path.name + suffix)
        if side.exists():
            side.chmod(PRIVATE_FILE_MODE)
    return path


def make_engine(url: str = DEFAULT_URL) -> Engine:
    url = normalise_url(url)
    if not url.startswith(("sqlite", "postgresql")):
        raise StoreError(f"database URL {url!r}: expected sqlite:///FILE or postgresql://...")
    engine = create_engine(url, pool_pre_ping=True)
    if engine.dialect.name == "sqlite":
        private_sqlite_file(url)
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
