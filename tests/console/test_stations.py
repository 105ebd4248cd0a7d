"""Stations: registry + live state, add / edit (admin), enable / disable (operator), audit, system hook."""

from __future__ import annotations

import math

import pytest

from augnet.console.geo import to_ecef_m
from augnet.console.live import StationLive
from augnet.store import queries as q

from tests.console.helpers import error_fields

# A short line along the 30th parallel, ~96 km (0.001 deg of longitude there is 96.4 m).
LINE = {"id": "L1", "length_km": 96.4, "polyline": [[30.0, 114.0], [30.0, 115.0]]}
NEW_STATION = {"code": "STA9", "name": "Wuhan east", "lat_deg": 30.0, "lon_deg": 114.5, "h_m": 35.0,
               "rtcm_station_id": 109, "mountpoint": "STA9"}


def test_add_station_converts_position_audits_and_tells_the_system(console):
    c = console
    c.live.set_line(LINE)
    calls = []
    c.live.on_station_change = lambda code, change: calls.append((code, change))
    r = c.client.post("/api/stations", json=NEW_STATION, headers=c.as_("ada"))
    assert r.status_code == 201, r.text
    st = r.json()
    assert st["code"] == "STA9" and st["in_store"] is True and st["enabled"] is True and st["live"] is None
    assert st["lat_deg"] == pytest.approx(30.0, abs=1e-9) and st["lon_deg"] == pytest.approx(114.5, abs=1e-9)
    assert st["h_m"] == pytest.approx(35.0, abs=1e-4)
    assert (st["x_m"], st["y_m"], st["z_m"]) == pytest.approx(to_ecef_m(30.0, 114.5, 35.0), abs=1e-6)
    assert math.hypot(st["x_m"], st["y_m"], st["z_m"]) == pytest.approx(6_372_800, abs=2_000)
    assert st["along_km"] == pytest.approx(48.2, abs=0.05)  # half way along the line
    assert calls == [("STA9", {"action": "add", "enabled": True, "lat_deg": 30.0, "lon_deg": 114.5, "h_m": 35.0,
                               "rtcm_station_id": 109, "mountpoint": "STA9", "name": "Wuhan east"})]
    with c.sessions() as s:
        e = q.audit_log(s, 1)[0]
        assert (e.actor, e.action, e.target) == ("ada", "station.add", "STA9")
    again = c.client.post("/api/stations", json=NEW_STATION, headers=c.as_("ada"))
    assert again.status_code == 409 and "exists" in again.json()["detail"]


@pytest.mark.parametrize("change, field", [
    ({"lat_deg": 91.0}, "lat_deg"), ({"lon_deg": -180.5}, "lon_deg"), ({"h_m": 20_000.0}, "h_m"),
    ({"rtcm_station_id": 4096}, "rtcm_station_id"), ({"rtcm_station_id": -1}, "rtcm_station_id"),
    ({"code": "bad code"}, "code"), ({"code": ""}, "code"), ({"mountpoint": "a/b"}, "mountpoint"),
    ({"lat_deg": "north"}, "lat_deg"), ({"colour": "red"}, "colour"), ({"code": "X" * 33}, "code"),
])
def test_add_station_invalid_body_422_names_the_field(sqlite_console, change, field):
    body = dict(NEW_STATION, **change)
    r = sqlite_console.client.post("/api/stations", json=body, headers=sqlite_console.as_("ada"))
    assert field in error_fields(r)


def test_add_station_missing_field_422(sqlite_console):
    body = {k: v for k, v in NEW_STATION.items() if k != "rtcm_station_id"}
    r = sqlite_console.client.post("/api/stations", json=body, headers=sqlite_console.as_("ada"))
    assert error_fields(r) == {"rtcm_station_id"}


def test_add_station_nan_is_422(sqlite_console):
    body = dict(NEW_STATION)
    raw = str(body).replace("'", '"').replace("30.0", "NaN")
    r = sqlite_console.client.post("/api/stations", content=raw, headers={**sqlite_console.as_("ada"),
                                                                          "Content-Type": "application/json"})
    assert r.status_code == 422


