"""Reference stations: the store's registry merged with what the running system reports.

Admins add, edit and delete stations; operators enable and disable them. Every change is audited (in the
store's transaction), handed to the running system of this process through LiveState.station_changed, and
announced on the bus (`augnet.bus.config_events`) for the centres of other processes: the running network
follows the registry (`augnet.system.station_membership`, decision 0240).
"""

from __future__ import annotations

import logging

import anyio.from_thread
from fastapi import APIRouter, Request, Response, status

from augnet.bus.config_events import CasterChange, publish_change
from augnet.console import geo
from augnet.console.deps import Admin, DB, Key, Live, OperatorRole, Viewer, field_error
from augnet.console.live import LiveState, StationLive
from augnet.console.schemas import StationIn, StationLiveOut, StationOut, StationPatch
from augnet.store import queries as q
from augnet.store.models import Station

router = APIRouter(prefix="/stations", tags=["stations"])
log = logging.getLogger(__name__)
NOT_FOUND = {404: {"description": "no such station"}}


def _along(live: LiveState, lat: float, lon: float) -> float | None:
    line = live.line_summary()
    return geo.along_track_km(line.get("polyline") or [], lat, lon, line.get("length_km"))


def _out(st: Station | None, sl: StationLive | None, live: LiveState) -> StationOut:
    live_out = None if sl is None else StationLiveOut(up=sl.up, last_data_age_s=sl.last_data_age_s,
                                                      satellites=sl.satellites)
    if st is None:  # reported by the system only
        assert sl is not None
        return StationOut(code=sl.id, name="", lat_deg=sl.lat_deg, lon_deg=sl.lon_deg, h_m=sl.h_m, x_m=None,
                          y_m=None, z_m=None, rtcm_station_id=sl.station_id, mountpoint=None, enabled=sl.enabled,
                          along_km=sl.along_km, in_store=False, live=live_out)
    lat, lon, h = geo.to_geodetic_deg(st.x_m, st.y_m, st.z_m)
    along = sl.along_km if sl is not None and sl.along_km is not None else _along(live, lat, lon)
    return StationOut(code=st.code, name=st.name, lat_deg=lat, lon_deg=lon, h_m=h, x_m=st.x_m, y_m=st.y_m,
                      z_m=st.z_m, rtcm_station_id=st.rtcm_station_id, mountpoint=st.mountpoint, enabled=st.enabled,
                      along_km=along, in_store=True, live=live_out)


def _check_rtcm_id(session, live: LiveState, code: str, rtcm_id: int) -> None:
    """Two stations with one RTCM id (DF003) would be one station to every rover and to the centre: 422."""
    taken = [st.code for st in q.list_stations(session) if st.rtcm_station_id == rtcm_id and st.code != code]
    taken += [sl.id for sl in live.station_list() if sl.station_id == rtcm_id and sl.id != code and sl.id not in taken]
    if taken:
        raise field_error("rtcm_station_id", f"RTCM station id {rtcm_id} is already used by station {taken[0]}")


def _tell_system(live: LiveState, code: str, change: dict, request: Request | None = None) -> None:
    """The change is committed; a failing system hook or bus must not turn it into an error for the operator
    (the centres' periodic reconcile picks the change up)."""
    try:
        live.station_changed(code, change)
    except Exception:  # the hook belongs to the running system; log it, keep serving
        log.exception("station change hook failed for %s", code)
    bus = request.app.state.bus if request is not None else None
    if bus is None:
        return
    try:  # these routes run on the thread pool: the bus lives on the app's event loop
        anyio.from_thread.run(publish_change, bus, CasterChange("station", code, str(change.get("action", "edit"))))
    except Exception:  # noqa: BLE001
        log.warning("station change of %s not announced on the bus", code, exc_info=True)


@router.get("", response_model=list[StationOut])
def list_stations(who: Viewer, session: DB, live: Live) -> list[StationOut]:
    stored = q.list_stations(session)
    live_by_code = {s.id: s for s in live.station_list()}
    out = [_out(st, live_by_code.pop(st.code, None), live) for st in stored]
    out += [_out(None, sl, live) for sl in sorted(live_by_code.values(), key=lambda s: s.id)]
    return out


