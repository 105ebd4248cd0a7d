"""Console fixtures: a store (SQLite, and PostgreSQL at 127.0.0.1:5432 when reachable), a live state, the app,
and three accounts (viewer, operator, admin) with tokens."""

from __future__ import annotations

import os
import uuid
from dataclasses import dataclass

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from augnet.console.app import create_app
from augnet.console.live import LiveState
from augnet.store import make_engine, open_store
from augnet.store import queries as q
from augnet.store.models import Base
from augwire.passwords import hash_password

from tests.console.helpers import FAST_HASH, PASSWORDS, ROLES

PG_ADMIN_URL = os.environ.get("AUGNET_TEST_PG", "postgresql://postgres@127.0.0.1:5432/test")


@pytest.fixture(scope="session")
def postgres_url():
    """One fresh database on the local PostgreSQL for the session (dropped at the end), or a skip."""
    try:
        admin = make_engine(PG_ADMIN_URL).execution_options(isolation_level="AUTOCOMMIT")
        with admin.connect() as c:
            name = f"augnet_console_{uuid.uuid4().hex[:8]}"
            c.execute(sa.text(f'CREATE DATABASE "{name}"'))
    except Exception as exc:  # any connection failure means: no server to test against
        pytest.skip(f"PostgreSQL not reachable at {PG_ADMIN_URL}: {exc.__class__.__name__}")
    url = PG_ADMIN_URL.rsplit("/", 1)[0] + "/" + name
    yield url
    with admin.connect() as c:
        c.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
    admin.dispose()


def empty_store(sessions) -> None:
    with sessions.begin() as s:
        for table in reversed(Base.metadata.sorted_tables):
            s.execute(table.delete())


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def sessions(request, tmp_path):
    """A migrated, empty store on each backend."""
    if request.param == "sqlite":
        factory = open_store(f"sqlite:///{tmp_path / 'console.sqlite'}")
        yield factory
        factory.kw["bind"].dispose()
        return
    factory = open_store(request.getfixturevalue("postgres_url"))
    empty_store(factory)
    yield factory
    factory.kw["bind"].dispose()


@pytest.fixture
def sqlite_sessions(tmp_path):
    """SQLite only: for tests whose subject is not the database."""
    factory = open_store(f"sqlite:///{tmp_path / 'console.sqlite'}")
    yield factory
    factory.kw["bind"].dispose()


@dataclass
class Console:
    client: TestClient
    sessions: object
    live: LiveState
    tokens: dict[str, str]

    def as_(self, who: str) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.tokens[who]}"}


def add_accounts(sessions) -> dict[str, str]:
    tokens = {}
    with sessions.begin() as s:
        for name, role in ROLES.items():
            op = q.add_operator(s, "fixture", name, hash_password(PASSWORDS[name], **FAST_HASH), role)
            tokens[name] = q.issue_token(s, op)
    return tokens


def make_console(sessions) -> Console:
    live = LiveState()
    tokens = add_accounts(sessions)
    client = TestClient(create_app(sessions, live))
    return Console(client, sessions, live, tokens)


@pytest.fixture
def console(sessions):
    c = make_console(sessions)
    with c.client:
        yield c


@pytest.fixture
def sqlite_console(sqlite_sessions):
    c = make_console(sqlite_sessions)
    with c.client:
        yield c
