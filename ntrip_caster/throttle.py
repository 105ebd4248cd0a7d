"""Failed NTRIP authentication throttled per client address and per user name (sans-IO), and the flood alarm.

The per-key rules are the console's (free failures, then an exponential lock, refused without hashing,
attempts in flight counted against the free ones), shared through `augwire/throttle.py` (`ntrip_caster`
may not import `augnet`: architecture.md). Two differences a caster needs live here:
  * many trains share one name (augnet's "train") and often one address (carrier NAT): a key whose last
    verified attempt succeeded and that has no failure since is *trusted* and may have up to
    MAX_IN_FLIGHT_TRUSTED verifications in flight (a fleet reconnecting after a caster restart), where an
    untrusted key gets only its remaining free failures;
  * an (address, name) pair that succeeded before skips the *name's* lock: an attacker spraying wrong
    passwords at "train" from elsewhere must not lock out the trains (the lock of their own address
    still applies).

Nothing here reads a clock: every call takes `now` (seconds, any monotonic origin), so tests step a clock.
"""

from __future__ import annotations

from collections import OrderedDict

from augwire.throttle import (BACKOFF_BASE_S, FORGET_AFTER_S, FREE_FAILURES, MAX_KEYS, MAX_LOCKOUT_S,
                              RETRY_WHILE_IN_FLIGHT_S, KeyState, KeyTable, backoff_s, wait_s)

__all__ = ["AuthThrottle", "BACKOFF_BASE_S", "FLOOD_ALARM_EVENTS", "FLOOD_ALARM_WINDOW_S", "FORGET_AFTER_S",
           "FREE_FAILURES", "FloodAlarm", "MAX_IN_FLIGHT_TRUSTED", "MAX_KEYS", "MAX_LOCKOUT_S",
           "RETRY_WHILE_IN_FLIGHT_S", "backoff_s"]

# In-flight verifications of a trusted key: the verification pool's queue bound (limits.py) is the real cap.
MAX_IN_FLIGHT_TRUSTED = 1_000_000


class AuthThrottle:
    """`admit()` before a password is verified; then exactly one of `failed()`, `succeeded()`, `abandon()`.

    Runs on the caster's event loop only (no lock needed)."""

    def __init__(self, max_keys: int = MAX_KEYS) -> None:
        self.max_keys = max_keys
        self._keys = KeyTable(max_keys, stamp_new=True)  # the shared rules (augwire/throttle.py)
        self._pairs: OrderedDict[tuple[str, str], float] = OrderedDict()  # (address, name) -> last success

    @staticmethod
    def _wait(st: KeyState, now: float, shared: bool = False) -> int:
        return wait_s(st, now, MAX_IN_FLIGHT_TRUSTED if shared or st.trusted else None)

    def _keys_of(self, address: str, name: str, now: float) -> list[KeyState]:
        states = [self._keys.state(("addr", address), now)]
        pair = self._pairs.get((address, name))
        if pair is None or now - pair > FORGET_AFTER_S:  # a known (address, name) pair skips the name's lock
            states.append(self._keys.state(("user", name), now))
        return states

    def admit(self, address: str, name: str, now: float, shared: bool = False) -> int:
        """0: verify now (the attempt is in flight until its outcome is reported); else Retry-After [s].
        `shared`: the attempt joins a verification of the same credentials already running (no hash of its
        own), so only a lock refuses it, not the in-flight cap: a fleet starting together is not throttled."""
        states = self._keys_of(address, name, now)
        wait = max(self._wait(st, now, shared) for st in states)
        if not wait:
            for st in states:
                st.in_flight += 1
        return wait

    def failed(self, address: str, name: str, now: float) -> None:
        self._pairs.pop((address, name), None)
        for key in (("addr", address), ("user", name)):
            self._keys.fail(key, now).trusted = False

    def succeeded(self, address: str, name: str, now: float) -> None:
        """The name starts afresh; the address keeps its failures (a valid account must not reset the count
        of an address spraying other names) and is trusted only when it has none."""
        for key in (("addr", address), ("user", name)):
            self._keys.release(key)
        self._keys.pop(("user", name))
        self._keys.state(("user", name), now).trusted = True
        addr = self._keys.state(("addr", address), now)
        addr.trusted = addr.failures == 0
        self._pairs[(address, name)] = now
        self._pairs.move_to_end((address, name))
        while len(self._pairs) > self.max_keys:
            self._pairs.popitem(last=False)

    def abandon(self, address: str, name: str) -> None:
        """An admitted attempt that was not verified after all (pool full, verification raised)."""
        for key in (("addr", address), ("user", name)):
            self._keys.release(key)


# A caster-wide alarm: this many failed or refused authentications within one window. A fleet of 10,000
# trains with a few misconfigured ones fails a handful a minute; a guesser past its free failures gets
# refused dozens a second.
FLOOD_ALARM_EVENTS = 100
FLOOD_ALARM_WINDOW_S = 60.0


class FloodAlarm:
    """Counts bad authentications in fixed windows: `note()` True once when the count reaches the threshold,
    `tick()` True once when a whole window after that stayed below it (the alarm clears)."""

    def __init__(self, threshold: int = FLOOD_ALARM_EVENTS, window_s: float = FLOOD_ALARM_WINDOW_S) -> None:
        self.threshold = threshold
        self.window_s = window_s
        self.window_start = 0.0
        self.count = 0
        self.raised = False

    def _roll(self, now: float) -> bool:
        """Start a new window if the current one is over; True when the one that ended was quiet."""
        if now - self.window_start < self.window_s:
            return False
        quiet = self.count < self.threshold
        self.window_start, self.count = now, 0
        return quiet

    def note(self, now: float) -> bool:
        self._roll(now)
        self.count += 1
        if self.count == self.threshold and not self.raised:
            self.raised = True
            return True
        return False

    def tick(self, now: float) -> bool:
        if self.raised and self._roll(now):
            self.raised = False
            return True
        return False