def test_list_merges_store_and_live(console):
    c = console
    c.live.set_line(LINE)
    with c.sessions.begin() as s:
        q.add_station(s, "fixture", "STA1", to_ecef_m(30.0, 114.0, 20.0), 101, "STA1", "west end")
        q.add_station(s, "fixture", "STA2", to_ecef_m(30.0, 115.0, 20.0), 102, "STA2")
    c.live.update_station(StationLive("STA2", 102, 30.0, 115.0, 20.0, along_km=96.4, up=True, satellites=23,
                                      last_data_age_s=0.4))
    c.live.update_station(StationLive("STA7", 107, 30.0, 114.7, 20.0, along_km=None, up=False))
    r = c.client.get("/api/stations", headers=c.as_("vera"))
    assert r.status_code == 200
    by = {s["code"]: s for s in r.json()}
    assert list(by) == ["STA1", "STA2", "STA7"]
    assert by["STA1"]["live"] is None and by["STA1"]["along_km"] == pytest.approx(0.0, abs=1e-6)
    assert by["STA1"]["name"] == "west end"
    assert by["STA2"]["live"] == {"up": True, "last_data_age_s": 0.4, "satellites": 23}
    assert by["STA2"]["along_km"] == 96.4  # the system's value wins
    assert by["STA7"]["in_store"] is False and by["STA7"]["x_m"] is None
    one = c.client.get("/api/stations/STA2", headers=c.as_("vera")).json()
    assert one == by["STA2"]
    assert c.client.get("/api/stations/STA7", headers=c.as_("vera")).json()["in_store"] is False
    missing = c.client.get("/api/stations/NOPE", headers=c.as_("vera"))
    assert missing.status_code == 404 and "NOPE" in missing.json()["detail"]


def test_disable_enable_by_operator_audited_and_pushed(console):
    c = console
    with c.sessions.begin() as s:
        q.add_station(s, "fixture", "STA1", to_ecef_m(30.0, 114.0, 20.0), 101, "STA1")
    c.live.update_station(StationLive("STA1", 101, 30.0, 114.0, 20.0, up=True))
    calls = []
    c.live.on_station_change = lambda code, change: calls.append((code, change))
    assert c.client.post("/api/stations/STA1/disable", headers=c.as_("vera")).status_code == 403
    r = c.client.post("/api/stations/STA1/disable", headers=c.as_("otto"))
    assert r.status_code == 200 and r.json()["enabled"] is False
    assert c.live.stations["STA1"].enabled is False
    again = c.client.post("/api/stations/STA1/disable", headers=c.as_("otto"))  # no change, no audit
    assert again.status_code == 200
    r = c.client.post("/api/stations/STA1/enable", headers=c.as_("otto"))
    assert r.json()["enabled"] is True
    assert calls == [("STA1", {"action": "disable", "enabled": False}),
                     ("STA1", {"action": "enable", "enabled": True})]
    with c.sessions() as s:
        assert [(e.actor, e.action) for e in q.audit_log(s, 2)] == [("otto", "station.enable"),
                                                                    ("otto", "station.disable")]
    assert c.client.post("/api/stations/NOPE/disable", headers=c.as_("otto")).status_code == 404


def test_edit_station_partial_position_keeps_the_rest(console):
    c = console
    with c.sessions.begin() as s:
        q.add_station(s, "fixture", "STA1", to_ecef_m(30.0, 114.0, 20.0), 101, "STA1")
    r = c.client.patch("/api/stations/STA1", json={"h_m": 25.5, "mountpoint": "STA1B"}, headers=c.as_("ada"))
    assert r.status_code == 200, r.text
    st = r.json()
    assert st["h_m"] == pytest.approx(25.5, abs=1e-4)
    assert st["lat_deg"] == pytest.approx(30.0, abs=1e-9) and st["lon_deg"] == pytest.approx(114.0, abs=1e-9)
    assert st["mountpoint"] == "STA1B" and st["rtcm_station_id"] == 101
    with c.sessions() as s:
        e = q.audit_log(s, 1)[0]
        assert (e.actor, e.action, e.target) == ("ada", "station.edit", "STA1")
        assert e.detail["after"]["mountpoint"] == "STA1B" and "z_m" in e.detail["after"]
    assert c.client.patch("/api/stations/STA1", json={"name": "x"}, headers=c.as_("otto")).status_code == 403
    assert c.client.patch("/api/stations/NOPE", json={"name": "x"}, headers=c.as_("ada")).status_code == 404


