"""History: network quality samples and the audit log of operator actions."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Query

from augnet.console.deps import DB, Viewer, utc
from augnet.console.schemas import AuditOut, QualityOut
from augnet.store import queries as q

router = APIRouter(tags=["history"])
MAX_QUALITY_SAMPLES = 10_000  # one day of one baseline at 10 s, or a week of a dozen at 10 min
MAX_AUDIT_ENTRIES = 1_000


@router.get("/quality", response_model=list[QualityOut])
def quality(who: Viewer, session: DB,
            subject: Annotated[str | None, Query(max_length=64, pattern=r"^[^\x00]*$", description='"STA1-STA2" or "STA1"')] = None,
            since: Annotated[dt.datetime | None, Query(description="ISO 8601; naive times are UTC")] = None,
            limit: Annotated[int, Query(ge=1, le=MAX_QUALITY_SAMPLES)] = 1000) -> list[QualityOut]:
    """Quality samples, oldest first: fixed fraction, residual RMS [m], satellites, per baseline or station."""
    if since is not None and since.tzinfo is None:
        since = since.replace(tzinfo=dt.timezone.utc)
    return [QualityOut(at=utc(at), subject=subj, fixed_fraction=ff, residual_rms_m=rms, satellites=n)
            for at, subj, ff, rms, n in q.quality_rows(session, subject=subject, since=since, limit=limit)]


@router.get("/audit", response_model=list[AuditOut])
def audit(who: Viewer, session: DB,
          limit: Annotated[int, Query(ge=1, le=MAX_AUDIT_ENTRIES)] = 200) -> list[AuditOut]:
    """Operator actions, newest first."""
    return [AuditOut(id=e.id, at=utc(e.at), actor=e.actor, action=e.action, target=e.target, detail=e.detail or {})
            for e in q.audit_log(session, limit=limit)]