@router.get("/{code}", response_model=StationOut, responses=NOT_FOUND)
def get_station(code: Key, who: Viewer, session: DB, live: Live) -> StationOut:
    sl = live.stations.get(code)
    try:
        st = q.get_station(session, code)
    except q.NotFound:
        if sl is None:
            raise
        st = None
    return _out(st, sl, live)


@router.post("", response_model=StationOut, status_code=status.HTTP_201_CREATED,
             responses={409: {"description": "code taken"}})
def add_station(body: StationIn, who: Admin, session: DB, live: Live, request: Request) -> StationOut:
    _check_rtcm_id(session, live, body.code, body.rtcm_station_id)
    xyz = geo.to_ecef_m(body.lat_deg, body.lon_deg, body.h_m)
    st = q.add_station(session, who.name, body.code, xyz, body.rtcm_station_id, body.mountpoint, body.name)
    session.commit()
    _tell_system(live, st.code, {"action": "add", "enabled": True, "lat_deg": body.lat_deg, "lon_deg": body.lon_deg,
                                 "h_m": body.h_m, "rtcm_station_id": body.rtcm_station_id,
                                 "mountpoint": body.mountpoint, "name": body.name}, request)
    return _out(st, live.stations.get(st.code), live)


@router.patch("/{code}", response_model=StationOut, responses=NOT_FOUND)
def edit_station(code: Key, body: StationPatch, who: Admin, session: DB, live: Live,
                 request: Request) -> StationOut:
    """Change any of name, position (any of lat/lon/h; the others are kept), RTCM id, mountpoint, enabled."""
    given = body.model_dump(exclude_unset=True)
    if not given:
        raise field_error("name", "give at least one field to change")
    for field, value in given.items():
        if value is None:
            raise field_error(field, "may not be null")
    st = q.get_station(session, code)
    if "rtcm_station_id" in given:
        _check_rtcm_id(session, live, code, given["rtcm_station_id"])
    changes = {k: v for k, v in given.items() if k in ("name", "rtcm_station_id", "mountpoint", "enabled")}
    if {"lat_deg", "lon_deg", "h_m"} & given.keys():
        lat, lon, h = geo.to_geodetic_deg(st.x_m, st.y_m, st.z_m)
        x, y, z = geo.to_ecef_m(given.get("lat_deg", lat), given.get("lon_deg", lon), given.get("h_m", h))
        changes.update(x_m=x, y_m=y, z_m=z)
    st = q.update_station(session, who.name, code, **changes)
    session.commit()
    _tell_system(live, code, {"action": "edit", **given}, request)
    return _out(st, live.stations.get(code), live)


@router.delete("/{code}", status_code=status.HTTP_204_NO_CONTENT, responses=NOT_FOUND)
def delete_station(code: Key, who: Admin, session: DB, live: Live, request: Request) -> Response:
    """The station leaves the registry and the running network (admin); its mountpoint stays."""
    q.delete_station(session, who.name, code)
    session.commit()
    _tell_system(live, code, {"action": "delete"}, request)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


def _set_enabled(code: str, enabled: bool, who, session, live: LiveState, request: Request) -> StationOut:
    st = q.get_station(session, code)
    if st.enabled != enabled:
        st = q.update_station(session, who.name, code, enabled=enabled)
        session.commit()
        _tell_system(live, code, {"action": "enable" if enabled else "disable", "enabled": enabled}, request)
    return _out(st, live.stations.get(code), live)


@router.post("/{code}/disable", response_model=StationOut, responses=NOT_FOUND)
def disable_station(code: Key, who: OperatorRole, session: DB, live: Live, request: Request) -> StationOut:
    """Take a station out of the network solution (operator or admin)."""
    return _set_enabled(code, False, who, session, live, request)


@router.post("/{code}/enable", response_model=StationOut, responses=NOT_FOUND)
def enable_station(code: Key, who: OperatorRole, session: DB, live: Live, request: Request) -> StationOut:
    return _set_enabled(code, True, who, session, live, request)
