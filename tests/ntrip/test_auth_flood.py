"""Issue 19: a bad-password flood must not hurt the service. Throttle and alarm on a stepped clock; the
caster on loopback (source addresses 127.0.0.x, Linux routes all of 127/8 to lo)."""

from __future__ import annotations

import contextlib

import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from augwire.rtcm_framing import frame
from ntrip_caster.embedded import CasterThread
from ntrip_caster.response import error_response
from ntrip_caster.server import AUTH_FLOOD_ALARM
from ntrip_caster.throttle import (FREE_FAILURES, MAX_LOCKOUT_S, AuthThrottle, FloodAlarm,
                                   backoff_s)

from .helpers import (STATION_PW, TRAIN_PW, basic, make_config, open_client, open_v1_source,
                      read_all, read_exactly, read_until)

HANG_GUARD_S = 60.0  # generous: only there so a broken caster fails instead of hanging the suite


# --- sans-IO throttle ---------------------------------------------------------------------------
def _flood(th: AuthThrottle, addresses, name: str, n: int, span_s: float) -> int:
    """n wrong-password attempts spread evenly over span_s (stepped clock); returns how many were verified."""
    verified = 0
    for i in range(n):
        now = i * span_s / n
        addr = addresses[i % len(addresses)]
        if th.admit(addr, name, now) == 0:
            verified += 1
            th.failed(addr, name, now)
    return verified


def test_1000_wrong_passwords_in_10_s_from_one_address_verify_a_handful():
    verified = _flood(AuthThrottle(), ["198.51.100.7"], "train", 1000, 10.0)
    # 5 free, then locks of 1, 2, 4 s: the 6th at 1 s, the 7th at 3 s, the 8th at 7 s
    assert verified == FREE_FAILURES + 3


def test_a_name_sprayed_from_many_addresses_is_locked_too():
    addrs = [f"10.0.{i // 250}.{i % 250}" for i in range(1000)]  # each address used once
    assert _flood(AuthThrottle(), addrs, "train", 1000, 10.0) == FREE_FAILURES + 3


def test_concurrent_guesses_cannot_outrun_the_free_failures():
    th = AuthThrottle()
    admitted = sum(th.admit("198.51.100.7", "train", 0.0) == 0 for _ in range(300))  # none answered yet
    assert admitted == FREE_FAILURES


def test_lock_grows_exponentially_to_its_cap_and_retry_after_says_how_long():
    assert [backoff_s(n) for n in range(FREE_FAILURES - 1, FREE_FAILURES + 3)] == [0.0, 1.0, 2.0, 4.0]
    assert backoff_s(1000) == MAX_LOCKOUT_S
    th = AuthThrottle()
    for now in [100.0] * FREE_FAILURES + [101.0, 103.0]:  # locked 1 s, then 2, then 4 s from 103
        assert th.admit("a", "u", now) == 0
        th.failed("a", "u", now)
    assert th.admit("a", "u", 100.5) == 7  # 6.5 s left, rounded up
    assert th.admit("a", "u", 103.5) == 4
    assert th.admit("a", "u", 107.0) == 0


def test_a_known_train_is_not_locked_out_by_a_spray_at_its_name():
    th = AuthThrottle()
    assert th.admit("192.0.2.1", "train", 0.0) == 0
    th.succeeded("192.0.2.1", "train", 0.0)
    _flood(th, [f"10.1.0.{i}" for i in range(200)], "train", 200, 2.0)
    assert th.admit("10.1.1.1", "train", 3.0) > 0  # a new address: the name's lock applies
    assert th.admit("192.0.2.1", "train", 3.0) == 0  # the train's own address: it does not


def test_a_fleet_behind_one_address_reconnects_together_once_trusted():
    th = AuthThrottle()
    assert th.admit("nat", "train", 0.0) == 0
    th.succeeded("nat", "train", 0.0)
    assert all(th.admit("nat", "train", 1.0) == 0 for _ in range(500))
    untrusted = AuthThrottle()
    assert sum(untrusted.admit("nat", "train", 1.0) == 0 for _ in range(500)) == FREE_FAILURES


def test_flood_alarm_raises_once_and_clears_after_a_quiet_window():
    al = FloodAlarm(threshold=10, window_s=60.0)
    raised = [al.note(1.0 + i * 0.1) for i in range(30)]
    assert raised.count(True) == 1 and raised.index(True) == 9
    assert not al.tick(30.0)  # same window
    assert not al.tick(61.0)  # the loud window just ended
    assert al.raised
    assert al.tick(121.5)  # a whole window below the threshold
    assert not al.raised


