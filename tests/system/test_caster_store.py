"""The operator's word reaches the running caster (issue 19, decision 0180): a caster, the store and the
console app on one event loop (as `augnet up` runs them), real loopback sockets. A change made through the
console's API is seen by NTRIP clients within a second, the revoked user's open session is closed, a new
caster built from the same store keeps the state, and every change is audited exactly once.

The seeding and own-account rules are tested on a bare store (fast); the running system is `slow`."""

from __future__ import annotations

import asyncio
import itertools
import threading
import time
from concurrent.futures import Future

import httpx
import pytest
import uvicorn
from sqlalchemy import func, select

from augnet.bus import InProcessBus
from augnet.bus.config_events import CASTER_CONFIG_SUBJECT, CasterChange, decode_change
from augnet.console.app import create_app
from augnet.console.live import LiveState
from augnet.store import open_store
from augnet.store import queries as q
from augnet.store.models import AuditEntry, CasterUser, Mountpoint, Role
from augnet.system import persistence
from augnet.system.caster_access import CasterAccessSync, caster_tables
from augwire.passwords import hash_password
from ntrip_caster.auth import User
from ntrip_caster.config import CasterConfig, Limits, MountConfig
from ntrip_caster.server import Caster
from tests.ntrip.helpers import FAST, STATION_PW, TRAIN_PW, open_client, open_v2_source, read_all

ADMIN, ADMIN_PW = "ada", "admin-secret"
EFFECT_DEADLINE_S = 10.0  # stops a hang only; the latency itself is read from the sync's own timestamps
APPLY_BOUND_S = 1.0  # issue 19: a change takes effect on the running caster within a second
POLL_S = 0.01
THROTTLE_STEP_S = 4000.0  # > ntrip_caster.throttle.MAX_LOCKOUT_S and FORGET_AFTER_S


def _seed_config() -> CasterConfig:
    users = {"train1": User("train1", hash_password(TRAIN_PW, **FAST), frozenset({"trains"})),
             "station1": User("station1", hash_password(STATION_PW, **FAST), frozenset({"stations"}))}
    mounts = (MountConfig("BASE01", "source", frozenset({"trains"}), frozenset({"stations"}),
                          {"identifier": "Base one", "latitude": 31.0, "longitude": 121.0}),
              MountConfig("BASE02", "source", frozenset({"trains"}), frozenset({"stations"})))
    return CasterConfig(host="127.0.0.1", port=0, limits=Limits(), users=users, mounts=mounts)


def _store(tmp_path):
    return open_store(f"sqlite:///{tmp_path / 'augnet.db'}")


def _audit(sessions, **where) -> list[tuple[str, str, str]]:
    with sessions() as s:
        rows = s.scalars(select(AuditEntry).order_by(AuditEntry.id)).all()
        return [(e.actor, e.action, e.target) for e in rows
                if all(getattr(e, k) == v for k, v in where.items())]


# --- seeding and the run's own accounts (bare store) ------------------------------------------------

def test_an_empty_store_is_seeded_once_under_the_system_actor(tmp_path):
    sessions = _store(tmp_path)
    cfg = _seed_config()
    with sessions.begin() as s:
        assert persistence.seed_caster(s, cfg) is True
    with sessions.begin() as s:
        q.delete_caster_user(s, "ada", "train1")
        q.update_mountpoint(s, "ada", "BASE02", enabled=False)
    with sessions.begin() as s:
        assert persistence.seed_caster(s, cfg) is False  # a restart: the operator's decisions stand
    with sessions.begin() as s:  # even an operator emptying both tables does not bring the seed back
        s.execute(CasterUser.__table__.delete())
        s.execute(Mountpoint.__table__.delete())
        assert persistence.seed_caster(s, cfg) is False
    assert _audit(sessions, actor=persistence.SYSTEM_ACTOR) == [("system", "caster.seed", "caster")]


