"""The caster's user and mountpoint tables replaced while it runs (`Caster.set_users` / `set_mounts`,
decision 0180): new credentials work at once, revoked ones are refused and their open sessions closed,
a disabled mountpoint leaves the sourcetable and its readers are closed."""

from __future__ import annotations

from dataclasses import replace

from augwire.passwords import hash_password
from ntrip_caster.auth import Authenticator, User
from ntrip_caster.config import MountConfig

from .helpers import FAST, TRAIN_PW, open_client, open_v2_source, read_all, wait_for


def _users(caster) -> dict[str, User]:
    return dict(caster.caster.auth.users)


def _mounts(caster) -> list[MountConfig]:
    return [m.cfg for m in caster.caster.mounts.values()]


def _stream_then_eof(sock) -> bytes:
    """What a connected client receives until the caster closes it (fails on a hang: read_all's timeout)."""
    return read_all(sock, timeout=5.0)


def _sourcetable(port: int) -> bytes:
    sock, head = open_client(port, "", user=None)
    body = head + read_all(sock)
    sock.close()
    return body


def test_replace_users_forgets_revoked_credentials_only():
    a = Authenticator({"u1": User("u1", hash_password("p1", **FAST), frozenset({"g"})),
                       "u2": User("u2", hash_password("p2", **FAST), frozenset({"g"}))})
    assert a.check("u1", "p1") == "u1" and a.check("u2", "p2") == "u2"
    users = dict(a.users)
    users["u1"] = User("u1", hash_password("new", **FAST), frozenset({"g"}))
    assert a.replace_users(users) == {"u1"} and a.revision == 1
    assert a.cached_user("u1", "p1") is None and a.check("u1", "p1") is None
    assert a.cached_user("u2", "p2") == "u2"  # untouched user keeps its cached verification
    assert a.check("u1", "new") == "u1"
    assert a.replace_users(dict(a.users)) == set() and a.revision == 1  # same table: nothing revoked
    assert a.replace_users({}) == {"u1", "u2"} and a.cached_user("u2", "p2") is None


def test_check_running_against_a_replaced_hash_is_not_cached():
    old = User("u", hash_password("pw", **FAST), frozenset({"g"}))
    a = Authenticator({"u": old})
    a.users = {"u": User("u", hash_password("other", **FAST), frozenset({"g"}))}  # as if swapped mid-check
    assert a._remember("u", "pw", old.password_hash) is False
    assert a.cached_user("u", "pw") is None


def test_new_user_logs_in_and_revoked_user_is_refused_and_disconnected(caster):
    src = open_v2_source(caster.port, "BASE01")
    try:
        wait_for(lambda: caster.snapshot()["mounts"]["BASE01"]["live"])
        s, head = open_client(caster.port, "BASE01", user="newbie", password="newbie-pw")
        s.close()
        assert b"401" in head.split(b"\r\n")[0]
        users = _users(caster)
        users["newbie"] = User("newbie", hash_password("newbie-pw", **FAST), frozenset({"trains"}))
        caster.call(caster.caster.set_users, users)
        s, head = open_client(caster.port, "BASE01", version=2, user="newbie", password="newbie-pw")
        assert head.startswith(b"HTTP/1.1 200"), head
        wait_for(lambda: caster.snapshot()["clients_now"] == 1)

        users.pop("newbie")
        assert caster.call(caster.caster.set_users, users) == {"newbie"}
        rest = _stream_then_eof(s)  # closed by the caster, not by us
        s.close()
        assert rest.endswith(b"0\r\n\r\n")  # a v2 stream ends with the last chunk
        snap = caster.snapshot()
        assert snap["clients_now"] == 0 and snap["counters"]["drop_revoked"] == 1
        s, head = open_client(caster.port, "BASE01", user="newbie", password="newbie-pw")
        s.close()
        assert b"401" in head.split(b"\r\n")[0]
    finally:
        src.close()


