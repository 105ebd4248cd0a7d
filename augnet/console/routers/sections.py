"""Train information per section: the section register's trains in order per line section and direction,
and the dispatcher's reorder (operator or admin acting as dispatcher; audited). Decision 0292.

With a system running in this process the register itself answers; without one, the store's last picture
(`section_trains`, read-only: a reorder needs the running register, 503)."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Path, Request, status
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from augnet.console.deps import OperatorRole, Viewer
from augnet.store import queries as q
from augnet.system.section_register import Authority, RegisterError

router = APIRouter(prefix="/sections", tags=["sections"])
MAX_SECTION_ID = 0xFFFE  # RSSP-I section ids are u16, 0xFFFF meaning "the whole line"
MAX_REASON_CHARS = 200
MAX_TRAINS_IN_ORDER = 255  # a SECTION_TRAINS telegram counts its trains in one byte
SectionId = Annotated[int, Path(ge=1, le=MAX_SECTION_ID)]
Direction = Literal["up", "down"]
# RegisterError codes answered 404 (the thing is not there); every other refusal is a 409 conflict
NOT_FOUND_CODES = ("unknown-section", "unknown-train")


class SectionTrainOut(BaseModel):
    train_id: str
    track: str
    km: float
    speed_m_s: float
    length_m: float
    integrity: str
    correction_age_s: float | None
    along_pl_m: float | None
    cross_pl_m: float | None
    hpl_m: float | None
    time_s: float


class SectionOut(BaseModel):
    section: int
    name: str = ""
    direction: Direction
    km_begin: float | None = None
    km_end: float | None = None
    entry: str = ""
    exit: str = ""
    version: int | None = None
    trains: list[SectionTrainOut]  # front (nearest the exit) first


class StationAreaOut(BaseModel):
    name: str
    km_begin: float
    km_end: float


class SectionsOut(BaseModel):
    live: bool  # the running register (True) or the store's last picture (False)
    sections: list[SectionOut]
    stations: list[StationAreaOut] = []
    in_station: dict[str, dict[str, str]] = {}  # train -> {station, track}
    waiting: list[str] = []  # trains reporting inside a section that the register does not hold


class TrainActionIn(BaseModel):
    train_id: str = Field(min_length=1, max_length=32)
    reason: str = Field(min_length=1, max_length=MAX_REASON_CHARS)


class ReorderIn(BaseModel):
    order: list[Annotated[str, Field(min_length=1, max_length=32)]] = Field(max_length=MAX_TRAINS_IN_ORDER)
    reason: str = Field(min_length=1, max_length=MAX_REASON_CHARS)


def _service(request: Request):
    return getattr(request.app.state, "sections", None)


def _stored(request: Request) -> SectionsOut:
    with request.app.state.sessions() as session:
        stored = q.section_trains(session)
    return SectionsOut(live=False, sections=[SectionOut(section=sid, direction=d, trains=trains)
                                             for (sid, d), trains in sorted(stored.items())])


@router.get("", response_model=SectionsOut)
async def list_sections(who: Viewer, request: Request) -> SectionsOut:
    """Every line section and direction with its trains front first, the station areas between them and
    the trains in a station."""
    svc = _service(request)
    if svc is None:
        return await run_in_threadpool(_stored, request)
    snap = svc.snapshot()  # on the event loop, where the register changes: a consistent picture
    return SectionsOut(live=True, sections=snap["sections"], stations=snap["stations"], in_station=snap["in_station"],
                       waiting=snap["waiting"])


@router.get("/{section_id}/{direction}", response_model=SectionOut,
            responses={404: {"description": "no such section"}})
async def get_section(section_id: SectionId, direction: Direction, who: Viewer, request: Request) -> SectionOut:
    svc = _service(request)
    if svc is None:
        out = await run_in_threadpool(_stored, request)
        found = [s for s in out.sections if s.section == section_id and s.direction == direction]
        return found[0] if found else SectionOut(section=section_id, direction=direction, trains=[])
    snap = next((s for s in svc.register.snapshot() if s["section"] == section_id and s["direction"] == direction),
                None)
    if snap is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no section {section_id}")
    return SectionOut(**snap)


def _refusal(exc: RegisterError) -> HTTPException:
    code = status.HTTP_404_NOT_FOUND if exc.code in NOT_FOUND_CODES else status.HTTP_409_CONFLICT
    return HTTPException(code, {"code": exc.code, "message": str(exc)})


async def _audited(request: Request, svc, audit, undo) -> None:
    """The dispatcher's change into the audit log; undone (`undo()`) when the entry cannot be written."""
    def store() -> None:
        with request.app.state.sessions.begin() as session:
            q.audit(session, audit.actor, audit.action, audit.target, reason=audit.reason, before=list(audit.before),
                    after=list(audit.after))

    try:
        await run_in_threadpool(store)
    except Exception as exc:  # noqa: BLE001 - no dispatcher change stands without its audit entry
        undo()
        raise HTTPException(status.HTTP_500_INTERNAL_SERVER_ERROR, "audit entry not written; change undone") from exc


