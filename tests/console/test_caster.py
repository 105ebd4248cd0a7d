"""Caster: mountpoints and users from the store, merged with a real running caster's statistics."""

from __future__ import annotations

import base64
import socket
import time

import pytest

from augnet.store import queries as q
from augnet.store.models import CasterUser
from augwire.passwords import hash_password, verify_password
from ntrip_caster.auth import PUBLIC, User
from ntrip_caster.config import CasterConfig, Limits, MountConfig
from ntrip_caster.embedded import CasterThread

from tests.console.helpers import FAST_HASH, error_fields

TRAIN_PW = "train-secret"
CLIENT_WAIT_S = 5.0


@pytest.fixture
def caster():
    users = {"train1": User("train1", hash_password(TRAIN_PW, **FAST_HASH), frozenset({"trains"}))}
    mounts = (MountConfig("STA1", "source", frozenset({PUBLIC}), frozenset({"stations"})),
              MountConfig("LIVEONLY", "source", frozenset({"trains"}), frozenset({"stations"})),
              MountConfig("NEAR", "nearest", frozenset({"trains"})))
    config = CasterConfig(host="127.0.0.1", port=0, limits=Limits(), users=users, mounts=mounts)
    with CasterThread(config, use_uvloop=False) as ct:
        yield ct


def _gga(lat_deg: float, lon_deg: float) -> bytes:
    body = (f"GPGGA,020000.00,{int(lat_deg):02d}{(lat_deg % 1) * 60:07.4f},N,"
            f"{int(lon_deg):03d}{(lon_deg % 1) * 60:07.4f},E,1,10,1.0,20.0,M,0.0,M,,")
    checksum = 0
    for ch in body.encode():
        checksum ^= ch
    return f"${body}*{checksum:02X}\r\n".encode()


def _connect_client(port: int, mount: str, user: str, password: str) -> socket.socket:
    """An NTRIP 2.0 client that reports its position with one GGA sentence."""
    s = socket.create_connection(("127.0.0.1", port), timeout=5)
    auth = base64.b64encode(f"{user}:{password}".encode()).decode()
    s.sendall((f"GET /{mount} HTTP/1.1\r\nHost: 127.0.0.1\r\nNtrip-Version: Ntrip/2.0\r\n"
               f"User-Agent: NTRIP console-test/1.0\r\nAuthorization: Basic {auth}\r\n\r\n").encode())
    head = s.recv(4096)
    assert head.startswith(b"HTTP/1.1 200"), head
    s.sendall(_gga(30.0, 114.5))
    return s


def test_caster_not_running_here(sqlite_console):
    c = sqlite_console
    assert c.client.get("/api/caster", headers=c.as_("vera")).json()["running"] is False
    assert c.client.get("/api/caster/clients", headers=c.as_("vera")).json() == []


def test_mountpoints_clients_users_from_store_and_running_caster(console, caster):
    c = console
    c.live.caster_snapshot = caster.snapshot
    with c.sessions.begin() as s:
        q.add_mountpoint(s, "fixture", "STA1", "source", read_groups="*", write_groups="stations")
        q.add_mountpoint(s, "fixture", "NEAR", "nearest", read_groups="trains")
        q.add_mountpoint(s, "fixture", "STOREONLY", "vrs", read_groups="trains")
        q.add_caster_user(s, "fixture", "train1", hash_password(TRAIN_PW, **FAST_HASH), "trains")
        q.add_caster_user(s, "fixture", "train2", hash_password(TRAIN_PW, **FAST_HASH), "trains")
    sock = _connect_client(caster.port, "NEAR", "train1", TRAIN_PW)
    try:
        deadline = time.monotonic() + CLIENT_WAIT_S
        while not any(x["last_position"] for x in caster.snapshot()["clients"]) and time.monotonic() < deadline:
            time.sleep(0.02)
        summary = c.client.get("/api/caster", headers=c.as_("vera")).json()
        assert summary["running"] is True and summary["port"] == caster.port
        assert summary["clients_now"] == 1 and summary["mountpoints_live"] == 3

        mounts = {m["name"]: m for m in c.client.get("/api/caster/mountpoints", headers=c.as_("vera")).json()}
        assert list(mounts) == ["NEAR", "STA1", "STOREONLY", "LIVEONLY"]
        assert mounts["NEAR"]["in_store"] and mounts["NEAR"]["stats"]["clients"] == 1
        assert mounts["STA1"]["stats"]["live"] is False  # no station publishing
        assert mounts["STOREONLY"]["stats"] is None
        assert mounts["LIVEONLY"]["in_store"] is False and mounts["LIVEONLY"]["read_groups"] is None

        clients = c.client.get("/api/caster/clients", headers=c.as_("vera")).json()
        assert len(clients) == 1
        assert clients[0]["user"] == "train1" and clients[0]["mount"] == "NEAR" and clients[0]["version"] == 2
        assert clients[0]["last_position"][0] == pytest.approx(30.0)

        users = c.client.get("/api/caster/users", headers=c.as_("vera")).json()
        assert users == [{"name": "train1", "groups": "trains", "enabled": True, "connected_clients": 1},
                         {"name": "train2", "groups": "trains", "enabled": True, "connected_clients": 0}]
        assert all("password" not in str(u) for u in users)
    finally:
        sock.close()


