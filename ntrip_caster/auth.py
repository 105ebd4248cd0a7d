"""Users, groups and per-mountpoint access; passwords stored as scrypt hashes (`augwire.passwords`,
a few tens of ms per check). A caster sees the same credentials on every reconnect of a
train, so successful checks are remembered in a bounded cache keyed by an HMAC of the credentials
under a per-process random key (no plaintext password is kept).

The user table may be replaced while the caster runs (`replace_users`: an operator's change, decision
0180): a removed or re-passworded user's cached credentials are forgotten at once, and a verification
already running against the old hash does not enter the cache.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

from augwire.passwords import SCRYPT_SALT_BYTES, hash_password, verify_password

# Distinct verified credentials remembered (one per train or station is the realistic case).
AUTH_CACHE_ENTRIES = 100_000
# Groups value that opens a mountpoint to anyone, without credentials.
PUBLIC = "*"


@dataclass(slots=True)
class User:
    name: str
    password_hash: str
    groups: frozenset[str] = field(default_factory=frozenset)


class Authenticator:
    """Decides who may read or publish a mountpoint.

    `read_groups` / `write_groups` of a mountpoint are sets of group names; PUBLIC ('*') means no
    credentials are needed. A user may read a mountpoint when one of their groups is listed.
    """

    def __init__(self, users: dict[str, User] | None = None) -> None:
        self.users: dict[str, User] = dict(users or {})
        self._key = os.urandom(32)
        self._cache: OrderedDict[bytes, str] = OrderedDict()
        self._lock = threading.Lock()  # checks run in worker threads, lookups on the event loop
        self.checks = 0  # scrypt verifications run (the expensive path)
        self.revision = 0  # bumped whenever a user loses credentials (removed, re-passworded)

    def replace_users(self, users: dict[str, User]) -> set[str]:
        """Take a new user table (on the event loop). Returns the names whose credentials no longer hold
        (removed, or another password hash): their cached verifications are forgotten. A change of groups
        alone revokes nothing here (`allowed` reads the table live)."""
        old = self.users
        revoked = {n for n, u in old.items() if n not in users or users[n].password_hash != u.password_hash}
        self.users = dict(users)
        if revoked:
            self.revision += 1
            with self._lock:
                for key in [k for k, name in self._cache.items() if name in revoked]:
                    del self._cache[key]
        return revoked

    def credential_key(self, user: str, password: str) -> bytes:
        """An HMAC of the credentials (never the password itself): the cache's key, and the caster's for
        verifications in flight."""
        return self._cache_key(user, password)

    def _cache_key(self, user: str, password: str) -> bytes:
        return hmac.new(self._key, f"{user}\0{password}".encode("utf-8", "surrogatepass"),
                        hashlib.sha256).digest()

    def cached_user(self, user: str | None, password: str | None) -> str | None:
        """The user name if these credentials were verified before, else None (cheap)."""
        if user is None or password is None:
            return None
        key = self._cache_key(user, password)
        with self._lock:
            name = self._cache.get(key)
            if name is not None:
                self._cache.move_to_end(key)
        return name

    def check(self, user: str | None, password: str | None) -> str | None:
        """Verify credentials (scrypt; run it off the event loop). Returns the user name or None."""
        if user is None or password is None:
            return None
        cached = self.cached_user(user, password)
        if cached is not None:
            return cached
        record = self.users.get(user)
        if record is None:
            # Spend the same time as for a real user, so response time does not reveal user names.
            verify_password(password, _DUMMY_HASH)
            self.checks += 1
            return None
        self.checks += 1
        if not verify_password(password, record.password_hash):
            return None
        return user if self._remember(user, password, record.password_hash) else None

    def check_source_password(self, password: str, write_groups: frozenset[str]) -> str | None:
        """NTRIP 1 SOURCE carries only a password: accept it when it is the password of a user in
        one of the mountpoint's write groups. Returns that user's name or None."""
        for name, record in self.users.items():
            if record.groups & write_groups:
                if self.cached_user(name, password) or self.check(name, password):
                    return name
        return None

    def _remember(self, user: str, password: str, password_hash: str) -> bool:
        """Cache a verification made against `password_hash`, if that is still the user's hash (the table
        may have changed while scrypt ran; `replace_users` swaps the table, then purges under the lock)."""
        key = self._cache_key(user, password)
        with self._lock:
            current = self.users.get(user)
            if current is None or current.password_hash != password_hash:
                return False
            self._cache[key] = user
            while len(self._cache) > AUTH_CACHE_ENTRIES:
                self._cache.popitem(last=False)
        return True

    def allowed(self, user: str | None, groups: frozenset[str]) -> bool:
        if PUBLIC in groups:
            return True
        if user is None or user not in self.users:
            return False
        return bool(self.users[user].groups & groups)


_DUMMY_HASH = hash_password("not a password", salt=b"\0" * SCRYPT_SALT_BYTES)