def test_a_store_configured_before_is_not_seeded(tmp_path):
    sessions = _store(tmp_path)
    with sessions.begin() as s:
        q.add_caster_user(s, "ada", "mine", hash_password("pw-mine-1", **FAST), "trains")
    with sessions.begin() as s:
        assert persistence.seed_caster(s, _seed_config()) is False
    with sessions() as s:
        assert [u.name for u in q.list_caster_users(s)] == ["mine"] and q.list_mountpoints(s) == []


def test_the_runs_own_account_keeps_its_password_and_an_operators_change_stands(tmp_path):
    sessions = _store(tmp_path)
    with sessions.begin() as s:
        persistence.seed_caster(s, _seed_config())
    fresh = "fresh-pw-1", hash_password("fresh-pw-1", **FAST)
    with sessions.begin() as s:  # the state file's password still verifies: kept, nothing written
        assert persistence.own_account_password(s, "train1", TRAIN_PW, *fresh) == TRAIN_PW
    with sessions.begin() as s:  # lost (no state file) and only the system ever wrote it: rotated, audited
        assert persistence.own_account_password(s, "train1", None, *fresh) == "fresh-pw-1"
    assert _audit(sessions, action="caster_user.rotate") == [("system", "caster_user.rotate", "train1")]
    with sessions.begin() as s:
        q.update_caster_user(s, "ada", "train1", password_hash=hash_password("operators-pw", **FAST))
        q.delete_caster_user(s, "ada", "station1")
    with sessions.begin() as s:  # re-passworded by an operator: the run does not take it back
        assert persistence.own_account_password(s, "train1", "fresh-pw-1", "x", hash_password("x", **FAST)) is None
        assert persistence.own_account_password(s, "station1", STATION_PW, *fresh) is None  # deleted: stays so
    with sessions() as s:
        assert s.scalar(select(func.count()).select_from(CasterUser)) == 1


def test_store_tables_as_the_caster_takes_them(tmp_path):
    sessions = _store(tmp_path)
    with sessions.begin() as s:
        persistence.seed_caster(s, _seed_config())
        q.update_caster_user(s, "ada", "station1", enabled=False)
        q.update_mountpoint(s, "ada", "BASE02", enabled=False, format="RTCM 3.2")
        q.add_mountpoint(s, "ada", "ODD", "relay")  # a kind the caster does not have: left out
    described = {m.name: m for m in _seed_config().mounts}
    with sessions() as s:
        users, mounts = caster_tables(s, described)
    assert set(users) == {"train1"} and users["train1"].groups == frozenset({"trains"})
    by_name = {m.name: m for m in mounts}
    assert set(by_name) == {"BASE01", "BASE02"}
    assert by_name["BASE01"].str_fields["identifier"] == "Base one" and by_name["BASE01"].enabled
    assert by_name["BASE02"].enabled is False and by_name["BASE02"].str_record().format == "RTCM 3.2"
    assert by_name["BASE01"].read == frozenset({"trains"}) and by_name["BASE01"].write == frozenset({"stations"})


def test_change_events_carry_no_values_and_bad_ones_are_refused():
    c = CasterChange("user", "train1", "edit")
    assert decode_change(c.encode()) == c and b"hash" not in c.encode()
    for bad in (b"", b"{", b"[]", b'{"kind":"user","name":"x"}', b'{"kind":"cake","name":"x","action":"a"}',
                b'{"kind":"user","name":1,"action":"a"}', b"x" * 5000, b"\xff\xfe"):
        with pytest.raises(ValueError):
            decode_change(bad)


# --- the running system --------------------------------------------------------------------------------

