"""Operator accounts (admin only): list, add, change role / enabled / password."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request, status
from sqlalchemy import func, select

from augnet.console.deps import Admin, DB, Key, field_error
from augnet.console.schemas import OperatorIn, OperatorOut, OperatorPatch
from augnet.store import queries as q
from augnet.store.models import Operator, Role
from augwire.passwords import hash_password

router = APIRouter(prefix="/operators", tags=["operators"])


def _out(op: Operator) -> OperatorOut:
    return OperatorOut(name=op.name, role=op.role, enabled=op.enabled)


@router.get("", response_model=list[OperatorOut])
def list_operators(who: Admin, session: DB) -> list[OperatorOut]:
    return [_out(op) for op in q.list_operators(session)]


@router.post("", response_model=OperatorOut, status_code=status.HTTP_201_CREATED,
             responses={409: {"description": "name taken"}})
def add_operator(body: OperatorIn, who: Admin, session: DB) -> OperatorOut:
    op = q.add_operator(session, who.name, body.name, hash_password(body.password), body.role)
    session.commit()
    return _out(op)


@router.patch("/{name}", response_model=OperatorOut,
              responses={404: {"description": "no such operator"}, 409: {"description": "last admin"}})
def edit_operator(name: Key, body: OperatorPatch, who: Admin, session: DB, request: Request) -> OperatorOut:
    """Change role, enabled flag or password. Disabling or a new password revokes the operator's tokens.
    The last enabled admin can be neither demoted nor disabled (nobody could manage accounts after)."""
    if body.role is None and body.enabled is None and body.password is None:
        raise field_error("role", "give at least one of role, enabled, password")
    op = q.get_operator(session, name)
    loses_admin = op.role is Role.ADMIN and op.enabled and (
        (body.role is not None and body.role is not Role.ADMIN) or body.enabled is False)
    if loses_admin:
        admins = session.scalar(select(func.count()).select_from(Operator).where(
            Operator.role == Role.ADMIN, Operator.enabled.is_(True))) or 0
        if admins <= 1:
            raise HTTPException(status.HTTP_409_CONFLICT, f"{name} is the last enabled admin")
    op = q.update_operator(session, who.name, name, role=body.role, enabled=body.enabled,
                           password_hash=None if body.password is None else hash_password(body.password))
    session.commit()
    request.app.state.token_cache.clear()  # a new role or a revoked token counts from the next request
    return _out(op)