def test_repassword_refuses_old_password_accepts_new_and_closes_old_session(caster):
    src = open_v2_source(caster.port, "BASE01")
    try:
        wait_for(lambda: caster.snapshot()["mounts"]["BASE01"]["live"])
        s, head = open_client(caster.port, "BASE01")  # train1, verified and cached
        assert b"200" in head
        wait_for(lambda: caster.snapshot()["clients_now"] == 1)
        users = _users(caster)
        users["train1"] = replace(users["train1"], password_hash=hash_password("fresh-pw", **FAST))
        caster.call(caster.caster.set_users, users)
        _stream_then_eof(s)
        s.close()
        s, head = open_client(caster.port, "BASE01", password=TRAIN_PW)
        s.close()
        assert b"401" in head.split(b"\r\n")[0]
        s, head = open_client(caster.port, "BASE01", password="fresh-pw")
        s.close()
        assert b"200" in head
    finally:
        src.close()


def test_group_change_closes_sessions_the_groups_no_longer_allow(caster):
    src = open_v2_source(caster.port, "BASE01")
    try:
        wait_for(lambda: caster.snapshot()["mounts"]["BASE01"]["live"])
        s, head = open_client(caster.port, "BASE01")
        assert b"200" in head
        open_pub, head = open_client(caster.port, "OPEN")  # public mountpoint: stays
        users = _users(caster)
        users["train1"] = replace(users["train1"], groups=frozenset({"visitors"}))
        assert caster.call(caster.caster.set_users, users) == set()
        _stream_then_eof(s)
        s.close()
        open_pub.close()
        assert caster.snapshot()["counters"]["drop_revoked"] == 1
    finally:
        src.close()


def test_revoked_station_user_loses_its_source(caster):
    src = open_v2_source(caster.port, "BASE01")
    try:
        wait_for(lambda: caster.snapshot()["mounts"]["BASE01"]["live"])
        users = _users(caster)
        users.pop("station1")
        caster.call(caster.caster.set_users, users)
        assert read_all(src, timeout=5.0) == b""
        snap = caster.snapshot()
        assert snap["mounts"]["BASE01"]["live"] is False and snap["counters"]["drop_source_revoked"] == 1
    finally:
        src.close()


def test_disabled_mountpoint_leaves_sourcetable_and_its_readers_are_closed(caster):
    src = open_v2_source(caster.port, "BASE01")
    try:
        wait_for(lambda: caster.snapshot()["mounts"]["BASE01"]["live"])
        s, head = open_client(caster.port, "BASE01")
        assert b"200" in head
        assert b"STR;BASE01;" in _sourcetable(caster.port)
        mounts = [replace(m, enabled=False) if m.name == "BASE01" else m for m in _mounts(caster)]
        caster.call(caster.caster.set_mounts, mounts)
        _stream_then_eof(s)
        s.close()
        assert b"STR;BASE01;" not in _sourcetable(caster.port)
        s, head = open_client(caster.port, "BASE01", version=2)
        s.close()
        assert head.startswith(b"HTTP/1.1 404"), head
        snap = caster.snapshot()
        assert snap["counters"]["drop_mount_disabled"] == 1
        assert snap["mounts"]["BASE01"]["enabled"] is False
        assert snap["mounts"]["BASE01"]["source"] is not None  # the station keeps feeding in-process taps

        caster.call(caster.caster.set_mounts, [replace(m, enabled=True) for m in mounts])
        s, head = open_client(caster.port, "BASE01")
        s.close()
        assert b"200" in head
    finally:
        src.close()


def test_mount_table_adds_new_and_disables_missing_mountpoints(caster):
    mounts = [m for m in _mounts(caster) if m.name != "BASE02"]
    mounts.append(MountConfig("BASE03", "source", frozenset({"trains"}), frozenset({"stations"})))
    mounts.append(MountConfig("VRSX", "vrs", frozenset({"trains"})))  # no factory here: not created
    caster.call(caster.caster.set_mounts, mounts)
    snap = caster.snapshot()
    assert snap["mounts"]["BASE02"]["enabled"] is False and "VRSX" not in snap["mounts"]
    src = open_v2_source(caster.port, "BASE03")
    try:
        wait_for(lambda: caster.snapshot()["mounts"]["BASE03"]["live"])
        s, head = open_client(caster.port, "BASE03")
        s.close()
        assert b"200" in head
    finally:
        src.close()
