"""The API refuses what would make the running system lie (issue 19): a second station with an RTCM id
already in use, a mountpoint format that would break the sourcetable's lines. 422, naming the field."""

from __future__ import annotations

import pytest

from augnet.console.live import StationLive
from tests.console.helpers import error_fields
from tests.console.test_stations import NEW_STATION


def test_duplicate_rtcm_station_id_is_refused_on_add_and_edit(sqlite_console):
    c = sqlite_console
    assert c.client.post("/api/stations", json=NEW_STATION, headers=c.as_("ada")).status_code == 201
    twin = dict(NEW_STATION, code="STA8", mountpoint="STA8")
    r = c.client.post("/api/stations", json=twin, headers=c.as_("ada"))
    assert error_fields(r) == {"rtcm_station_id"} and "STA9" in r.text
    other = dict(twin, rtcm_station_id=110)
    assert c.client.post("/api/stations", json=other, headers=c.as_("ada")).status_code == 201
    r = c.client.patch("/api/stations/STA8", json={"rtcm_station_id": 109}, headers=c.as_("ada"))
    assert error_fields(r) == {"rtcm_station_id"}
    # its own id again is no conflict
    assert c.client.patch("/api/stations/STA8", json={"rtcm_station_id": 110}, headers=c.as_("ada")).status_code == 200


def test_rtcm_id_of_a_station_the_system_reports_is_taken_too(sqlite_console):
    c = sqlite_console
    c.live.update_station(StationLive(id="LIVE1", lat_deg=30.0, lon_deg=114.2, h_m=10.0, station_id=109))
    r = c.client.post("/api/stations", json=NEW_STATION, headers=c.as_("ada"))
    assert error_fields(r) == {"rtcm_station_id"} and "LIVE1" in r.text


@pytest.mark.parametrize("fmt", ["RTCM 3.3\r\nSTR;EVIL", "RTCM\n3", "RTCM\r", "RTCM 3;x", "RTCM\t3", "RTCM\x00"])
def test_mountpoint_format_with_line_ends_or_separators_is_refused(sqlite_console, fmt):
    c = sqlite_console
    r = c.client.post("/api/caster/mountpoints", json={"name": "VRS2", "kind": "vrs", "format": fmt},
                      headers=c.as_("ada"))
    assert error_fields(r) == {"format"}
    ok = c.client.post("/api/caster/mountpoints", json={"name": "VRS3", "kind": "vrs", "format": "RTCM 3.3"},
                       headers=c.as_("ada"))
    assert ok.status_code == 201, ok.text
    r = c.client.patch("/api/caster/mountpoints/VRS3", json={"format": fmt}, headers=c.as_("ada"))
    assert error_fields(r) == {"format"}