def test_v1_source_and_http_answers_carry_the_refusal():
    assert error_response(1, 429, "x", source_v1=True, retry_after=3) == b"ERROR - Too many attempts\r\n"
    assert error_response(1, 503, "x", source_v1=True, retry_after=2) == b"ERROR - Server busy\r\n"
    for version in (1, 2):
        assert b"\r\nRetry-After: 7\r\n" in error_response(version, 429, "x", retry_after=7)


# --- on loopback ---------------------------------------------------------------------------------
def _request(port: int, user: str, password: str, source_ip: str = "127.0.0.1", mount: str = "BASE01",
             version: int = 2) -> bytes:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(HANG_GUARD_S)
    try:
        s.bind((source_ip, 0))
        s.connect(("127.0.0.1", port))
        first = f"GET /{mount} HTTP/1.1" if version == 2 else f"GET /{mount} HTTP/1.0"
        s.sendall((f"{first}\r\nHost: x\r\nNtrip-Version: Ntrip/2.0\r\nUser-Agent: NTRIP flood\r\n"
                   f"Authorization: {basic(user, password)}\r\n\r\n").encode())
        return read_until(s, b"\r\n\r\n")  # an error's head, or a stream's (whose body never ends)
    finally:
        s.close()


def _status(reply: bytes) -> int:
    return int(reply.split(b" ", 2)[1]) if reply.startswith(b"HTTP/") else 0


class SteppedClock:
    def __init__(self) -> None:
        self.t = 1000.0
        self.lock = threading.Lock()

    def __call__(self) -> float:
        return self.t

    def step(self, dt: float) -> None:
        with self.lock:
            self.t += dt


def test_1000_wrong_passwords_from_one_address_on_loopback():
    clock = SteppedClock()
    with CasterThread(make_config()) as ct:
        ct.caster.clock = clock
        alarms: list[tuple] = []
        ct.caster.on_alarm = lambda *a: alarms.append(a)
        src = open_v1_source(ct.port, "BASE01", STATION_PW)  # a live mountpoint: else 404 before any auth
        before = ct.snapshot(clients=False)["auth_checks"]  # the source's own check

        def one(i: int) -> int:
            clock.step(0.01)  # 1,000 requests in 10 s of the caster's clock
            reply = _request(ct.port, "train1", f"guess-{i}")
            if _status(reply) == 429:
                assert b"\r\nRetry-After: " in reply
            return _status(reply)

        with ThreadPoolExecutor(8) as pool:
            statuses = list(pool.map(one, range(1000)))
        snap = ct.snapshot(clients=False)
        src.close()
    hashed = snap["auth_checks"] - before
    assert hashed <= 2 * FREE_FAILURES  # a handful, not a thousand
    assert statuses.count(401) == hashed
    assert statuses.count(429) == 1000 - hashed
    assert snap["counters"]["auth_refused_throttled"] == 1000 - hashed
    assert [a[0] for a in alarms] == [AUTH_FLOOD_ALARM] and alarms[0][4] is False


N_STREAM_FRAMES, N_STREAM_TRAINS = 300, 100


@contextlib.contextmanager
def trains_streaming(ct, src, n_trains: int = N_STREAM_TRAINS, n_frames: int = N_STREAM_FRAMES):
    """n_trains reading BASE01 while the source sends n_frames over ~3 s; yields the list each train received
    (filled once the block ends) and the bytes sent."""
    frames = [frame((1005 << 4).to_bytes(2, "big") + i.to_bytes(4, "big") + bytes(40)) for i in range(n_frames)]
    sent = b"".join(frames)
    trains = []
    for _ in range(n_trains):
        s, head = open_client(ct.port, "BASE01", version=1)  # 127.0.0.1: a known train address after this
        assert head == b"ICY 200 OK\r\n"
        trains.append(s)
    received: list[bytes] = [b""] * n_trains

    def read_train(k: int) -> None:
        received[k] = read_exactly(trains[k], len(sent), timeout=HANG_GUARD_S)

    def feed() -> None:
        for f in frames:
            src.sendall(f)
            time.sleep(0.01)

    threads = [threading.Thread(target=read_train, args=(k,)) for k in range(n_trains)] + [threading.Thread(target=feed)]
    for t in threads:
        t.start()
    try:
        yield received, sent
    finally:
        for t in threads:
            t.join(HANG_GUARD_S)
        for t in trains:
            t.close()


