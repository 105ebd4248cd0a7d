"""Alarms: the system raises and clears them in the store; operators list and acknowledge them here."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query

from augnet.console.deps import DB, Live, OperatorRole, Viewer, utc
from augnet.console.schemas import AlarmOut
from augnet.store import queries as q
from augnet.store.models import Alarm

router = APIRouter(prefix="/alarms", tags=["alarms"])
MAX_ALARMS_PER_PAGE = 1000
NOT_FOUND = {404: {"description": "no such alarm"}}
SQL_INTEGER_MAX = 2**31 - 1  # alarm ids are SQL INTEGER (4 bytes on PostgreSQL)
AlarmId = Annotated[int, Path(ge=1, le=SQL_INTEGER_MAX)]


def alarm_out(a: Alarm) -> AlarmOut:
    return AlarmOut(id=a.id, kind=a.kind, subject=a.subject, severity=a.severity, message=a.message, state=a.state,
                    raised_at=utc(a.raised_at), acknowledged_at=utc(a.acknowledged_at),
                    acknowledged_by=a.acknowledged_by, cleared_at=utc(a.cleared_at))


@router.get("", response_model=list[AlarmOut])
def list_alarms(who: Viewer, session: DB, include_cleared: bool = False,
                limit: Annotated[int, Query(ge=1, le=MAX_ALARMS_PER_PAGE)] = 200) -> list[AlarmOut]:
    """Newest first; cleared alarms only when asked."""
    return [alarm_out(a) for a in q.list_alarms(session, include_cleared=include_cleared, limit=limit)]


@router.get("/{alarm_id}", response_model=AlarmOut, responses=NOT_FOUND)
def get_alarm(alarm_id: AlarmId, who: Viewer, session: DB) -> AlarmOut:
    return alarm_out(q.get_alarm(session, alarm_id))


@router.post("/{alarm_id}/acknowledge", response_model=AlarmOut, responses=NOT_FOUND)
def acknowledge(alarm_id: AlarmId, who: OperatorRole, session: DB, live: Live) -> AlarmOut:
    """Acknowledge a raised alarm (operator or admin; audited). Acknowledging an alarm already acknowledged
    or cleared changes nothing and returns it as it is."""
    before = q.get_alarm(session, alarm_id).state
    alarm = q.acknowledge_alarm(session, who.name, alarm_id)
    session.commit()
    out = alarm_out(alarm)
    if alarm.state is not before:
        live.publish({"type": "alarm", "action": "acknowledged", "alarm": out.model_dump(mode="json")})
    return out
