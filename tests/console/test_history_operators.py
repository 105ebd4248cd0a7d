"""Quality history, the audit log, and operator accounts."""

from __future__ import annotations

import datetime as dt

import pytest

from augnet.store import queries as q
from augwire.passwords import verify_password

from tests.console.helpers import error_fields

T0 = dt.datetime(2026, 11, 22, 2, 0, tzinfo=dt.timezone.utc)


def test_quality_history_filters(console):
    c = console
    with c.sessions.begin() as s:
        for i in range(6):
            q.record_quality(s, T0 + dt.timedelta(minutes=i), "STA1-STA2", 0.9 + i / 100, 0.012, 20 + i)
            q.record_quality(s, T0 + dt.timedelta(minutes=i), "STA2-STA3", 0.5, None, 18)
    r = c.client.get("/api/quality?subject=STA1-STA2", headers=c.as_("vera"))
    assert r.status_code == 200
    rows = r.json()
    assert [x["satellites"] for x in rows] == [20, 21, 22, 23, 24, 25]
    assert dt.datetime.fromisoformat(rows[0]["at"]) == T0
    assert rows[0]["fixed_fraction"] == pytest.approx(0.9) and rows[0]["residual_rms_m"] == pytest.approx(0.012)
    since = (T0 + dt.timedelta(minutes=4)).isoformat()
    r = c.client.get("/api/quality", params={"since": since, "subject": "STA1-STA2"}, headers=c.as_("vera"))
    assert [x["satellites"] for x in r.json()] == [24, 25]
    r = c.client.get("/api/quality", params={"subject": "STA1-STA2", "limit": 2}, headers=c.as_("vera"))
    assert [x["satellites"] for x in r.json()] == [20, 21]
    assert len(c.client.get("/api/quality", headers=c.as_("vera")).json()) == 12
    naive = c.client.get("/api/quality", params={"since": "2026-11-22T02:05:00", "subject": "STA2-STA3"},
                         headers=c.as_("vera")).json()
    assert len(naive) == 1 and naive[0]["residual_rms_m"] is None  # naive times are UTC


@pytest.mark.parametrize("query, field", [({"since": "yesterday"}, "since"), ({"limit": 0}, "limit"),
                                          ({"limit": 10_001}, "limit"), ({"subject": "S" * 65}, "subject")])
def test_quality_bad_query_422(sqlite_console, query, field):
    r = sqlite_console.client.get("/api/quality", params=query, headers=sqlite_console.as_("vera"))
    assert field in error_fields(r)


def test_audit_log_newest_first(console):
    c = console
    r = c.client.get("/api/audit?limit=2", headers=c.as_("vera"))
    assert r.status_code == 200
    rows = r.json()
    assert [(x["actor"], x["action"], x["target"]) for x in rows] == [("fixture", "operator.add", "ada"),
                                                                      ("fixture", "operator.add", "otto")]
    assert rows[0]["id"] > rows[1]["id"] and rows[0]["detail"] == {"role": "admin"}
    assert "limit" in error_fields(c.client.get("/api/audit?limit=5000", headers=c.as_("vera")))


def test_operator_accounts(console):
    c = console
    names = [o["name"] for o in c.client.get("/api/operators", headers=c.as_("ada")).json()]
    assert names == ["ada", "otto", "vera"]
    r = c.client.post("/api/operators", json={"name": "ivy", "password": "ivy-password", "role": "operator"},
                      headers=c.as_("ada"))
    assert r.status_code == 201 and r.json() == {"name": "ivy", "role": "operator", "enabled": True}
    assert c.client.post("/api/operators", json={"name": "ivy", "password": "ivy-password", "role": "viewer"},
                         headers=c.as_("ada")).status_code == 409
    login = c.client.post("/api/auth/login", json={"name": "ivy", "password": "ivy-password"})
    assert login.status_code == 200
    ivy = {"Authorization": f"Bearer {login.json()['token']}"}
    assert c.client.post("/api/stations/X/disable", headers=ivy).status_code == 404  # operator: allowed, no such
    # demote ivy: her token now has viewer rights
    r = c.client.patch("/api/operators/ivy", json={"role": "viewer"}, headers=c.as_("ada"))
    assert r.json()["role"] == "viewer"
    assert c.client.post("/api/stations/X/disable", headers=ivy).status_code == 403
    # a new password revokes her tokens
    r = c.client.patch("/api/operators/ivy", json={"password": "another-password"}, headers=c.as_("ada"))
    assert r.status_code == 200
    assert c.client.get("/api/trains", headers=ivy).status_code == 401
    with c.sessions() as s:
        assert verify_password("another-password", q.get_operator(s, "ivy").password_hash)
        edits = [e for e in q.audit_log(s) if e.action == "operator.edit"]
        assert [e.detail.get("role") for e in edits] == [None, {"before": "operator", "after": "viewer"}]
        assert edits[0].detail["tokens_revoked"] is True and edits[0].detail["password"] == "changed"
    assert c.client.patch("/api/operators/nobody", json={"enabled": False}, headers=c.as_("ada")).status_code == 404


def test_last_admin_cannot_be_demoted_or_disabled(console):
    c = console
    for body in ({"role": "operator"}, {"enabled": False}):
        r = c.client.patch("/api/operators/ada", json=body, headers=c.as_("ada"))
        assert r.status_code == 409 and "last enabled admin" in r.json()["detail"]
    c.client.patch("/api/operators/otto", json={"role": "admin"}, headers=c.as_("ada"))
    assert c.client.patch("/api/operators/ada", json={"enabled": False}, headers=c.as_("otto")).status_code == 200
    assert c.client.get("/api/operators", headers=c.as_("ada")).status_code == 401  # disabled: tokens revoked


@pytest.mark.parametrize("body, field", [({"name": "x", "password": "short", "role": "viewer"}, "password"),
                                         ({"name": "x", "password": "long-enough", "role": "root"}, "role"),
                                         ({"name": "x y", "password": "long-enough", "role": "viewer"}, "name"),
                                         ({"name": "x", "password": "long-enough"}, "role")])
def test_add_operator_invalid_body_422(sqlite_console, body, field):
    r = sqlite_console.client.post("/api/operators", json=body, headers=sqlite_console.as_("ada"))
    assert field in error_fields(r)


@pytest.mark.parametrize("body, field", [({}, "role"), ({"role": "boss"}, "role"), ({"enabled": "no way"}, "enabled"),
                                         ({"name": "renamed"}, "name")])
def test_edit_operator_invalid_body_422(sqlite_console, body, field):
    r = sqlite_console.client.patch("/api/operators/vera", json=body, headers=sqlite_console.as_("ada"))
    assert field in error_fields(r)
