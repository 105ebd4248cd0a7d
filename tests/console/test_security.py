"""The console as an attacker meets it (issue 19, decision 0170): login brute force throttled and audited,
bodies over the limit refused unread, no submitted secret echoed, security headers on every answer, the
websocket closed to foreign origins, the bootstrap token kept by logout and rotated from the CLI.
Time is a stepped clock (create_app's `clock`), never a sleep."""

from __future__ import annotations

import json
import re
import socket

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect
from typer.testing import CliRunner

import augnet.console.security as security
from augnet.console.app import create_app
from augnet.console.cli import app as console_app
from augnet.console.headers import COMMON_HEADERS
from augnet.console.limits import MAX_BODY_BYTES
from augnet.console.live import LiveState
from augnet.console.routers.page import STATIC_DIR
from augnet.console.server import ConsoleThread
from augnet.console.statefile import read_state, write_private
from augnet.console.throttle import ALARM_FAILURES, ALARM_REFUSALS, FREE_FAILURES, MAX_LOCKOUT_S, backoff_s
from augnet.store import queries as q

from tests.console.conftest import add_accounts
from tests.console.helpers import PASSWORDS

MARKER = "Zq9-MARKER-s3cret-7Xw"  # a password no answer may ever contain
ATTACKER = ("203.0.113.7", 40000)  # TEST-NET-3 (RFC 5737)


class Clock:
    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def stepped(sqlite_sessions):
    """A console on a stepped clock, its accounts, and a client calling from ATTACKER's address."""
    clock = Clock()
    tokens = add_accounts(sqlite_sessions)
    app = create_app(sqlite_sessions, LiveState(), clock=clock)
    with TestClient(app, client=ATTACKER) as client:
        yield client, clock, tokens, sqlite_sessions


@pytest.fixture
def verifications(monkeypatch):
    """How many passwords the login route verified (scrypt runs)."""
    count = [0]
    real = security.verify_password

    def counting(password, stored):
        count[0] += 1
        return real(password, stored)

    monkeypatch.setattr(security, "verify_password", counting)
    return count


def _login(client, name, password, **kw):
    return client.post("/api/auth/login", json={"name": name, "password": password}, **kw)


def _audit(sessions, *actions):
    with sessions() as s:
        return [e for e in reversed(q.audit_log(s, 10_000)) if e.action in actions]


# --- login throttling -----------------------------------------------------------------------------------

def test_brute_force_of_100_wrong_passwords_is_throttled_and_audited(stepped, verifications):
    client, clock, _, sessions = stepped
    answers = [_login(client, "ada", f"{MARKER}-{i}") for i in range(100)]
    codes = [r.status_code for r in answers]
    assert codes == [401] * FREE_FAILURES + [429] * (100 - FREE_FAILURES)
    assert verifications[0] == FREE_FAILURES  # a locked name costs us no scrypt
    assert all(int(r.headers["Retry-After"]) >= 1 for r in answers[FREE_FAILURES:])
    # the right password is refused too while locked: the lock must not tell a guesser when he is right
    right = _login(client, "ada", PASSWORDS["ada"])
    assert right.status_code == 429
    failed = _audit(sessions, "operator.login_failed")
    refused = _audit(sessions, "operator.login_refused")
    assert [(e.actor, e.target, e.detail["address"]) for e in failed] == [("anonymous", "ada", ATTACKER[0])] * 5
    assert [e.detail["failures"] for e in failed] == [1, 2, 3, 4, 5]
    # one entry for the lock's first refusal and one where the alarm was raised, not one per request
    assert [e.detail["refused"] for e in refused] == [1, ALARM_REFUSALS - 1]
    with sessions() as s:
        [alarm] = q.list_alarms(s)
        assert (alarm.kind, alarm.subject, alarm.severity.value) == ("console-login-failures", ATTACKER[0], "warning")
        assert MARKER not in alarm.message
    # after the lock the right password logs in; its entry carries the refusals not yet recorded
    clock.t += int(right.headers["Retry-After"])
    ok = _login(client, "ada", PASSWORDS["ada"])
    assert ok.status_code == 200, ok.text
    login = _audit(sessions, "operator.login")[-1]
    accounted = len(failed) + sum(e.detail["refused"] for e in refused) + login.detail["refused"]
    assert accounted == 101  # 100 wrong passwords + the right one refused while locked: every attempt counted
    for e in _audit(sessions, "operator.login_failed", "operator.login_refused", "operator.login"):
        assert MARKER not in json.dumps(e.detail) + e.target and PASSWORDS["ada"] not in json.dumps(e.detail)
    metrics = client.get("/metrics").text
    assert 'augnet_console_logins_total{outcome="failed"} 5' in metrics
    assert 'augnet_console_logins_total{outcome="refused"} 96' in metrics
    assert 'augnet_console_logins_total{outcome="succeeded"} 1' in metrics