class RunningSystem:
    """A caster built from the store, its CasterAccessSync on an in-process bus, and the console app served
    by uvicorn, all on one event loop in a background thread (as `augnet up` runs them)."""

    def __init__(self, sessions, reconcile_s: float = 600.0):
        self.sessions = sessions
        self.reconcile_s = reconcile_s
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name="test-system", daemon=True)
        self.described = {m.name: m for m in _seed_config().mounts}

    def call(self, coro, timeout: float = 20.0):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def on_loop(self, fn):
        fut: Future = Future()
        self.loop.call_soon_threadsafe(lambda: fut.set_result(fn()))
        return fut.result(10)

    def __enter__(self):
        self.thread.start()
        self.call(self._start())
        return self

    async def _start(self):
        self.bus = InProcessBus()
        with self.sessions() as s:
            users, mounts = caster_tables(s, self.described)
        cfg = CasterConfig(host="127.0.0.1", port=0, limits=Limits(), users=users, mounts=tuple(mounts))
        self.caster = Caster(cfg)
        # the failure throttle's clock steps past any lockout at each look: the tests' refused polls are
        # wrong-password attempts from one address, which the throttle exists to slow down
        self.caster.clock = itertools.count(0.0, THROTTLE_STEP_S).__next__
        self.caster_port = await self.caster.start()
        self.sync = CasterAccessSync(self.caster, self.sessions, self.described, self.bus,
                                     reconcile_s=self.reconcile_s)
        await self.sync.start()
        app = create_app(self.sessions, LiveState(), bus=self.bus)
        config = uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="off",
                                access_log=False)
        self.server = uvicorn.Server(config)
        self.server.install_signal_handlers = lambda: None  # older uvicorn
        self.serving = asyncio.ensure_future(self.server.serve())
        while not self.server.started:
            if self.serving.done():
                self.serving.result()
            await asyncio.sleep(0.02)
        self.console_port = self.server.servers[0].sockets[0].getsockname()[1]

    async def _stop(self):
        self.server.should_exit = True
        await self.serving
        await self.sync.stop()
        await self.caster.stop()
        await self.bus.close()

    def __exit__(self, *exc):
        try:
            self.call(self._stop())
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(10)

    def snapshot(self):
        return self.on_loop(lambda: self.caster.snapshot())


def _admin_token(sessions) -> str:
    with sessions.begin() as s:
        op = q.add_operator(s, "fixture", ADMIN, hash_password(ADMIN_PW, **FAST), Role.ADMIN)
        return q.issue_token(s, op)


@pytest.fixture
def system(tmp_path):
    sessions = _store(tmp_path)
    with sessions.begin() as s:
        persistence.seed_caster(s, _seed_config())
    token = _admin_token(sessions)
    with RunningSystem(sessions) as rs:
        rs.api = httpx.Client(base_url=f"http://127.0.0.1:{rs.console_port}/api",
                              headers={"Authorization": f"Bearer {token}"}, timeout=10.0)
        rs.token = token
        with rs.api:
            yield rs


def _status(port: int, mount: str, user: str | None, password: str, version: int = 2) -> int:
    sock, head = open_client(port, mount, version=version, user=user, password=password)
    sock.close()
    line = head.split(b"\r\n")[0].split()
    return int(line[1]) if len(line) > 1 and line[1].isdigit() else 200  # v1 "ICY 200 OK"


def _until(pred, what: str) -> float:
    """Poll `pred` until true; the seconds it took from the call (reported, never asserted)."""
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > EFFECT_DEADLINE_S:
            raise AssertionError(f"{what}: not seen within {EFFECT_DEADLINE_S} s")
        time.sleep(POLL_S)
    return time.monotonic() - t0


def _applied_within_bound(rs: RunningSystem, change: CasterChange) -> None:
    """The sync's own record of the event: received, and applied to the caster, within APPLY_BOUND_S."""
    hits = rs.on_loop(lambda: [a for a in rs.sync.applied if a.change == change])
    assert hits, f"{change} not applied by an event (reconcile is 600 s here)"
    assert hits[-1].applied_at - hits[-1].received_at < APPLY_BOUND_S


