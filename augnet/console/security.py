"""Operator credentials: scrypt password hashes (`augwire.passwords`, the caster's format) and Bearer API
tokens.

Tokens are random (augnet.store.queries.TOKEN_BYTES); the store keeps only their SHA-256. A login token
lives LOGIN_TOKEN_LIFETIME; the bootstrap admin token printed by `augnet up` does not expire (revoke it
with logout, or by changing the admin's password).
"""

from __future__ import annotations

import datetime as dt
import secrets
from dataclasses import dataclass
from functools import lru_cache

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from augnet.store import queries as q
from augnet.store.models import Operator, Role
from augwire.passwords import hash_password, verify_password

# A working shift plus margin: an operator logs in once per shift.
LOGIN_TOKEN_LIFETIME = dt.timedelta(hours=12)
BOOTSTRAP_PASSWORD_BYTES = 12  # 96 bits, printed once by `augnet up` / `augnet console serve`
SYSTEM_ACTOR = "system"

__all__ = ["authenticate", "ensure_admin", "Bootstrap", "LOGIN_TOKEN_LIFETIME", "SYSTEM_ACTOR"]


@lru_cache(maxsize=1)
def _dummy_hash() -> str:
    return hash_password("not a password")


def authenticate(session: Session, name: str, password: str) -> Operator | None:
    """The enabled operator with this name and password, or None. An unknown name costs the same scrypt
    work as a known one, so response time does not reveal which names exist."""
    op = session.scalar(select(Operator).where(Operator.name == name))
    if op is None:
        verify_password(password, _dummy_hash())
        return None
    if not verify_password(password, op.password_hash) or not op.enabled:
        return None
    return op


@dataclass(frozen=True, slots=True)
class Bootstrap:
    name: str
    password: str
    token: str


def ensure_admin(sessions: sessionmaker[Session], name: str = "admin",
                 password: str | None = None) -> Bootstrap | None:
    """Create the first admin account when the store has no operator at all, with a non-expiring token.

    Returns the credentials to print (the password is random unless given), or None when operators exist
    (nothing is created, nothing secret is printed)."""
    with sessions.begin() as s:
        if q.operator_count(s) > 0:
            return None
        password = password or secrets.token_urlsafe(BOOTSTRAP_PASSWORD_BYTES)
        op = q.add_operator(s, SYSTEM_ACTOR, name, hash_password(password), Role.ADMIN)
        token = q.issue_token(s, op)
        q.audit(s, SYSTEM_ACTOR, "token.issue", name, reason="bootstrap")
    return Bootstrap(name=name, password=password, token=token)


def issue_operator_token(sessions: sessionmaker[Session], name: str, actor: str = SYSTEM_ACTOR,
                         lifetime: dt.timedelta | None = LOGIN_TOKEN_LIFETIME) -> str:
    """A new token for an existing operator (the CLI's `augnet console token`)."""
    with sessions.begin() as s:
        op = q.get_operator(s, name)
        token = q.issue_token(s, op, lifetime)
        q.audit(s, actor, "token.issue", name,
                lifetime_s=None if lifetime is None else int(lifetime.total_seconds()))
    return token