def test_caster_snapshot_failure_is_served_as_not_running(sqlite_console):
    c = sqlite_console

    def broken():
        raise ConnectionError("caster loop stopped")

    c.live.caster_snapshot = broken
    assert c.client.get("/api/caster", headers=c.as_("vera")).json()["running"] is False
    assert c.client.get("/api/caster/mountpoints", headers=c.as_("vera")).status_code == 200


def test_manage_caster_users_admin_only_audited(console):
    c = console
    changes = []
    c.live.on_caster_change = lambda kind, name, change: changes.append((kind, name, change["action"]))
    body = {"name": "train7", "password": "train7-secret", "groups": "trains"}
    assert c.client.post("/api/caster/users", json=body, headers=c.as_("otto")).status_code == 403
    r = c.client.post("/api/caster/users", json=body, headers=c.as_("ada"))
    assert r.status_code == 201, r.text
    assert r.json() == {"name": "train7", "groups": "trains", "enabled": True, "connected_clients": 0}
    assert c.client.post("/api/caster/users", json=body, headers=c.as_("ada")).status_code == 409
    with c.sessions() as s:
        stored = q.get_caster_user(s, "train7").password_hash
        assert stored.startswith("scrypt$") and verify_password("train7-secret", stored)
    r = c.client.patch("/api/caster/users/train7", json={"enabled": False, "password": "new-secret-7"},
                       headers=c.as_("ada"))
    assert r.status_code == 200 and r.json()["enabled"] is False
    with c.sessions() as s:
        assert verify_password("new-secret-7", q.get_caster_user(s, "train7").password_hash)
    assert c.client.delete("/api/caster/users/train7", headers=c.as_("ada")).status_code == 204
    assert c.client.delete("/api/caster/users/train7", headers=c.as_("ada")).status_code == 404
    with c.sessions() as s:
        assert s.query(CasterUser).count() == 0
        actions = [(e.actor, e.action, e.target) for e in q.audit_log(s, 3)]
    assert actions == [("ada", "caster_user.delete", "train7"), ("ada", "caster_user.edit", "train7"),
                       ("ada", "caster_user.add", "train7")]
    assert changes == [("user", "train7", "add"), ("user", "train7", "edit"), ("user", "train7", "delete")]


@pytest.mark.parametrize("body, field", [({"name": "t", "password": "short"}, "password"),
                                         ({"name": "a b", "password": "long-enough"}, "name"),
                                         ({"name": "t", "password": "long-enough", "groups": "x y"}, "groups"),
                                         ({"password": "long-enough"}, "name")])
def test_caster_user_invalid_body_422(sqlite_console, body, field):
    r = sqlite_console.client.post("/api/caster/users", json=body, headers=sqlite_console.as_("ada"))
    assert field in error_fields(r)


def test_manage_mountpoints(console):
    c = console
    r = c.client.post("/api/caster/mountpoints", json={"name": "VRS", "kind": "vrs", "read_groups": "trains"},
                      headers=c.as_("ada"))
    assert r.status_code == 201, r.text
    assert r.json()["format"] == "RTCM 3.3" and r.json()["in_store"] is True
    assert c.client.post("/api/caster/mountpoints", json={"name": "VRS", "kind": "vrs"},
                         headers=c.as_("ada")).status_code == 409
    r = c.client.patch("/api/caster/mountpoints/VRS", json={"enabled": False}, headers=c.as_("ada"))
    assert r.status_code == 200 and r.json()["enabled"] is False
    assert c.client.patch("/api/caster/mountpoints/NOPE", json={"enabled": False},
                          headers=c.as_("ada")).status_code == 404
    assert "kind" in error_fields(c.client.post("/api/caster/mountpoints", json={"name": "X", "kind": "relay"},
                                                headers=c.as_("ada")))
    assert "kind" in error_fields(c.client.patch("/api/caster/mountpoints/VRS", json={},
                                                 headers=c.as_("ada")))
    with c.sessions() as s:
        assert [e.action for e in q.audit_log(s, 2)] == ["mountpoint.edit", "mountpoint.add"]
