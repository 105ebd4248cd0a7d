"""The NTRIP caster: its counters, mountpoints (the store's configuration merged with live statistics),
connected clients, and caster users (admins manage them; password hashes never leave the store).

Every change is committed (with its audit entry) first, then announced on the bus
(`augnet.bus.config_events`), so that every running caster re-reads the store within a second (decision
0180); an announcement lost is caught up by the casters' periodic reconcile."""

from __future__ import annotations

import logging

from fastapi import APIRouter, Request, Response, status
from starlette.concurrency import run_in_threadpool

from augnet.bus.config_events import CasterChange, publish_change
from augnet.console.deps import Admin, Key, Live, Viewer, field_error
from augnet.console.live import LiveState, json_safe
from augnet.console.schemas import (
    CasterOut,
    CasterUserIn,
    CasterUserOut,
    CasterUserPatch,
    MountpointIn,
    MountpointOut,
    MountpointPatch,
)
from augnet.store import queries as q
from augnet.store.models import CasterUser, Mountpoint
from augwire.passwords import hash_password

router = APIRouter(prefix="/caster", tags=["caster"])
log = logging.getLogger(__name__)


def _check_format(value: str | None) -> None:
    """The format goes into the sourcetable's STR line: a line end or ';' there would break every client's
    parse of the table (ntrip_caster/sourcetable.py), so only printable ASCII without ';' is taken: 422."""
    if value is not None and not all(" " <= c <= "~" and c != ";" for c in value):
        raise field_error("format", "only printable ASCII without ';' (no line ends or control characters)")


async def _announce(request: Request, kind: str, name: str, action: str) -> None:
    """Tell the casters (on the bus, when this console has one) that `kind` `name` changed in the store."""
    bus = request.app.state.bus
    if bus is None:
        return
    try:
        await publish_change(bus, CasterChange(kind, name, action))
    except Exception:  # noqa: BLE001 - the change is stored; the casters' reconcile picks it up
        log.warning("caster change of %s %s not announced on the bus", kind, name, exc_info=True)


def _snapshot(live: LiveState) -> dict | None:
    return live.caster()


def _tell_system(live: LiveState, kind: str, name: str, change: dict) -> None:
    hook = live.on_caster_change
    if hook is None:
        return
    try:
        hook(kind, name, dict(change))
    except Exception:
        log.exception("caster change hook failed for %s %s", kind, name)


@router.get("", response_model=CasterOut)
async def caster(who: Viewer, live: Live) -> CasterOut:
    snap = _snapshot(live)
    if snap is None:
        return CasterOut(running=False)
    return CasterOut(running=True, started_at=snap.get("started_at"), port=snap.get("port"),
                     clients_now=snap.get("clients_now", 0), connections_now=snap.get("connections_now", 0),
                     counters=json_safe(snap.get("counters", {})), mountpoints_live=len(snap.get("mounts") or {}))


def _mount_out(mp: Mountpoint | None, name: str, stats: dict | None) -> MountpointOut:
    if mp is None:
        stats = json_safe(stats)
        return MountpointOut(name=name, kind=(stats or {}).get("kind", "source"), format=None, read_groups=None,
                             write_groups=None, enabled=True, correction_bound=None, in_store=False, stats=stats)
    stats = json_safe(stats)
    return MountpointOut(name=mp.name, kind=mp.kind, format=mp.format, read_groups=mp.read_groups,
                         write_groups=mp.write_groups, enabled=mp.enabled,
                         correction_bound=bool(mp.correction_bound), in_store=True, stats=stats)


def _read(sessions, query, *args, **kwargs):
    """Run a store query in its own session (in a worker thread: the caller stays on the event loop)."""
    with sessions() as session:
        return query(session, *args, **kwargs)


def _write(sessions, change, *args, **kwargs):
    """Run a store change (it writes its own audit entry) in its own session and commit it (in a worker
    thread); the returned row stays readable (the factory does not expire on commit)."""
    with sessions() as session:
        out = change(session, *args, **kwargs)
        session.commit()
        return out


# Routes that combine the store with the caster's snapshot are async: the snapshot is taken on the event
# loop (where `augnet up` runs the caster, so its dicts are not read while they change); the store is read
# in a worker thread.

@router.get("/mountpoints", response_model=list[MountpointOut])
async def mountpoints(who: Viewer, live: Live, request: Request) -> list[MountpointOut]:
    snap = _snapshot(live)
    mounts = dict((snap or {}).get("mounts") or {})
    stored = await run_in_threadpool(_read, request.app.state.sessions, q.list_mountpoints)
    out = [_mount_out(mp, mp.name, mounts.pop(mp.name, None)) for mp in stored]
    out += [_mount_out(None, name, stats) for name, stats in sorted(mounts.items())]
    return out


@router.post("/mountpoints", response_model=MountpointOut, status_code=status.HTTP_201_CREATED,
             responses={409: {"description": "name taken"}})
async def add_mountpoint(body: MountpointIn, who: Admin, live: Live, request: Request) -> MountpointOut:
    _check_format(body.format)
    mp = await run_in_threadpool(_write, request.app.state.sessions, q.add_mountpoint, who.name, body.name,
                                 body.kind, body.format, body.read_groups, body.write_groups,
                                 body.correction_bound)
    _tell_system(live, "mountpoint", mp.name, {"action": "add", **body.model_dump()})
    await _announce(request, "mountpoint", mp.name, "add")
    return _mount_out(mp, mp.name, None)