@pytest.mark.slow
def test_a_patient_guesser_waits_exponentially_longer(stepped, verifications):
    """An attacker who honours every Retry-After: the locks double up to MAX_LOCKOUT_S, so 100 guesses
    take most of a day instead of seconds."""
    client, clock, _, _ = stepped
    start, waits = clock.t, []
    for i in range(100):
        r = _login(client, "otto", f"{MARKER}-{i}")
        while r.status_code == 429:
            waits.append(int(r.headers["Retry-After"]))
            clock.t += waits[-1]
            r = _login(client, "otto", f"{MARKER}-{i}")
        assert r.status_code == 401
    assert verifications[0] == 100
    with stepped[3]() as s:  # a guesser who never trips a refusal flood is still an alarm
        assert [a.kind for a in q.list_alarms(s)] == ["console-login-failures"]
        entry = [e for e in q.audit_log(s, 10_000) if e.action == "operator.login_failed"][::-1][ALARM_FAILURES - 1]
        assert entry.detail["failures"] == ALARM_FAILURES
    assert waits[:4] == [1, 2, 4, 8] and max(waits) == MAX_LOCKOUT_S
    assert waits == sorted(waits)
    assert clock.t - start == sum(backoff_s(n) for n in range(FREE_FAILURES, 100)) > 20 * 3600  # 1+2+..+512 s,
    # then 85 locks of 15 min: 21.5 h for 100 guesses at one name
    assert backoff_s(FREE_FAILURES - 1) == 0 and backoff_s(1000) == MAX_LOCKOUT_S


def test_throttled_per_address_and_per_name(stepped):
    client, clock, _, _ = stepped
    # one address spraying many names: its own lock, whatever the name
    for i in range(FREE_FAILURES):
        assert _login(client, f"user{i}", MARKER).status_code == 401
    assert _login(client, "someone-else", MARKER).status_code == 429
    assert _login(client, "vera", PASSWORDS["vera"]).status_code == 429  # from that address, for now
    with TestClient(client.app, client=("198.51.100.1", 1)) as other:
        assert _login(other, "vera", PASSWORDS["vera"]).status_code == 200  # another address is not locked
        # one name guessed from many addresses: the name's lock, whatever the address
        for i in range(FREE_FAILURES):
            with TestClient(client.app, client=(f"198.51.100.{10 + i}", 1)) as c:
                assert _login(c, "otto", MARKER).status_code == 401
        assert _login(other, "otto", PASSWORDS["otto"]).status_code == 429
        clock.t += backoff_s(FREE_FAILURES)
        assert _login(other, "otto", PASSWORDS["otto"]).status_code == 200  # lock over: the owner logs in
        assert _login(other, "otto", MARKER).status_code == 401  # and the success reset the name's count


