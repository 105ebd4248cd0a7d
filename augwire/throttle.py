"""Failed-login throttling, the part the console's login (augnet/console/throttle.py) and the caster's NTRIP
authentication (ntrip_caster/throttle.py) share: per-key failure counts, an exponential lock, attempts in
flight, forgetting quiet keys, a bounded key table. Sans-IO: no clock of its own (every call takes `now`,
seconds, any monotonic origin), no lock (the console's wrapper holds one; the caster runs on one loop).

Rules (per key; a key is ("addr", client address) or ("user", submitted name)):
  * the first FREE_FAILURES failures cost nothing; each further one locks the key for
    BACKOFF_BASE_S * 2**(failures - FREE_FAILURES), at most MAX_LOCKOUT_S;
  * a locked key is refused without verifying the password, with Retry-After in whole seconds;
  * attempts in flight count against the free failures (a burst of concurrent guesses cannot run more than
    FREE_FAILURES verifications before the first lock), unless the caller allows more (`allowed_in_flight`);
  * a key quiet for FORGET_AFTER_S (nothing in flight, not locked) is forgotten.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

# Free failures before the first lock: a typo or two plus a caps-lock, as OWASP's authentication cheat
# sheet suggests ("a small number"); Django-axes and fail2ban's sshd jail default to 3 and 5.
FREE_FAILURES = 5
BACKOFF_BASE_S = 1.0  # first lock after the free failures; doubles with each failure after it
# Longest lock: 15 min. Amazon Cognito's user pools do the same (5 free failures, a lock from 1 s doubling to
# about 15 min). 100 guesses at one name then take 21.5 h; an operator locked out waits 15 min at worst.
MAX_LOCKOUT_S = 900.0
FORGET_AFTER_S = 3600.0  # a key with no failure for an hour (and not locked) starts afresh
# Keys remembered (addresses + names); beyond this the least recently failed are dropped first.
MAX_KEYS = 100_000
RETRY_WHILE_IN_FLIGHT_S = 1  # Retry-After when refused only because other attempts are being verified

Key = tuple[str, str]


@dataclass(slots=True)
class KeyState:
    failures: int = 0
    locked_until: float = 0.0
    last_seen: float = 0.0  # the last failure (or, where the table stamps new keys, the key's creation)
    in_flight: int = 0
    # what only one of the two users keeps
    trusted: bool = False  # caster: last verified outcome a success, no failure since
    refused: int = 0  # console: attempts of this key refused
    lock_audited: bool = True  # console: whether the current lock's first refusal was audited (no lock: True)


def backoff_s(failures: int) -> float:
    """Lock length after `failures` consecutive failures of one key [s] (0: not locked)."""
    if failures < FREE_FAILURES:
        return 0.0
    return min(MAX_LOCKOUT_S, BACKOFF_BASE_S * 2.0 ** min(failures - FREE_FAILURES, 30))


def free_in_flight(st: KeyState) -> int:
    """Verifications a key may have in flight by default: its remaining free failures (at least one)."""
    return FREE_FAILURES - st.failures if st.failures < FREE_FAILURES else 1


def wait_s(st: KeyState, now: float, allowed_in_flight: int | None = None) -> int:
    """0: the key may verify now; else the Retry-After [s] (whole seconds, rounded up: RFC 9110 10.2.3)."""
    if st.locked_until > now:
        return max(1, int(-(-(st.locked_until - now) // 1)))
    allowed = free_in_flight(st) if allowed_in_flight is None else allowed_in_flight
    return RETRY_WHILE_IN_FLIGHT_S if st.in_flight >= allowed else 0


class KeyTable:
    """The keys' states, least recently failed first, at most `max_keys`. `stamp_new`: a new key's
    `last_seen` is its creation time (else 0: forgotten at its next look unless it failed meanwhile)."""

    def __init__(self, max_keys: int = MAX_KEYS, stamp_new: bool = False) -> None:
        self.max_keys = max_keys
        self.stamp_new = stamp_new
        self._keys: OrderedDict[Key, KeyState] = OrderedDict()

    def state(self, key: Key, now: float) -> KeyState:
        """The key's state (a fresh one for a key unknown or quiet long enough)."""
        st = self._keys.get(key)
        if st is not None and st.in_flight == 0 and st.locked_until <= now and now - st.last_seen > FORGET_AFTER_S:
            st = None  # quiet long enough: forgotten
        if st is None:
            st = self._keys[key] = KeyState(last_seen=now if self.stamp_new else 0.0)
            while len(self._keys) > self.max_keys:
                self._keys.popitem(last=False)
        return st

    def get(self, key: Key) -> KeyState | None:
        return self._keys.get(key)

    def pop(self, key: Key) -> None:
        self._keys.pop(key, None)

    def fail(self, key: Key, now: float) -> KeyState:
        """A verified attempt of `key` failed: out of flight, one more failure, locked past the free ones.
        Returns the state (`locked_until` > now when this failure locked it)."""
        st = self.state(key, now)
        st.in_flight = max(0, st.in_flight - 1)
        st.failures += 1
        st.last_seen = now
        lock = backoff_s(st.failures)
        if lock:
            st.locked_until = now + lock
        self._keys.move_to_end(key)
        return st

    def release(self, key: Key) -> None:
        """An admitted attempt of `key` is no longer in flight (answered otherwise, or abandoned)."""
        st = self._keys.get(key)
        if st is not None:
            st.in_flight = max(0, st.in_flight - 1)

    def __len__(self) -> int:
        return len(self._keys)
