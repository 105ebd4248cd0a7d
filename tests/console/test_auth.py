"""Accounts, login, tokens, and the 401 / 403 rules on every route of the OpenAPI document."""

from __future__ import annotations

import datetime as dt
import re

import pytest
from sqlalchemy import select

from augnet.console.security import LOGIN_TOKEN_LIFETIME, ensure_admin, issue_operator_token
from augnet.store import queries as q
from augnet.store.models import ApiToken

from tests.console.helpers import PASSWORDS, error_fields

# Routes anyone may call: the page, liveness, the scrape endpoint, and login itself.
PUBLIC_ROUTES = {("get", "/healthz"), ("get", "/metrics"), ("post", "/api/auth/login")}
# The lowest role each changing route needs (reads need viewer).
OPERATOR_ROUTES = {("post", "/api/alarms/{alarm_id}/acknowledge"), ("post", "/api/stations/{code}/disable"),
                   ("post", "/api/stations/{code}/enable"), ("post", "/api/sections/{section_id}/{direction}/reorder"),
                   ("post", "/api/sections/{section_id}/{direction}/withdraw"), ("post", "/api/sections/admit")}
ADMIN_ROUTES = {("get", "/api/operators"), ("post", "/api/operators"), ("patch", "/api/operators/{name}"),
                ("post", "/api/stations"), ("patch", "/api/stations/{code}"),
                ("post", "/api/caster/mountpoints"), ("patch", "/api/caster/mountpoints/{name}"),
                ("post", "/api/caster/users"), ("patch", "/api/caster/users/{name}"),
                ("delete", "/api/caster/users/{name}")}


def _routes(client):
    paths = client.get("/openapi.json").json()["paths"]
    for path, ops in paths.items():
        for method in ops:
            yield method, path


def _concrete(path: str) -> str:
    return re.sub(r"\{[^}]+\}", "1", path)


def test_openapi_lists_the_console_resources(sqlite_console):
    routes = set(_routes(sqlite_console.client))
    for needed in [("get", "/api/stations"), ("get", "/api/network"), ("get", "/api/trains"),
                   ("get", "/api/alarms"), ("get", "/api/caster/mountpoints"), ("get", "/api/caster/clients"),
                   ("get", "/api/caster/users"), ("get", "/api/quality"), ("get", "/api/audit"),
                   ("get", "/metrics"), ("post", "/api/auth/login")]:
        assert needed in routes
    assert OPERATOR_ROUTES | ADMIN_ROUTES <= routes


def test_every_protected_route_answers_401_without_or_with_a_bad_token(sqlite_console):
    c = sqlite_console.client
    checked = 0
    for method, path in _routes(c):
        if (method, path) in PUBLIC_ROUTES:
            continue
        url = _concrete(path)
        for headers in ({}, {"Authorization": "Bearer not-a-token"}, {"Authorization": "Basic YTpi"}):
            r = c.request(method.upper(), url, headers=headers, json={})
            assert r.status_code == 401, (method, path, headers, r.status_code, r.text)
            assert r.headers["www-authenticate"] == "Bearer"
        checked += 1
    assert checked >= 25


@pytest.mark.parametrize("who, allowed", [("vera", set()), ("otto", OPERATOR_ROUTES),
                                          ("ada", OPERATOR_ROUTES | ADMIN_ROUTES)])
def test_roles_403_below_the_needed_role(sqlite_console, who, allowed):
    c = sqlite_console
    for method, path in OPERATOR_ROUTES | ADMIN_ROUTES:
        r = c.client.request(method.upper(), _concrete(path), headers=c.as_(who), json={})
        if (method, path) in allowed:
            assert r.status_code != 403, (who, method, path, r.text)
        else:
            assert r.status_code == 403, (who, method, path, r.status_code)
            assert "role required" in r.json()["detail"]


def test_viewer_reads_every_get_route(sqlite_console):
    c = sqlite_console
    for method, path in _routes(c.client):
        if method != "get" or (method, path) in ADMIN_ROUTES or "{" in path:
            continue
        r = c.client.get(path, headers=c.as_("vera"))
        assert r.status_code == 200, (path, r.text)


def test_login_issues_a_token_that_works_and_is_audited(console):
    c = console
    r = c.client.post("/api/auth/login", json={"name": "otto", "password": PASSWORDS["otto"]})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["role"] == "operator" and body["token_type"] == "bearer"
    expires = dt.datetime.fromisoformat(body["expires_at"])
    lifetime = expires - dt.datetime.now(dt.timezone.utc)
    assert LOGIN_TOKEN_LIFETIME - dt.timedelta(minutes=1) < lifetime <= LOGIN_TOKEN_LIFETIME
    me = c.client.get("/api/auth/me", headers={"Authorization": f"Bearer {body['token']}"})
    assert me.json() == {"name": "otto", "role": "operator", "enabled": True}
    with c.sessions() as s:
        assert [(e.actor, e.action) for e in q.audit_log(s, 1)] == [("otto", "operator.login")]