def test_a_concurrent_burst_verifies_at_most_the_free_failures():
    """The sans-IO core: attempts in flight count against the free failures, so 50 guesses arriving together
    (the route's worker threads) run FREE_FAILURES verifications, the rest wait a second."""
    from augnet.console.throttle import FORGET_AFTER_S, LoginThrottle

    t = LoginThrottle()
    verdicts = [t.admit("203.0.113.9", "ada", 0.0) for _ in range(50)]
    assert [v.retry_after_s for v in verdicts] == [0] * FREE_FAILURES + [1] * (50 - FREE_FAILURES)
    for _ in range(FREE_FAILURES):
        t.failed("203.0.113.9", "ada", 0.0)
    assert t.admit("203.0.113.9", "ada", 0.0).retry_after_s == backoff_s(FREE_FAILURES)
    assert t.admit("203.0.113.9", "ada", 0.0 + backoff_s(FREE_FAILURES)).retry_after_s == 0  # one, after the lock
    assert t.admit("203.0.113.9", "ada", 0.0 + backoff_s(FREE_FAILURES)).retry_after_s == 1  # and only one
    t.failed("203.0.113.9", "ada", 1.0)
    assert t.admit("203.0.113.9", "ada", 1.0 + FORGET_AFTER_S + 1).retry_after_s == 0  # an hour quiet: forgotten
    small = LoginThrottle(max_keys=4)
    for i in range(10):
        small.admit(f"a{i}", f"n{i}", 0.0)
    assert len(small._keys) == 4  # bounded memory under a spray of names and addresses


def test_a_failure_in_verification_does_not_leave_the_name_locked(stepped, monkeypatch):
    client, _, _, _ = stepped

    def broken(*_):
        raise RuntimeError("store down")

    monkeypatch.setattr(security, "verify_password", broken)
    for _ in range(FREE_FAILURES + 2):
        with pytest.raises(RuntimeError):
            _login(client, "vera", PASSWORDS["vera"])
    monkeypatch.undo()
    assert _login(client, "vera", PASSWORDS["vera"]).status_code == 200


# --- request body limit -----------------------------------------------------------------------------------

def test_bodies_over_the_limit_get_413(sqlite_console):
    c = sqlite_console
    pad = MAX_BODY_BYTES  # with the JSON around it, one field this long is over the limit
    big = json.dumps({"name": "ada", "password": MARKER + "x" * pad})
    for method, path, headers in [("POST", "/api/auth/login", {}), ("POST", "/api/operators", c.as_("ada")),
                                  ("PATCH", "/api/stations/STA1", c.as_("ada")),
                                  ("POST", "/api/caster/users", {})]:  # before authentication, too
        r = c.client.request(method, path, content=big, headers={**headers, "Content-Type": "application/json"})
        assert r.status_code == 413, (path, r.status_code)
        assert MARKER not in r.text and r.json()["detail"] == f"request body over {MAX_BODY_BYTES} bytes"
    # chunked, no Content-Length: counted while read, refused once past the limit
    r = c.client.post("/api/auth/login", content=(big[i:i + 4096].encode() for i in range(0, len(big), 4096)),
                      headers={"Content-Type": "application/json"})
    assert r.status_code == 413 and MARKER not in r.text
    # at the limit: read and judged as usual
    body = json.dumps({"name": "ada", "password": "x"})
    at_limit = body[:-1] + " " * (MAX_BODY_BYTES - len(body)) + "}"
    r = c.client.post("/api/auth/login", content=at_limit, headers={"Content-Type": "application/json"})
    assert len(at_limit) == MAX_BODY_BYTES and r.status_code == 401  # read, parsed, a wrong password


@pytest.mark.slow
def test_a_50_mb_password_is_refused_before_it_is_sent(sqlite_sessions):
    """On a real server: a request declaring a 50 MB body gets its 413 after the headers and the first KiB,
    and the connection is closed; the server never waited for (or held) the rest."""
    declared = 50 * 1024 * 1024
    with ConsoleThread(create_app(sqlite_sessions)) as server, \
            socket.create_connection((server.host, server.port), timeout=10) as sock:
        head = (f"POST /api/auth/login HTTP/1.1\r\nHost: {server.host}:{server.port}\r\n"
                f"Content-Type: application/json\r\nContent-Length: {declared}\r\n\r\n").encode()
        sock.sendall(head + b'{"name": "ada", "password": "' + MARKER.encode() + b"x" * 1024)
        answer = b""
        try:
            while chunk := sock.recv(65536):  # until the server closes
                answer += chunk
        except ConnectionResetError:  # closed with our unread bytes in its buffer: a reset, after the answer
            pass
    assert answer.startswith(b"HTTP/1.1 413 "), answer[:200]
    assert MARKER.encode() not in answer and b"x-frame-options: deny" in answer.lower()


