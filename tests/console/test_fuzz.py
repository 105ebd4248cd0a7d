"""Any body on any changing route gets an answer, never a server error: random JSON (right and wrong field
names, every JSON type, NaN and huge numbers, unicode) against every POST and PATCH route."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from augnet.console.app import create_app
from augnet.console.geo import to_ecef_m
from augnet.console.live import LiveState
from augnet.store import open_store
from augnet.store import queries as q
from augnet.store.models import Severity

from tests.console.conftest import add_accounts, empty_store

EXAMPLES_PER_ROUTE = 60
ANSWERS = {200, 201, 204, 401, 403, 404, 409, 422, 429}  # 429: the login throttle

FIELDS = ["code", "name", "lat_deg", "lon_deg", "h_m", "rtcm_station_id", "mountpoint", "enabled", "password",
          "role", "groups", "kind", "format", "read_groups", "write_groups", "x"]
scalars = (st.none() | st.booleans() | st.integers(min_value=-(10**30), max_value=10**30)
           | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=80))
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner,
                                                                                           max_size=3), max_leaves=6)
bodies = st.one_of(st.dictionaries(st.sampled_from(FIELDS), values, max_size=8), values)


@pytest.fixture(scope="module",
                params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def fuzz_console(request, tmp_path_factory):
    if request.param == "sqlite":
        sessions = open_store(f"sqlite:///{tmp_path_factory.mktemp('fuzz') / 'fuzz.sqlite'}")
    else:
        sessions = open_store(request.getfixturevalue("postgres_url"))
        empty_store(sessions)
    tokens = add_accounts(sessions)
    with sessions.begin() as s:
        q.add_station(s, "fixture", "STA1", to_ecef_m(30.0, 114.0, 20.0), 101, "STA1")
        q.add_mountpoint(s, "fixture", "VRS", "vrs")
        q.add_caster_user(s, "fixture", "train1", "scrypt$10$8$1$AAAA$AAAA", "trains")
        q.raise_alarm(s, "station-down", "STA2", Severity.WARNING)
    with TestClient(create_app(sessions, LiveState())) as client:
        yield client, {"Authorization": f"Bearer {tokens['ada']}"}
    sessions.kw["bind"].dispose()


ROUTES = [("POST", "/api/auth/login"), ("POST", "/api/operators"), ("PATCH", "/api/operators/vera"),
          ("POST", "/api/stations"), ("PATCH", "/api/stations/STA1"), ("POST", "/api/caster/mountpoints"),
          ("PATCH", "/api/caster/mountpoints/VRS"), ("POST", "/api/caster/users"),
          ("PATCH", "/api/caster/users/train1")]


@pytest.mark.slow
@pytest.mark.parametrize("method, path", ROUTES)
def test_random_bodies_never_crash(fuzz_console, method, path):
    client, admin = fuzz_console

    @settings(max_examples=EXAMPLES_PER_ROUTE, deadline=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
    @given(body=bodies)
    def check(body):
        raw = json.dumps(body, allow_nan=True)  # NaN / Infinity as Python's json writes them
        r = client.request(method, path, content=raw, headers={**admin, "Content-Type": "application/json"})
        assert r.status_code in ANSWERS, (body, r.status_code, r.text)
        r.json() if r.status_code != 204 else None  # every answer is valid JSON

    check()


@pytest.mark.parametrize("path", ["/api/alarms?limit=%00", "/api/quality?since=%FF%FE", "/api/stations/%2e%2e",
                                  "/api/trains/" + "x" * 5000, "/api/alarms/99999999999999999999999",
                                  "/api/alarms/-1", "/api/alarms/2147483648/acknowledge"])
def test_odd_paths_and_queries_answered(fuzz_console, path):
    client, admin = fuzz_console
    r = client.request("POST" if path.endswith("acknowledge") else "GET", path, headers=admin)
    assert r.status_code in ANSWERS, (path, r.status_code, r.text)