@pytest.mark.parametrize("body, field", [({}, "name"), ({"lat_deg": None}, "lat_deg"), ({"h_m": -5000}, "h_m"),
                                         ({"enabled": "maybe"}, "enabled"), ({"code": "STA2"}, "code")])
def test_edit_station_invalid_body_422_names_the_field(sqlite_console, body, field):
    c = sqlite_console
    with c.sessions.begin() as s:
        q.add_station(s, "fixture", "STA1", to_ecef_m(30.0, 114.0, 20.0), 101, "STA1")
    r = c.client.patch("/api/stations/STA1", json=body, headers=c.as_("ada"))
    assert field in error_fields(r)


def test_a_failing_system_hook_does_not_fail_the_committed_change(sqlite_console):
    c = sqlite_console

    def broken(code, change):
        raise RuntimeError("system busy")

    c.live.on_station_change = broken
    r = c.client.post("/api/stations", json=NEW_STATION, headers=c.as_("ada"))
    assert r.status_code == 201
    with c.sessions() as s:
        assert q.get_station(s, "STA9").code == "STA9"


class _RecordingBus:
    def __init__(self):
        self.published = []

    async def publish(self, subject, payload):
        self.published.append((subject, payload))


def test_delete_station_is_admins_audited_told_and_announced(console):
    """Deleting from the registry takes the station out of the running network (issue 19): the system hook
    of this process and, on the bus, the centres of others are told."""
    c = console
    bus = c.client.app.state.bus = _RecordingBus()
    with c.sessions.begin() as s:
        q.add_station(s, "fixture", "STA1", to_ecef_m(30.0, 114.0, 20.0), 101, "STA1")
    calls = []
    c.live.on_station_change = lambda code, change: calls.append((code, change))
    assert c.client.delete("/api/stations/STA1", headers=c.as_("otto")).status_code == 403
    r = c.client.delete("/api/stations/STA1", headers=c.as_("ada"))
    assert r.status_code == 204 and r.content == b""
    assert calls == [("STA1", {"action": "delete"})]
    assert bus.published == [("augnet.config.stations", b'{"kind":"station","name":"STA1","action":"delete"}')]
    with c.sessions() as s:
        assert q.list_stations(s) == []
        e = q.audit_log(s, 1)[0]
        assert (e.actor, e.action, e.target) == ("ada", "station.delete", "STA1") and e.detail["rtcm_station_id"] == 101
    assert c.client.delete("/api/stations/STA1", headers=c.as_("ada")).status_code == 404


def test_a_mountpoint_a_station_streams_to_cannot_be_deleted(console):
    c = console
    with c.sessions.begin() as s:
        q.add_station(s, "fixture", "STA1", to_ecef_m(30.0, 114.0, 20.0), 101, "STA1")
        q.add_mountpoint(s, "fixture", "STA1", "source")
        q.add_mountpoint(s, "fixture", "SPARE", "source")
    r = c.client.delete("/api/caster/mountpoints/STA1", headers=c.as_("ada"))
    assert r.status_code == 409 and "STA1" in r.json()["detail"]
    assert c.client.delete("/api/caster/mountpoints/SPARE", headers=c.as_("otto")).status_code == 403
    assert c.client.delete("/api/caster/mountpoints/SPARE", headers=c.as_("ada")).status_code == 204
    assert c.client.delete("/api/caster/mountpoints/SPARE", headers=c.as_("ada")).status_code == 404
    with c.sessions() as s:
        assert [m.name for m in q.list_mountpoints(s)] == ["STA1"]
        assert q.audit_log(s, 1)[0].action == "mountpoint.delete"