# --- no secret echoed ---------------------------------------------------------------------------------------

SECRET_BODIES = [
    {"name": "ada", "password": MARKER}, {"name": "ada", "password": 5, "x": MARKER},
    {"name": MARKER * 4, "password": MARKER}, {"password": MARKER}, {"name": "ada", "password": [MARKER]},
    {"name": "new-op", "password": MARKER[:5], "role": "viewer"}, {"name": "new-op", "password": MARKER, "role": MARKER},
    {"name": "new-op", "password": MARKER + "\x00", "role": "viewer"}, {"password": MARKER * 20},
    {"name": "bad name!", "password": MARKER, "groups": MARKER}, {"enabled": MARKER, "password": MARKER},
    {"token": MARKER}, [MARKER], MARKER,
]
SECRET_ROUTES = [("POST", "/api/auth/login"), ("POST", "/api/operators"), ("PATCH", "/api/operators/vera"),
                 ("POST", "/api/caster/users"), ("PATCH", "/api/caster/users/nobody"),
                 ("PATCH", "/api/caster/users/train1"), ("POST", "/api/stations")]


@pytest.mark.slow
def test_no_4xx_answer_contains_a_submitted_password(sqlite_console):
    c = sqlite_console
    with c.sessions.begin() as s:
        q.add_caster_user(s, "fixture", "train1", "scrypt$10$8$1$AAAA$AAAA", "trains")
    seen = set()
    for method, path in SECRET_ROUTES:
        for who in (None, "vera", "ada"):
            headers = c.as_(who) if who else {}
            for body in SECRET_BODIES:
                r = c.client.request(method, path, json=body, headers=headers)
                seen.add(r.status_code)
                if r.status_code >= 400:
                    assert MARKER[:5] not in r.text, (method, path, who, body, r.text)
            raw = b'{"name": "ada", "password": "' + MARKER.encode() + b'"'  # not JSON: cut short
            r = c.client.request(method, path, content=raw, headers={**headers, "Content-Type": "application/json"})
            assert r.status_code in (401, 403, 422) and MARKER[:5] not in r.text, r.text
    assert {401, 403, 404, 422} <= seen
    # the 422 still names the field and the rule
    r = c.client.post("/api/operators", json={"name": "x1", "password": "short", "role": "viewer"}, headers=c.as_("ada"))
    err = r.json()["detail"][0]
    assert err["loc"] == ["body", "password"] and "input" not in err and err["type"] == "string_too_short"


# --- security headers -----------------------------------------------------------------------------------------

def test_security_headers_on_pages_and_api(sqlite_console):
    c = sqlite_console
    answers = {
        "page": c.client.get("/"), "script": c.client.get("/static/console.js"), "health": c.client.get("/healthz"),
        "metrics": c.client.get("/metrics"), "missing": c.client.get("/no-such-page"),
        "login": _login(c.client, "vera", PASSWORDS["vera"]), "login-401": _login(c.client, "vera", "wrong-pw"),
        "api": c.client.get("/api/trains", headers=c.as_("vera")), "api-401": c.client.get("/api/trains"),
        "api-422": c.client.post("/api/auth/login", json={}),
        "api-413": c.client.post("/api/auth/login", content=b"x" * (MAX_BODY_BYTES + 1)),
        "docs": c.client.get("/docs"),
    }
    assert answers["login"].status_code == 200 and answers["api-413"].status_code == 413
    for what, r in answers.items():
        for name, value in COMMON_HEADERS.items():
            assert r.headers.get(name) == value, (what, name)
        assert "frame-ancestors 'none'" in r.headers["content-security-policy"], what
    page_csp = answers["page"].headers["content-security-policy"]
    assert "'unsafe-inline'" not in page_csp and "script-src 'self';" in page_csp
    assert "connect-src 'self' ws://testserver wss://testserver;" in page_csp
    for what in ("login", "login-401", "api", "api-401", "api-422", "api-413"):
        assert answers[what].headers["cache-control"] == "no-store", what
    assert "no-store" not in answers["page"].headers.get("cache-control", "")
    assert "cdn.jsdelivr.net" in answers["docs"].headers["content-security-policy"]  # Swagger UI's own policy