@router.patch("/mountpoints/{name}", response_model=MountpointOut, responses={404: {"description": "no such mountpoint"}})
async def edit_mountpoint(name: Key, body: MountpointPatch, who: Admin, live: Live, request: Request) -> MountpointOut:
    given = body.model_dump(exclude_unset=True)
    if not given:
        raise field_error("kind", "give at least one field to change")
    for field, value in given.items():
        if value is None:
            raise field_error(field, "may not be null")
    _check_format(given.get("format"))
    mp = await run_in_threadpool(_write, request.app.state.sessions, q.update_mountpoint, who.name, name, **given)
    _tell_system(live, "mountpoint", name, {"action": "edit", **given})
    await _announce(request, "mountpoint", name, "edit")
    return _mount_out(mp, name, None)


@router.get("/clients", response_model=list[dict])
async def clients(who: Viewer, live: Live) -> list[dict]:
    """Connected NTRIP clients as the caster reports them (id, ip, user, mount, version, bytes out, last GGA
    position, serving base); empty when no caster runs in this process."""
    snap = _snapshot(live)
    return json_safe(list((snap or {}).get("clients") or []))


def _user_out(u: CasterUser, counts: dict[str, int]) -> CasterUserOut:
    return CasterUserOut(name=u.name, groups=u.groups, enabled=u.enabled, connected_clients=counts.get(u.name, 0))


def _client_counts(live: LiveState) -> dict[str, int]:
    counts: dict[str, int] = {}
    for c in (_snapshot(live) or {}).get("clients") or []:
        if c.get("user"):
            counts[c["user"]] = counts.get(c["user"], 0) + 1
    return counts


@router.get("/users", response_model=list[CasterUserOut])
async def users(who: Viewer, live: Live, request: Request) -> list[CasterUserOut]:
    counts = _client_counts(live)
    stored = await run_in_threadpool(_read, request.app.state.sessions, q.list_caster_users)
    return [_user_out(u, counts) for u in stored]


@router.post("/users", response_model=CasterUserOut, status_code=status.HTTP_201_CREATED,
             responses={409: {"description": "name taken"}})
async def add_user(body: CasterUserIn, who: Admin, live: Live, request: Request) -> CasterUserOut:
    password_hash = await run_in_threadpool(hash_password, body.password)  # scrypt: tens of ms, off the loop
    u = await run_in_threadpool(_write, request.app.state.sessions, q.add_caster_user, who.name, body.name,
                                password_hash, body.groups)
    _tell_system(live, "user", u.name, {"action": "add", "groups": u.groups, "password_hash": u.password_hash})
    await _announce(request, "user", u.name, "add")
    return _user_out(u, {})


def _edit_user(sessions, actor: str, name: str, given: dict) -> CasterUser:
    pw = given.get("password")
    password_hash = None if pw is None else hash_password(pw)  # scrypt: tens of ms, off the loop
    with sessions() as session:
        u = q.update_caster_user(session, actor, name, groups=given.get("groups"), enabled=given.get("enabled"),
                                 password_hash=password_hash)
        session.commit()
        return u


@router.patch("/users/{name}", response_model=CasterUserOut, responses={404: {"description": "no such user"}})
async def edit_user(name: Key, body: CasterUserPatch, who: Admin, live: Live, request: Request) -> CasterUserOut:
    given = body.model_dump(exclude_unset=True)
    if not given:
        raise field_error("groups", "give at least one field to change")
    for field, value in given.items():
        if value is None:
            raise field_error(field, "may not be null")
    u = await run_in_threadpool(_edit_user, request.app.state.sessions, who.name, name, given)
    _tell_system(live, "user", name, {"action": "edit", "groups": u.groups, "enabled": u.enabled,
                                      "password_hash": u.password_hash})
    await _announce(request, "user", name, "edit")
    return _user_out(u, _client_counts(live))


@router.delete("/mountpoints/{name}", status_code=status.HTTP_204_NO_CONTENT,
               responses={404: {"description": "no such mountpoint"},
                          409: {"description": "a registered station streams to it"}})
async def delete_mountpoint(name: Key, who: Admin, live: Live, request: Request) -> Response:
    """The mountpoint leaves the store and the sourcetable; its readers are closed (admin)."""
    await run_in_threadpool(_write, request.app.state.sessions, q.delete_mountpoint, who.name, name)
    _tell_system(live, "mountpoint", name, {"action": "delete"})
    await _announce(request, "mountpoint", name, "delete")
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.delete("/users/{name}", status_code=status.HTTP_204_NO_CONTENT,
               responses={404: {"description": "no such user"}})
async def delete_user(name: Key, who: Admin, live: Live, request: Request) -> Response:
    await run_in_threadpool(_write, request.app.state.sessions, q.delete_caster_user, who.name, name)
    _tell_system(live, "user", name, {"action": "delete"})
    await _announce(request, "user", name, "delete")
    return Response(status_code=status.HTTP_204_NO_CONTENT)