def _open_stream(rs, mount="BASE01", user="train1", password=TRAIN_PW):
    sock, head = open_client(rs.caster_port, mount, version=2, user=user, password=password)
    assert head.startswith(b"HTTP/1.1 200"), head
    return sock


@pytest.mark.slow
def test_console_changes_reach_the_running_caster_within_a_second(system):
    rs = system
    port = rs.caster_port
    src = open_v2_source(port, "BASE01")
    try:
        _until(lambda: rs.snapshot()["mounts"]["BASE01"]["live"], "station source")
        seen: dict[str, float] = {}

        # a user created in the console logs in
        assert _status(port, "BASE01", "train7", "train7-secret") == 401
        r = rs.api.post("/caster/users", json={"name": "train7", "password": "train7-secret", "groups": "trains"})
        assert r.status_code == 201, r.text
        seen["add user"] = _until(lambda: _status(port, "BASE01", "train7", "train7-secret") == 200, "new user")
        _applied_within_bound(rs, CasterChange("user", "train7", "add"))

        # re-password: the open session is closed, the old password refused, the new one accepted
        stream = _open_stream(rs, user="train7", password="train7-secret")
        r = rs.api.patch("/caster/users/train7", json={"password": "train7-new-pw"})
        assert r.status_code == 200, r.text
        assert read_all(stream, timeout=EFFECT_DEADLINE_S).endswith(b"0\r\n\r\n")  # closed by the caster
        stream.close()
        seen["re-password"] = _until(lambda: _status(port, "BASE01", "train7", "train7-secret") == 401, "old pw")
        assert _status(port, "BASE01", "train7", "train7-new-pw") == 200
        _applied_within_bound(rs, CasterChange("user", "train7", "edit"))

        # disable: session closed, refused; enable again: accepted
        stream = _open_stream(rs, user="train7", password="train7-new-pw")
        assert rs.api.patch("/caster/users/train7", json={"enabled": False}).status_code == 200
        assert read_all(stream, timeout=EFFECT_DEADLINE_S).endswith(b"0\r\n\r\n")
        stream.close()
        seen["disable user"] = _until(lambda: _status(port, "BASE01", "train7", "train7-new-pw") == 401,
                                      "disabled user")
        assert rs.api.patch("/caster/users/train7", json={"enabled": True}).status_code == 200
        _until(lambda: _status(port, "BASE01", "train7", "train7-new-pw") == 200, "enabled again")

        # delete (revoke): session closed, refused
        stream = _open_stream(rs, user="train7", password="train7-new-pw")
        assert rs.api.delete("/caster/users/train7").status_code == 204
        assert read_all(stream, timeout=EFFECT_DEADLINE_S).endswith(b"0\r\n\r\n")
        stream.close()
        seen["delete user"] = _until(lambda: _status(port, "BASE01", "train7", "train7-new-pw") == 401, "deleted")
        _applied_within_bound(rs, CasterChange("user", "train7", "delete"))

        # disable a mountpoint: its reader is closed, it leaves the sourcetable and is not served
        reader = _open_stream(rs)
        assert rs.api.patch("/caster/mountpoints/BASE01", json={"enabled": False}).status_code == 200
        assert read_all(reader, timeout=EFFECT_DEADLINE_S).endswith(b"0\r\n\r\n")
        reader.close()
        seen["disable mountpoint"] = _until(lambda: _status(port, "BASE01", "train1", TRAIN_PW) == 404,
                                            "disabled mountpoint")
        table, head = open_client(port, "", version=1, user=None)
        assert b"BASE01" not in head + read_all(table)
        table.close()
        _applied_within_bound(rs, CasterChange("mountpoint", "BASE01", "edit"))
        snap = rs.snapshot()
        assert snap["counters"]["drop_revoked"] == 3 and snap["counters"]["drop_mount_disabled"] == 1
        print("console change -> seen by an NTRIP client [s]:", {k: round(v, 3) for k, v in seen.items()})
    finally:
        src.close()

    # every change audited exactly once, by the operator; applying them wrote nothing
    assert _audit(rs.sessions, actor=ADMIN) == [
        (ADMIN, "caster_user.add", "train7"), (ADMIN, "caster_user.edit", "train7"),
        (ADMIN, "caster_user.edit", "train7"), (ADMIN, "caster_user.edit", "train7"),
        (ADMIN, "caster_user.delete", "train7"), (ADMIN, "mountpoint.edit", "BASE01")]
    assert _audit(rs.sessions, actor=persistence.SYSTEM_ACTOR) == [("system", "caster.seed", "caster")]


