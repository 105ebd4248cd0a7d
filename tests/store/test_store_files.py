"""The SQLite store's files are owner-only (0600): they hold operator password and token hashes."""

from __future__ import annotations

import os
import stat

import pytest

from augnet.store import open_store
from augnet.store import queries as q
from augnet.store.db import private_sqlite_file
from augnet.store.models import Role


@pytest.fixture
def lax_umask():
    old = os.umask(0o022)  # the usual default: files 0644, readable by every local user
    yield
    os.umask(old)


def _modes(directory) -> dict[str, int]:
    return {p.name: stat.S_IMODE(p.stat().st_mode) for p in directory.iterdir()}


def test_a_new_store_and_its_wal_and_shm_are_0600(tmp_path, lax_umask):
    sessions = open_store(f"sqlite:///{tmp_path / 'augnet.db'}")
    with sessions.begin() as s:  # a write: SQLite now has its -wal and -shm files open
        q.add_operator(s, "test", "ada", "scrypt$hash", Role.ADMIN)
        modes = _modes(tmp_path)
    assert set(modes) == {"augnet.db", "augnet.db-wal", "augnet.db-shm"}, modes
    assert set(modes.values()) == {0o600}, modes
    sessions.kw["bind"].dispose()


def test_an_existing_world_readable_store_is_narrowed(tmp_path, lax_umask):
    db = tmp_path / "augnet.db"
    sessions = open_store(f"sqlite:///{db}")
    with sessions.begin() as s:
        q.audit(s, "test", "x", "y")
    sessions.kw["bind"].dispose()
    for p in tmp_path.iterdir():
        p.chmod(0o644)  # as an earlier version left them
    (tmp_path / "augnet.db-wal").touch(0o644)
    sessions = open_store(f"sqlite:///{db}")
    assert set(_modes(tmp_path).values()) == {0o600}, _modes(tmp_path)
    sessions.kw["bind"].dispose()


def test_memory_and_uri_databases_are_left_alone(tmp_path):
    assert private_sqlite_file("sqlite://") is None
    assert private_sqlite_file("sqlite:///:memory:") is None
    assert private_sqlite_file("sqlite:///file:x?mode=memory&uri=true") is None
    assert private_sqlite_file(f"sqlite:///{tmp_path / 'a.db'}") == tmp_path / "a.db"