def test_the_page_needs_no_inline_script_or_style():
    """What the page's CSP forbids, the page does not use."""
    html = (STATIC_DIR / "index.html").read_text()
    assert re.findall(r"<script\b[^>]*>", html) == ['<script src="/static/console.js">']
    assert not re.search(r"<style\b|\sstyle\s*=|\son[a-z]+\s*=|javascript:", html, re.I)
    js = (STATIC_DIR / "console.js").read_text()
    assert not re.search(r"innerHTML|outerHTML|eval\(|new Function|setAttribute\(\s*['\"]style", js)


def test_a_hostile_host_header_stays_out_of_the_policy(sqlite_console):
    r = sqlite_console.client.get("/", headers={"Host": "evil; script-src *"})
    assert "script-src *" not in r.headers["content-security-policy"]


# --- websocket Origin -----------------------------------------------------------------------------------------

def test_websocket_refuses_a_foreign_origin(sqlite_console):
    c = sqlite_console
    url = f"/api/live?token={c.tokens['vera']}"
    for origin in ("http://evil.example", "http://testserver.evil.example", "https://testserver", "null",
                   "http://testserver:8080"):
        with pytest.raises(WebSocketDisconnect) as refused:
            with c.client.websocket_connect(url, headers={"Origin": origin}):
                pass
        assert refused.value.code == 1008, origin
    for headers in ({"Origin": "http://testserver"}, {"Origin": "http://TestServer/"}, {}):  # same origin, none
        with c.client.websocket_connect(url, headers=headers) as ws:
            assert ws.receive_json()["events"][0]["type"] == "snapshot"


def test_websocket_allowed_origins_behind_a_proxy(sqlite_sessions):
    tokens = add_accounts(sqlite_sessions)
    app = create_app(sqlite_sessions, allowed_origins=("https://console.example.org",))
    with TestClient(app) as client:
        with client.websocket_connect(f"/api/live?token={tokens['vera']}",
                                      headers={"Origin": "https://console.example.org"}) as ws:
            assert ws.receive_json()["events"][0]["type"] == "snapshot"


@pytest.mark.slow
def test_websocket_foreign_origin_handshake_is_403_on_a_real_server(sqlite_sessions):
    websockets = pytest.importorskip("websockets.sync.client")
    from websockets.exceptions import InvalidStatus

    tokens = add_accounts(sqlite_sessions)
    with ConsoleThread(create_app(sqlite_sessions, LiveState())) as server:
        url = f"ws://{server.host}:{server.port}/api/live?token={tokens['vera']}"
        with pytest.raises(InvalidStatus) as refused:
            websockets.connect(url, origin="http://evil.example", open_timeout=10)
        assert refused.value.response.status_code == 403
        with websockets.connect(url, origin=server.url, open_timeout=10) as ws:
            assert json.loads(ws.recv(timeout=10))["events"][0]["type"] == "snapshot"


# --- the bootstrap token ----------------------------------------------------------------------------------------

def test_one_bootstrap_token_per_store_reused_from_the_state_file(sqlite_sessions, tmp_path):
    first = security.bootstrap_admin(sqlite_sessions, "admin")
    assert first.created and first.password
    previous = {"admin_token": first.token, "admin_name": "admin", "admin_password": first.password}
    again = security.bootstrap_admin(sqlite_sessions, "admin", previous=previous)
    assert (again.token, again.password, again.created) == (first.token, first.password, False)  # nothing minted
    assert security.bootstrap_admin(sqlite_sessions, "admin", previous={**previous, "admin_password": "stale-pw"}
                                    ).password is None  # a password that no longer logs in is not carried
    lost = security.bootstrap_admin(sqlite_sessions, "admin", previous={})  # the state file is gone: rotated
    assert lost.token != first.token and lost.password is None
    with sqlite_sessions() as s:
        assert q.operator_for_token(s, first.token) is None and q.is_bootstrap_token(s, lost.token)
        assert [e.detail["reason"] for e in q.audit_log(s) if e.action == "token.rotate"] == ["not in the state file"]
    assert security.bootstrap_admin(sqlite_sessions, "nobody", previous={}) is None