def _running(request: Request):
    svc = _service(request)
    if svc is None:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, "no section register runs in this process")
    return svc


def _section_out(svc, section_id: int, direction: str) -> SectionOut:
    return SectionOut(**next(s for s in svc.register.snapshot()
                             if s["section"] == section_id and s["direction"] == direction))


@router.post("/{section_id}/{direction}/reorder", response_model=SectionOut,
             responses={404: {"description": "no such section or train"}, 409: {"description": "refused"},
                        503: {"description": "no running register"}})
async def reorder(section_id: SectionId, direction: Direction, body: ReorderIn, who: OperatorRole,
                  request: Request) -> SectionOut:
    """The dispatcher's new order of the section's trains (front first), with a reason: the one change to a
    section's order that does not come from a station (operator or admin; audited)."""
    svc = _running(request)
    authority = Authority(who.name, "dispatcher")
    try:
        audit = svc.reorder(section_id, direction, list(body.order), authority, body.reason)
    except RegisterError as exc:
        raise _refusal(exc) from exc
    await _audited(request, svc, audit, lambda: svc.reorder(section_id, direction, list(audit.before), authority,
                                                            "reverted: the audit entry could not be written"))
    return _section_out(svc, section_id, direction)


@router.post("/admit", response_model=SectionOut,
             responses={404: {"description": "no report inside a section"}, 409: {"description": "refused"},
                        503: {"description": "no running register"}})
async def admit(body: TrainActionIn, who: OperatorRole, request: Request) -> SectionOut:
    """A waiting train into the register where its last report puts it (operator or admin; audited)."""
    svc = _running(request)
    authority = Authority(who.name, "dispatcher")
    try:
        audit = svc.admit(body.train_id, authority, body.reason)
    except RegisterError as exc:
        raise _refusal(exc) from exc
    sid, d = svc.register.where(body.train_id)
    await _audited(request, svc, audit, lambda: svc.withdraw(sid, d, body.train_id, authority,
                                                             "reverted: the audit entry could not be written"))
    return _section_out(svc, sid, d)


@router.post("/{section_id}/{direction}/withdraw", response_model=SectionOut,
             responses={404: {"description": "no such section or train"}, 409: {"description": "refused"},
                        503: {"description": "no running register"}})
async def withdraw(section_id: SectionId, direction: Direction, body: TrainActionIn, who: OperatorRole,
                   request: Request) -> SectionOut:
    """A train off the register (lost radio, withdrawn from service; operator or admin; audited). It waits for
    a dispatcher's admission if it reports again."""
    svc = _running(request)
    authority = Authority(who.name, "dispatcher")
    try:
        audit = svc.withdraw(section_id, direction, body.train_id, authority, body.reason)
    except RegisterError as exc:
        raise _refusal(exc) from exc
    await _audited(request, svc, audit, lambda: svc.admit(body.train_id, authority,
                                                          "reverted: the audit entry could not be written"))
    return _section_out(svc, section_id, direction)