@pytest.mark.parametrize("name, password", [("otto", "wrong-password"), ("nobody", "whatever-pw"),
                                            ("OTTO", PASSWORDS["otto"])])
def test_login_wrong_credentials_401(sqlite_console, name, password):
    r = sqlite_console.client.post("/api/auth/login", json={"name": name, "password": password})
    assert r.status_code == 401
    assert r.json()["detail"] == "wrong name or password"


@pytest.mark.parametrize("body, field", [({"password": "x"}, "name"), ({"name": "otto"}, "password"),
                                         ({"name": "", "password": "x"}, "name"),
                                         ({"name": "otto", "password": "x", "role": "admin"}, "role"),
                                         ({"name": 5, "password": "x"}, "name")])
def test_login_invalid_body_422_names_the_field(sqlite_console, body, field):
    r = sqlite_console.client.post("/api/auth/login", json=body)
    assert field in error_fields(r)


def test_login_body_not_json_is_422(sqlite_console):
    r = sqlite_console.client.post("/api/auth/login", content=b"{not json",
                                   headers={"Content-Type": "application/json"})
    assert r.status_code == 422
    assert r.json()["detail"][0]["type"] == "json_invalid"


def test_logout_revokes_the_token(console):
    c = console
    assert c.client.post("/api/auth/logout", headers=c.as_("vera")).status_code == 204
    assert c.client.get("/api/trains", headers=c.as_("vera")).status_code == 401
    assert c.client.get("/api/trains", headers=c.as_("otto")).status_code == 200  # others unaffected
    with c.sessions() as s:
        assert q.audit_log(s, 1)[0].action == "token.revoke"


def test_expired_token_and_disabled_operator_401(console):
    c = console
    with c.sessions.begin() as s:
        for row in s.scalars(select(ApiToken)):
            if row.operator.name == "vera":
                row.expires_at = dt.datetime.now(dt.timezone.utc) - dt.timedelta(seconds=1)
        q.get_operator(s, "otto").enabled = False
    assert c.client.get("/api/alarms", headers=c.as_("vera")).status_code == 401
    assert c.client.get("/api/alarms", headers=c.as_("otto")).status_code == 401
    assert c.client.get("/api/alarms", headers=c.as_("ada")).status_code == 200
    # a disabled operator cannot log in either
    r = c.client.post("/api/auth/login", json={"name": "otto", "password": PASSWORDS["otto"]})
    assert r.status_code == 401


def test_ensure_admin_bootstraps_once(sessions):
    boot = ensure_admin(sessions, "root", "root-password")
    assert boot is not None and boot.name == "root" and boot.password == "root-password"
    assert ensure_admin(sessions, "root2") is None  # operators exist: nothing created
    with sessions() as s:
        op = q.operator_for_token(s, boot.token)
        assert op is not None and op.name == "root" and op.role.value == "admin"
        assert [e.action for e in q.audit_log(s)] == ["token.issue", "operator.add"]
    token = issue_operator_token(sessions, "root")
    with sessions() as s:
        assert q.operator_for_token(s, token).name == "root"
    with pytest.raises(q.NotFound):
        issue_operator_token(sessions, "nobody")


def test_ensure_admin_random_password_logs_in(sqlite_sessions):
    from fastapi.testclient import TestClient

    from augnet.console.app import create_app

    boot = ensure_admin(sqlite_sessions)
    assert len(boot.password) >= 16
    with TestClient(create_app(sqlite_sessions)) as client:
        r = client.post("/api/auth/login", json={"name": "admin", "password": boot.password})
        assert r.status_code == 200 and r.json()["role"] == "admin"
        assert client.get("/api/operators", headers={"Authorization": f"Bearer {boot.token}"}).status_code == 200


def test_nul_characters_are_422_on_every_backend(console):
    c = console
    r = c.client.post("/api/auth/login", json={"name": "ot\x00to", "password": "x"})
    assert "name" in error_fields(r)
    assert "code" in error_fields(c.client.get("/api/stations/A%00B", headers=c.as_("vera")))
    assert "subject" in error_fields(c.client.get("/api/quality", params={"subject": "S\x00"}, headers=c.as_("vera")))


def test_token_cache_trusts_a_token_at_most_its_ttl(console):
    """A change made by another process (here: straight in the store) reaches the console within the TTL."""
    c = console
    cache = c.client.app.state.token_cache
    now = [1000.0]
    cache.clock = lambda: now[0]
    assert c.client.get("/api/alarms", headers=c.as_("vera")).status_code == 200  # verified, remembered
    with c.sessions.begin() as s:
        q.get_operator(s, "vera").enabled = False
    assert c.client.get("/api/alarms", headers=c.as_("vera")).status_code == 200  # still trusted
    now[0] += cache.ttl_s + 0.001
    assert c.client.get("/api/alarms", headers=c.as_("vera")).status_code == 401