@pytest.mark.slow
def test_300_concurrent_wrong_passwords_while_trains_stream():
    """300 guesses at once from 300 addresses (half at the trains' name, half at random names, which cost a
    dummy hash each) while 100 trains stream BASE01: every train gets every frame the source sent."""
    with CasterThread(make_config()) as ct:
        alarms: list[tuple] = []
        ct.caster.on_alarm = lambda *a: alarms.append(a)
        src = open_v1_source(ct.port, "BASE01", STATION_PW)
        with trains_streaming(ct, src) as (received, sent):

            def guess(i: int) -> int:
                ip = f"127.0.{1 + i // 200}.{2 + i % 200}"
                user = "train1" if i % 2 else f"nobody{i}"
                return _status(_request(ct.port, user, f"guess-{i}", source_ip=ip))

            with ThreadPoolExecutor(300) as pool:
                statuses = list(pool.map(guess, range(300)))
            # a train reconnecting from its known address while "train1" is locked for everyone else
            s, head = open_client(ct.port, "BASE01", version=1)
            assert head == b"ICY 200 OK\r\n"
            s.close()
        snap = ct.snapshot(clients=False)
        src.close()
    assert all(r == sent for r in received), [len(r) for r in received]
    assert set(statuses) <= {401, 429, 503} and len(statuses) == 300
    c = snap["counters"]
    assert c.get("auth_refused_throttled", 0) + c.get("auth_refused_busy", 0) > 0
    assert snap["auth_checks"] < 300
    assert AUTH_FLOOD_ALARM in [a[0] for a in alarms]


@pytest.mark.slow
def test_1000_wrong_passwords_from_one_address_while_100_trains_stream():
    """The one-address flood of the first test (1,000 guesses in 10 s of the caster's stepped clock) while 100
    trains stream BASE01: every train gets every frame, the guesses are refused 429 after a handful."""
    clock = SteppedClock()
    with CasterThread(make_config()) as ct:
        ct.caster.clock = clock
        src = open_v1_source(ct.port, "BASE01", STATION_PW)
        with trains_streaming(ct, src) as (received, sent):

            def one(i: int) -> int:
                clock.step(0.01)
                return _status(_request(ct.port, "train1", f"guess-{i}", source_ip="127.0.0.77"))

            with ThreadPoolExecutor(8) as pool:
                statuses = list(pool.map(one, range(1000)))
        src.close()
    assert all(r == sent for r in received), [len(r) for r in received]
    assert statuses.count(429) >= 1000 - 2 * FREE_FAILURES and set(statuses) <= {401, 429}


def test_pending_connections_per_address_are_bounded():
    from ntrip_caster.config import Limits

    with CasterThread(make_config(limits=Limits(max_pending_per_ip=3))) as ct:
        src = open_v1_source(ct.port, "BASE01", STATION_PW)  # admitted: no longer pending
        idle = [socket.create_connection(("127.0.0.1", ct.port)) for _ in range(3)]  # heads never sent
        try:
            time.sleep(0.2)  # let the caster accept them (a hang guard, not a timing assertion)
            extra = socket.create_connection(("127.0.0.1", ct.port), timeout=HANG_GUARD_S)
            assert b" 503 " in read_all(extra, timeout=HANG_GUARD_S)
            other = _request(ct.port, "train1", TRAIN_PW, source_ip="127.0.0.9")  # another address: served
            assert _status(other) == 200
        finally:
            for s in idle:
                s.close()
            src.close()
        assert ct.snapshot(clients=False)["counters"]["refused_pending_per_ip"] >= 1


def test_joining_a_running_verification_skips_the_in_flight_cap_but_not_a_lock():
    th = AuthThrottle()
    assert sum(th.admit("nat", "train", 0.0, shared=True) == 0 for _ in range(100)) == 100
    locked = AuthThrottle()
    for now in [0.0] * FREE_FAILURES:
        locked.admit("nat", "train", now)
        locked.failed("nat", "train", now)
    assert locked.admit("nat", "train", 0.5, shared=True) == 1


def test_a_fleet_starting_together_behind_one_address_is_served_with_one_hash():
    with CasterThread(make_config()) as ct:
        src = open_v1_source(ct.port, "BASE01", STATION_PW)
        before = ct.snapshot(clients=False)["auth_checks"]
        with ThreadPoolExecutor(50) as pool:  # cold cache, one address, one name, one password
            statuses = list(pool.map(lambda _: _status(_request(ct.port, "train1", TRAIN_PW)), range(50)))
        checks = ct.snapshot(clients=False)["auth_checks"] - before
        src.close()
    assert statuses == [200] * 50
    assert checks == 1
