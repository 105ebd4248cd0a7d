"""The centre service (the loop side of `augnet up`'s centre process) checks every VRS position before the
centre sees it: a refusal reaches the caster as `StreamRefused` and the alarm store through `on_alarm`, once
per episode. No centre process is started: the check is the loop's."""

from __future__ import annotations

import asyncio
import io

import pytest
from pyrtcm import RTCMReader

from augnet.centre.service_area import AREA_ALARM_KIND
from augnet.system.centre_protocol import MoveSession, OpenSession
from augnet.system.centre_service import CentreService, CentreSpec
from augwire.errors import StreamRefused
from ntrip_caster.gga import GgaFix
from tests.ntrip.test_gga_fuzz import INSIDE, STATIONS


def fix(lat, lon, h) -> GgaFix:
    return GgaFix(lat, lon, h, 1, 12, "GN", b"")


def test_loop_side_refuses_raises_one_alarm_and_clears_it():
    loop = asyncio.new_event_loop()
    try:
        raised = []
        spec = CentreSpec({k: tuple(v) for k, v in STATIONS.items()}, 0.0, "catnet")
        svc = CentreService(spec, loop, on_alarm=lambda *a: raised.append(a))
        handle = svc.open("VRS/1", "VRS", fix(*INSIDE), lambda b: None)
        assert isinstance(svc._pending[-1], OpenSession) and not raised
        for i, bad in enumerate([(89.9, 2.0, 0.0), (-41.0, 2.0, 0.0), (41.0, 2.0, 1e308), (41.0, 2.0, float("nan"))]):
            with pytest.raises(StreamRefused) as exc:
                svc.open(f"VRS/{i + 2}", "VRS", fix(*bad), lambda b: None)
            (_, msg), = list(RTCMReader(io.BytesIO(exc.value.data)))
            assert msg.identity == "1029"
        assert not any(isinstance(m, OpenSession) and m.client_id != "VRS/1" for m in svc._pending)
        # a session moving out of the area is closed, and the centre never hears of the bad point
        with pytest.raises(StreamRefused):
            handle.update_position(fix(89.9, 0.0, 0.0))
        assert "VRS/1" not in svc._sinks and not any(isinstance(m, MoveSession) for m in svc._pending)
        assert [(a[0], a[1], a[4]) for a in raised] == [(AREA_ALARM_KIND, "catnet", False)]
        assert svc.area_alarm.refusals == 5
        svc.area_alarm.hold_s = 0.0
        event = svc.area_alarm.poll(loop.time() + 1.0)
        assert event is not None and event[4] is True
    finally:
        loop.close()


def test_settings_configure_the_area():
    from augnet.system.settings import SettingsError, SystemSettings

    area = SystemSettings(service_radius_km=30.0, outside_area="nearest").validate().area()
    assert area.max_distance_m == 30_000.0 and area.outside == "nearest"
    assert SystemSettings().area().max_distance_m is None
    for bad in ({"service_radius_km": 0.0}, {"outside_area": "ignore"}):
        with pytest.raises(SettingsError):
            SystemSettings(**bad).validate()
    spec = CentreSpec({k: tuple(v) for k, v in STATIONS.items()}, 0.0, "catnet", area=area)
    loop = asyncio.new_event_loop()
    try:
        got = bytearray()
        svc = CentreService(spec, loop)
        svc.open("VRS/1", "VRS", fix(41.0, 2.7, 0.0), got.extend)  # ~70 km from GARR: served at GARR, told so
        (_, msg), = list(RTCMReader(io.BytesIO(bytes(got))))
        assert "serving station GARR" in msg.DF140
    finally:
        loop.close()
