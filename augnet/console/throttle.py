"""Failed-login throttling: exponential back-off per client address and per operator name (sans-IO); the
per-key rules are the ones the caster shares (augwire/throttle.py), the audit bookkeeping is the console's.

`LoginThrottle` holds no socket and reads no clock of its own: every call takes `now` (seconds, any
monotonic origin), so tests step a clock instead of sleeping. The login route asks `admit()` before it
verifies a password, and reports the outcome with `failed()` or `succeeded()`.

Rules (per key; a key is ("addr", client address) or ("user", submitted name), checked together):
  * the first FREE_FAILURES failures cost nothing; each further one locks the key for
    BACKOFF_BASE_S * 2**(failures - FREE_FAILURES), at most MAX_LOCKOUT_S;
  * a locked key is refused without verifying the password (the attacker pays a request, we pay no
    scrypt); the answer is 429 with Retry-After, the right password included (else the lock only slows
    a guesser who happens to guess right);
  * attempts in flight count against the free ones, so a burst of concurrent guesses cannot run more
    than FREE_FAILURES verifications before the first lock;
  * a success forgets the name's failures (not the address's: a valid account must not reset the
    counter of an address spraying other names); a key quiet for FORGET_AFTER_S is forgotten;
  * ALARM_FAILURES failures of one key, or ALARM_REFUSALS refusals of one address, ask for an alarm.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

from augwire.throttle import (BACKOFF_BASE_S, FORGET_AFTER_S, FREE_FAILURES, MAX_KEYS, MAX_LOCKOUT_S,
                              RETRY_WHILE_IN_FLIGHT_S, KeyTable, backoff_s, wait_s)

__all__ = ["ALARM_FAILURES", "ALARM_REFUSALS", "BACKOFF_BASE_S", "FORGET_AFTER_S", "FREE_FAILURES", "MAX_KEYS",
           "MAX_LOCKOUT_S", "RETRY_WHILE_IN_FLIGHT_S", "Counters", "Failure", "LoginThrottle", "Verdict",
           "backoff_s"]

# An alarm for the operators: twice the free failures (past any typing slip) for one address or one name, or
# this many refused attempts from one address (a client ignoring Retry-After: a script, not a person).
ALARM_FAILURES = 2 * FREE_FAILURES
ALARM_REFUSALS = 50


@dataclass(frozen=True, slots=True)
class Verdict:
    """`admit()`'s answer: retry_after_s == 0 means go ahead and verify."""

    retry_after_s: int
    audit: bool = False  # a refusal worth its own audit entry (the first of a lock)
    refused_unaudited: int = 0  # earlier refusals from this address not yet in the audit log
    alarm: bool = False  # this refusal made the address's count reach ALARM_REFUSALS


@dataclass(frozen=True, slots=True)
class Failure:
    """`failed()`'s answer."""

    failures: int  # consecutive failures of the name
    refused_unaudited: int  # refusals from the address not yet in the audit log
    alarm: bool  # the address's or the name's failures just reached ALARM_FAILURES


@dataclass(slots=True)
class Counters:
    """For /metrics: totals since start."""

    failed: int = 0  # passwords verified and wrong (or account disabled / unknown)
    refused: int = 0  # attempts refused by a lock, not verified
    succeeded: int = 0


@dataclass
class LoginThrottle:
    max_keys: int = MAX_KEYS
    counters: Counters = field(default_factory=Counters)

    def __post_init__(self) -> None:
        self._keys = KeyTable(self.max_keys)  # the shared rules (augwire/throttle.py)
        self._unaudited: dict[str, int] = {}  # address -> refusals not yet written to the audit log
        self._lock = threading.Lock()  # the login route runs in worker threads

    def admit(self, address: str, name: str, now: float) -> Verdict:
        """May this attempt verify a password now? If so it is in flight until failed() / succeeded()."""
        with self._lock:
            states = [self._keys.state(("addr", address), now), self._keys.state(("user", name), now)]
            wait = max(wait_s(st, now) for st in states)
            if wait:
                self.counters.refused += 1
                states[0].refused += 1
                alarm = states[0].refused == ALARM_REFUSALS
                first = [st for st in states if not st.lock_audited and st.locked_until > now]
                for st in first:
                    st.lock_audited = True
                if first or alarm:
                    return Verdict(wait, audit=True, refused_unaudited=self._unaudited.pop(address, 0), alarm=alarm)
                self._unaudited[address] = self._unaudited.get(address, 0) + 1
                return Verdict(wait)
            for st in states:
                st.in_flight += 1
            return Verdict(0)

    def failed(self, address: str, name: str, now: float) -> Failure:
        """A verified attempt failed."""
        with self._lock:
            self.counters.failed += 1
            alarm = False
            for key in (("addr", address), ("user", name)):
                st = self._keys.fail(key, now)
                alarm |= st.failures == ALARM_FAILURES
                if backoff_s(st.failures):
                    st.lock_audited = False
            return Failure(self._keys.get(("user", name)).failures, self._unaudited.pop(address, 0), alarm)

    def succeeded(self, address: str, name: str, now: float) -> int:
        """A verified attempt succeeded: the name starts afresh. Returns the address's unaudited refusals."""
        with self._lock:
            self.counters.succeeded += 1
            st = self._keys.state(("addr", address), now)
            st.in_flight = max(0, st.in_flight - 1)
            self._keys.pop(("user", name))
            return self._unaudited.pop(address, 0)

    def abandon(self, address: str, name: str) -> None:
        """A verification that raised instead of answering: no longer in flight, counted as nothing."""
        with self._lock:
            for key in (("addr", address), ("user", name)):
                self._keys.release(key)

    def unaudited(self, address: str) -> int:
        with self._lock:
            return self._unaudited.get(address, 0)
