"""The shared per-key throttle rules (augwire/throttle.py) on a stepped clock; the console's and the
caster's throttles built on them are tested in tests/console/test_security.py and tests/ntrip/test_auth_flood.py."""

from __future__ import annotations

from augwire.throttle import (BACKOFF_BASE_S, FORGET_AFTER_S, FREE_FAILURES, MAX_LOCKOUT_S, RETRY_WHILE_IN_FLIGHT_S,
                              KeyTable, backoff_s, wait_s)

KEY = ("addr", "192.0.2.1")


def test_free_failures_then_a_doubling_lock_up_to_the_cap():
    assert [backoff_s(n) for n in range(FREE_FAILURES)] == [0.0] * FREE_FAILURES
    assert backoff_s(FREE_FAILURES) == BACKOFF_BASE_S and backoff_s(FREE_FAILURES + 3) == 8 * BACKOFF_BASE_S
    assert backoff_s(10_000) == MAX_LOCKOUT_S


def test_a_locked_key_waits_whole_seconds_rounded_up():
    t = KeyTable()
    for _ in range(FREE_FAILURES + 1):  # the last failure locks for 2 s
        st = t.fail(KEY, 100.0)
    assert wait_s(st, 100.0) == 2 and wait_s(st, 101.5) == 1 and wait_s(st, 102.0) == 0


def test_attempts_in_flight_count_against_the_free_failures():
    t = KeyTable()
    st = t.state(KEY, 0.0)
    st.in_flight = FREE_FAILURES
    assert wait_s(st, 0.0) == RETRY_WHILE_IN_FLIGHT_S
    assert wait_s(st, 0.0, allowed_in_flight=10 * FREE_FAILURES) == 0  # a caller may trust a key more
    t.release(KEY)
    assert st.in_flight == FREE_FAILURES - 1 and wait_s(st, 0.0) == 0


def test_quiet_keys_are_forgotten_and_the_table_is_bounded():
    t = KeyTable(max_keys=3)
    t.fail(KEY, 10.0)
    assert t.state(KEY, 10.0 + FORGET_AFTER_S).failures == 1  # not yet
    assert t.state(KEY, 10.0 + FORGET_AFTER_S + 1).failures == 0
    for i in range(10):
        t.fail(("user", f"u{i}"), 20.0)
    assert len(t) == 3 and t.get(("user", "u9")) is not None and t.get(("user", "u0")) is None


def test_stamped_new_keys_stay_until_quiet_unstamped_ones_at_once():
    stamped, plain = KeyTable(stamp_new=True), KeyTable()
    for t in (stamped, plain):
        t.state(KEY, 5000.0).refused = 1
    assert stamped.state(KEY, 5001.0).refused == 1  # created at 5000: remembered for an hour
    assert plain.state(KEY, 5001.0).refused == 0  # never failed: last_seen 0, long quiet
