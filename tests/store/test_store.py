"""The store on SQLite and on the PostgreSQL at 127.0.0.1:5432 (skipped with the reason when absent)."""

from __future__ import annotations

import datetime as dt
import os
import uuid

import pytest
import sqlalchemy as sa
from sqlalchemy import inspect

from alembic.script import ScriptDirectory

from augnet.store import make_engine, migrate, open_store
from augnet.store.db import alembic_config
from augnet.store import queries as q
from augnet.store.models import AlarmState, Base, Role, Severity

PG_ADMIN_URL = os.environ.get("AUGNET_TEST_PG", "postgresql://postgres@127.0.0.1:5432/test")


def _postgres_url():
    """A fresh database on the local PostgreSQL for this test run, dropped afterwards."""
    try:
        admin = make_engine(PG_ADMIN_URL).execution_options(isolation_level="AUTOCOMMIT")
        with admin.connect() as c:
            name = f"augnet_test_{uuid.uuid4().hex[:8]}"
            c.execute(sa.text(f'CREATE DATABASE "{name}"'))
    except Exception as exc:  # any connection failure means: no server to test against
        pytest.skip(f"PostgreSQL not reachable at {PG_ADMIN_URL}: {exc.__class__.__name__}")
    url = PG_ADMIN_URL.rsplit("/", 1)[0] + "/" + name
    return url, admin, name


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def store(request, tmp_path):
    if request.param == "sqlite":
        yield open_store(f"sqlite:///{tmp_path / 'augnet.sqlite'}")
        return
    url, admin, name = _postgres_url()
    factory = open_store(url)
    yield factory
    factory.kw["bind"].dispose()
    with admin.connect() as c:
        c.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))


def test_migrations_create_exactly_the_model_schema(store):
    engine = store.kw["bind"]
    tables = set(inspect(engine).get_table_names()) - {"alembic_version"}
    assert tables == set(Base.metadata.tables)
    for table in Base.metadata.sorted_tables:  # every column too: a model change needs its migration
        assert {c["name"] for c in inspect(engine).get_columns(table.name)} == set(table.columns.keys()), table.name
    migrate(engine)  # idempotent
    head = ScriptDirectory.from_config(alembic_config(engine)).get_current_head()
    with engine.connect() as c:
        assert c.execute(sa.text("select version_num from alembic_version")).scalar() == head


def test_station_changes_are_audited(store):
    with store.begin() as s:
        q.add_station(s, "alice", "STA1", (-2.0e6, 5.0e6, 3.0e6), 101, "STA1")
    with store.begin() as s:
        q.update_station(s, "bob", "STA1", enabled=False)
        with pytest.raises(q.Conflict):
            q.add_station(s, "alice", "STA1", (0, 0, 0), 1, "X")
    with store() as s:
        assert q.get_station(s, "STA1").enabled is False
        log = q.audit_log(s)
        assert [(e.actor, e.action, e.target) for e in log] == [("bob", "station.disable", "STA1"),
                                                                 ("alice", "station.add", "STA1")]
        assert log[0].detail == {"before": {"enabled": True}, "after": {"enabled": False}}
        with pytest.raises(q.NotFound):
            q.get_station(s, "NOPE")


def test_alarm_life_cycle(store):
    with store.begin() as s:
        a = q.raise_alarm(s, "satellite-excluded", "G12", Severity.CRITICAL, "clock step 30 m")
        again = q.raise_alarm(s, "satellite-excluded", "G12", Severity.CRITICAL)
        s.flush()
        assert again.id == a.id  # one open alarm per condition
        alarm_id = a.id
    with store.begin() as s:
        acked = q.acknowledge_alarm(s, "carol", alarm_id)
        assert acked.state is AlarmState.ACKNOWLEDGED and acked.acknowledged_by == "carol"
    with store.begin() as s:
        q.clear_alarm(s, "satellite-excluded", "G12")
    with store() as s:
        assert q.list_alarms(s) == []
        [cleared] = q.list_alarms(s, include_cleared=True)
        assert cleared.state is AlarmState.CLEARED and cleared.cleared_at is not None
        assert q.audit_log(s)[0].action == "alarm.acknowledge"
        with pytest.raises(q.NotFound):
            q.acknowledge_alarm(s, "carol", 9999)


def test_tokens_roles_and_expiry(store):
    with store.begin() as s:
        op = q.add_operator(s, "admin", "dave", "scrypt$14$8$1$c2FsdA==$aGFzaA==", Role.OPERATOR)
        token = q.issue_token(s, op)
        old = q.issue_token(s, op, lifetime=dt.timedelta(seconds=-1))
    with store() as s:
        who = q.operator_for_token(s, token)
        assert who is not None and who.name == "dave"
        assert q.has_role(who, Role.VIEWER) and q.has_role(who, Role.OPERATOR)
        assert not q.has_role(who, Role.ADMIN)
        assert q.operator_for_token(s, old) is None
        assert q.operator_for_token(s, "not-a-token") is None
        # only the hash is stored
        raw = s.execute(sa.text("select token_sha256 from api_tokens")).scalars().all()
        assert token not in raw and len(raw) == 2


def test_quality_history(store):
    t0 = dt.datetime(2026, 11, 21, 12, 0, tzinfo=dt.timezone.utc)
    with store.begin() as s:
        for i in range(10):
            q.record_quality(s, t0 + dt.timedelta(seconds=i), "STA1-STA2", 0.9 + i / 100, 0.004, 14)
            q.record_quality(s, t0 + dt.timedelta(seconds=i), "STA2-STA3", 0.5, None, 12)
    with store() as s:
        rows = q.quality_history(s, "STA1-STA2", since=t0 + dt.timedelta(seconds=5))
        assert [round(r.fixed_fraction, 2) for r in rows] == [0.95, 0.96, 0.97, 0.98, 0.99]


def test_bad_url_names_what_is_expected():
    from augnet.store import StoreError

    with pytest.raises(StoreError, match="expected sqlite"):
        make_engine("mysql://x")


def test_a_mountpoints_correction_bound_is_off_by_default_and_its_change_audited(store):
    with store.begin() as s:
        q.add_mountpoint(s, "alice", "VRS", "vrs", read_groups="trains")
        q.add_mountpoint(s, "alice", "VRS4001", "vrs", correction_bound=True)
    with store.begin() as s:
        q.update_mountpoint(s, "bob", "VRS", correction_bound=True)
    with store() as s:
        assert [(m.name, m.correction_bound) for m in q.list_mountpoints(s)] == [("VRS", True), ("VRS4001", True)]
        log = q.audit_log(s)
        assert (log[0].actor, log[0].action, log[0].detail) == (
            "bob", "mountpoint.edit", {"before": {"correction_bound": False}, "after": {"correction_bound": True}})
        assert log[-1].detail["correction_bound"] is False and log[-2].detail["correction_bound"] is True


def test_the_correction_bound_migration_keeps_existing_mountpoints_off(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'old.sqlite'}")
    migrate(engine, "0002")
    with engine.begin() as c:
        c.execute(sa.text("insert into mountpoints (name, kind, format, read_groups, write_groups, enabled) "
                          "values ('VRS', 'vrs', 'RTCM 3.3', 'trains', '', 1)"))
    migrate(engine)
    with engine.connect() as c:
        assert c.execute(sa.text("select correction_bound from mountpoints")).scalar() in (0, False)