@pytest.mark.slow
def test_a_restarted_caster_keeps_the_stores_state(tmp_path):
    sessions = _store(tmp_path)
    with sessions.begin() as s:
        persistence.seed_caster(s, _seed_config())
    token = _admin_token(sessions)
    with RunningSystem(sessions) as rs:
        with httpx.Client(base_url=f"http://127.0.0.1:{rs.console_port}/api",
                          headers={"Authorization": f"Bearer {token}"}, timeout=10.0) as api:
            assert api.delete("/caster/users/train1").status_code == 204
            assert api.post("/caster/users", json={"name": "train9", "password": "train9-secret",
                                                   "groups": "trains"}).status_code == 201
            assert api.patch("/caster/mountpoints/BASE02", json={"enabled": False}).status_code == 200
    with sessions.begin() as s:  # the next start seeds nothing: the deleted user does not come back
        assert persistence.seed_caster(s, _seed_config()) is False
    with RunningSystem(sessions) as rs:
        src1, src2 = open_v2_source(rs.caster_port, "BASE01"), open_v2_source(rs.caster_port, "BASE02")
        try:
            _until(lambda: rs.snapshot()["mounts"]["BASE01"]["live"], "source")
            assert _status(rs.caster_port, "BASE01", "train1", TRAIN_PW) == 401
            assert _status(rs.caster_port, "BASE01", "train9", "train9-secret") == 200
            assert _status(rs.caster_port, "BASE02", "train9", "train9-secret") == 404
            assert rs.snapshot()["mounts"]["BASE02"]["enabled"] is False
        finally:
            src1.close()
            src2.close()
    assert len(_audit(sessions, action="caster_user.delete")) == 1
    assert _audit(sessions, actor=persistence.SYSTEM_ACTOR) == [("system", "caster.seed", "caster")]


@pytest.mark.slow
def test_a_missed_event_is_caught_up_by_the_reconcile(tmp_path):
    sessions = _store(tmp_path)
    with sessions.begin() as s:
        persistence.seed_caster(s, _seed_config())
    with RunningSystem(sessions, reconcile_s=0.2) as rs:
        src = open_v2_source(rs.caster_port, "BASE01")
        try:
            _until(lambda: rs.snapshot()["mounts"]["BASE01"]["live"], "source")
            stream = _open_stream(rs)
            with sessions.begin() as s:  # another console wrote the store, and its event was lost
                q.update_caster_user(s, "ada", "train1", enabled=False)
            assert read_all(stream, timeout=EFFECT_DEADLINE_S).endswith(b"0\r\n\r\n")
            stream.close()
            assert _status(rs.caster_port, "BASE01", "train1", TRAIN_PW) == 401
            assert rs.on_loop(lambda: rs.sync.events) == 0
            # garbage on the subject is counted and ignored, the sync keeps running
            rs.call(rs.bus.publish(CASTER_CONFIG_SUBJECT, b"not an event"))
            _until(lambda: rs.on_loop(lambda: rs.sync.bad_events) == 1, "bad event counted")
            with sessions.begin() as s:
                q.update_caster_user(s, "ada", "train1", enabled=True)
            _until(lambda: _status(rs.caster_port, "BASE01", "train1", TRAIN_PW) == 200, "re-enabled")
        finally:
            src.close()
