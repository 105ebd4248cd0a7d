"""Trains: live position, track, along-track km, fix state, correction age, protection levels; the store's
registry and correction-service sessions for one train."""

from __future__ import annotations

import time

from fastapi import APIRouter, HTTPException, status

from augnet.console.deps import DB, Key, Live, Viewer, utc
from augnet.console.live import TrainLive, as_dict
from augnet.console.schemas import TrainDetailOut, TrainOut, TrainSessionOut
from augnet.store import queries as q
from augnet.store.models import Train
from sqlalchemy import select

router = APIRouter(prefix="/trains", tags=["trains"])


def train_out(t: TrainLive, now: float) -> TrainOut:
    d = as_dict(t)
    if d["fix_state"] not in ("fix", "float", "dgps", "single", "none"):
        d["fix_state"] = "none"
    return TrainOut(**d, age_s=max(0.0, now - t.updated_unix))


@router.get("", response_model=list[TrainOut])
async def list_trains(who: Viewer, live: Live) -> list[TrainOut]:
    now = time.time()
    return [train_out(t, now) for t in live.train_list()]


@router.get("/{train_id}", response_model=TrainDetailOut, responses={404: {"description": "unknown train"}})
def get_train(train_id: Key, who: Viewer, session: DB, live: Live) -> TrainDetailOut:
    t = live.trains.get(train_id)
    registered = session.scalar(select(Train).where(Train.code == train_id))
    if t is None and registered is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no train {train_id}")
    sessions = [TrainSessionOut(mountpoint=s.mountpoint, started_at=utc(s.started_at), ended_at=utc(s.ended_at),
                                bytes_sent=s.bytes_sent, fix_rate=s.fix_rate)
                for s in q.train_sessions(session, train_id)] if registered is not None else []
    return TrainDetailOut(id=train_id, live=None if t is None else train_out(t, time.time()),
                          registered=registered is not None,
                          length_m=None if registered is None else registered.length_m, sessions=sessions)
