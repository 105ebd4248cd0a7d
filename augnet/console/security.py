"""Operator credentials: scrypt password hashes (`augwire.passwords`, the caster's format) and Bearer API
tokens.

Tokens are random (augnet.store.queries.TOKEN_BYTES); the store keeps only their SHA-256. A login token
lives LOGIN_TOKEN_LIFETIME. Each store has one bootstrap token (decision 0170): created with the first admin,
written to the state file (0600) of `augnet up` / `augnet console serve`, reused by every later start that
finds it there, never expiring; logout does not revoke it (a page opened with it trades it for a session
token first), `augnet console token --rotate` or a new admin password replaces it.
"""

from __future__ import annotations

import datetime as dt
import secrets
from dataclasses import dataclass
from functools import lru_cache

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from augnet.store import queries as q
from augnet.store.models import ApiToken, Operator, Role
from augwire.passwords import hash_password, verify_password

# A working shift plus margin: an operator logs in once per shift.
LOGIN_TOKEN_LIFETIME = dt.timedelta(hours=12)
BOOTSTRAP_PASSWORD_BYTES = 12  # 96 bits, written to the state file (0600) of `augnet up` / `console serve`
SYSTEM_ACTOR = "system"

__all__ = ["authenticate", "ensure_admin", "bootstrap_admin", "rotate_bootstrap", "Bootstrap", "LOGIN_TOKEN_LIFETIME",
           "SYSTEM_ACTOR"]


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
    password: str | None  # known only when just created, or carried over from the last state file and still valid
    token: str
    created: bool = True


def ensure_admin(sessions: sessionmaker[Session], name: str = "admin",
                 password: str | None = None) -> Bootstrap | None:
    """Create the first admin account when the store has no operator at all, with the store's bootstrap token.

    Returns the credentials to hand over (the password is random unless given), or None when operators exist
    (nothing is created)."""
    with sessions.begin() as s:
        if q.operator_count(s) > 0:
            return None
        password = password or secrets.token_urlsafe(BOOTSTRAP_PASSWORD_BYTES)
        op = q.add_operator(s, SYSTEM_ACTOR, name, hash_password(password), Role.ADMIN)
        token = q.issue_token(s, op, kind=q.TOKEN_BOOTSTRAP)
        q.audit(s, SYSTEM_ACTOR, "token.issue", name, reason="bootstrap")
    return Bootstrap(name=name, password=password, token=token)


def bootstrap_admin(sessions: sessionmaker[Session], name: str = "admin", password: str | None = None,
                    previous: dict | None = None) -> Bootstrap | None:
    """The console's admin credentials for a start: a new store gets its first admin (ensure_admin); an
    existing one keeps the bootstrap token of the last state file (`previous`) while it is still the store's.
    Only when the state file lost it is the bootstrap token rotated (audited), for the admin `name`.
    None: no such enabled admin (log in with your own account)."""
    boot = ensure_admin(sessions, name, password)
    if boot is not None:
        return boot
    previous = previous or {}
    old_token, old_password = previous.get("admin_token"), previous.get("admin_password")
    with sessions.begin() as s:
        if isinstance(old_token, str) and q.is_bootstrap_token(s, old_token):
            op = q.operator_for_token(s, old_token)
            token = old_token
        else:
            op = s.scalar(select(Operator).where(Operator.name == name))
            if op is None or not op.enabled or op.role is not Role.ADMIN:
                return None
            token = q.rotate_bootstrap_token(s, SYSTEM_ACTOR, op, reason="not in the state file")
        op_name, op_hash = op.name, op.password_hash
    keep = isinstance(old_password, str) and previous.get("admin_name", name) == op_name \
        and verify_password(old_password, op_hash)
    return Bootstrap(name=op_name, password=old_password if keep else None, token=token, created=False)


def rotate_bootstrap(sessions: sessionmaker[Session], name: str | None = None) -> Bootstrap:
    """A new bootstrap token (the CLI's `augnet console token --rotate`): for `name`, or for whoever holds
    the current one, or for `admin`. The old token stops working (a running console within TOKEN_CACHE_TTL_S)."""
    with sessions.begin() as s:
        if name is None:
            holder = s.scalar(select(Operator).join(ApiToken).where(ApiToken.kind == q.TOKEN_BOOTSTRAP))
            name = holder.name if holder is not None else "admin"
        op = q.get_operator(s, name)
        if op.role is not Role.ADMIN:
            raise q.Conflict(f"{name} is {op.role.value}: the bootstrap token belongs to an admin")
        token = q.rotate_bootstrap_token(s, SYSTEM_ACTOR, op)
    return Bootstrap(name=name, password=None, token=token, created=False)


def issue_operator_token(sessions: sessionmaker[Session], name: str, actor: str = SYSTEM_ACTOR,
                         lifetime: dt.timedelta | None = LOGIN_TOKEN_LIFETIME) -> str:
    """A new token for an existing operator (the CLI's `augnet console token`)."""
    with sessions.begin() as s:
        op = q.get_operator(s, name)
        token = q.issue_token(s, op, lifetime)
        q.audit(s, actor, "token.issue", name,
                lifetime_s=None if lifetime is None else int(lifetime.total_seconds()))
    return token