def test_logout_keeps_the_bootstrap_token_and_the_page_trades_it(sqlite_sessions):
    boot = security.ensure_admin(sqlite_sessions, "admin", "admin-password")
    with TestClient(create_app(sqlite_sessions)) as client:
        bearer = {"Authorization": f"Bearer {boot.token}"}
        r = client.post("/api/auth/logout", headers=bearer)
        assert r.status_code == 409 and "--rotate" in r.json()["detail"]
        assert client.get("/api/auth/me", headers=bearer).status_code == 200
        # what the page does with #token=...: a session token of its own, then logout revokes only that
        traded = client.post("/api/auth/session", headers=bearer)
        assert traded.status_code == 200 and traded.headers["cache-control"] == "no-store"
        own = {"Authorization": f"Bearer {traded.json()['token']}"}
        assert traded.json()["expires_at"] is not None
        assert client.post("/api/auth/logout", headers=own).status_code == 204
        assert client.get("/api/auth/me", headers=own).status_code == 401
        assert client.get("/api/auth/me", headers=bearer).status_code == 200
        # a session token does not renew itself
        again = client.post("/api/auth/session", headers={"Authorization": f"Bearer {traded.json()['token']}"})
        assert again.status_code in (401, 409)
        fresh = {"Authorization": f"Bearer {client.post('/api/auth/session', headers=bearer).json()['token']}"}
        assert client.post("/api/auth/session", headers=fresh).status_code == 409
    js = (STATIC_DIR / "console.js").read_text()
    assert '"/api/auth/session"' in js


def test_cli_rotates_the_bootstrap_token_into_the_state_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    db = f"sqlite:///{tmp_path / 'store.db'}"
    from augnet.store import open_store

    sessions = open_store(db)
    boot = security.ensure_admin(sessions, "admin", "admin-password")
    state = tmp_path / "augnet-up.json"
    write_private(state, {"console_url": "http://127.0.0.1:8000/", "admin_token": boot.token, "pid": 1})
    r = CliRunner().invoke(console_app, ["token", "--rotate", "--db", db])
    assert r.exit_code == 0, r.output
    assert "in augnet-up.json" in r.output and boot.token not in r.output  # the secret goes to the file only
    new = read_state(state)
    assert new["admin_token"] != boot.token and new["pid"] == 1 and state.stat().st_mode & 0o777 == 0o600
    with sessions() as s:
        assert q.operator_for_token(s, boot.token) is None
        assert q.is_bootstrap_token(s, new["admin_token"])
    # without a state file it is printed (the operator asked for it); an unknown holder is an error
    state.unlink()
    r = CliRunner().invoke(console_app, ["token", "--rotate", "--db", db])
    assert r.exit_code == 0 and len(r.output.strip()) >= 40
    assert CliRunner().invoke(console_app, ["token", "--rotate", "nobody", "--db", db]).exit_code == 1
    assert CliRunner().invoke(console_app, ["token", "--db", db]).exit_code == 2  # no name, no --rotate
    sessions.kw["bind"].dispose()


def test_state_files_are_written_0600_from_the_start(tmp_path):
    import os

    old = os.umask(0)
    try:
        path = tmp_path / "state.json"
        path.write_text("{}")
        path.chmod(0o644)
        write_private(path, {"admin_token": "t"})
        assert path.stat().st_mode & 0o777 == 0o600 and read_state(path) == {"admin_token": "t"}
        fresh = write_private(tmp_path / "new.json", {"a": 1})
        assert fresh.stat().st_mode & 0o777 == 0o600
        assert sorted(p.name for p in tmp_path.iterdir()) == ["new.json", "state.json"]  # no temporary left
    finally:
        os.umask(old)
