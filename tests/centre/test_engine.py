"""The centre's processing core fed with station RTCM bytes, serving VRS sessions through the caster's
stream-factory interface, publishing correction models and alarms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from augnet.centre.engine import CentreEngine, CentreStreamFactory, correction_model_json
from augnet.centre.ingest import StationDecoder
from augnet.gnss.geometry import ecef_to_geodetic
from ntrip_caster.gga import GgaFix
from ntrip_caster.stream_factory import StreamFactory
from tests.centre.simdata import recorded_streams

pytestmark = pytest.mark.slow

DURATION_S = 20


def test_engine_serves_vrs_sessions_from_station_bytes():
    world, streams, stations = recorded_streams(DURATION_S)
    engine = CentreEngine(stations, world.t0, network_name="test")
    factory = CentreStreamFactory(engine)
    assert isinstance(factory, StreamFactory)
    got = bytearray()
    check = world.receivers[world.receiver_ids.index("check1")].ecef[0]
    lat, lon, h = ecef_to_geodetic(check)
    fix = GgaFix(np.degrees(lat), np.degrees(lon), h, 1, 12, "GN", b"")
    handle = factory.open("client-1", "VRS", fix, got.extend)
    # stations deliver epoch by epoch, one of them always a little late
    now = 0.0
    solved = 0
    for e in range(DURATION_S):
        for name in stations:
            t, data = streams.epoch_bytes[name][e]
            engine.feed(name, data, now + (0.3 if name == "WEST" else 0.0))
        now += 1.0
        solved += len(engine.tick(now))
    solved += len(engine.tick(now + 5.0))
    assert solved == DURATION_S
    dec = StationDecoder("VRS", world.t0)
    vrs_epochs = dec.feed(bytes(got)) + dec.flush()
    assert len(vrs_epochs) == DURATION_S
    assert np.linalg.norm(dec.arp_ecef - check) < 0.01
    # the published correction model parses and names the network's stations
    subjects = [s for s, _ in engine.drain_outbox()]
    assert subjects.count("augnet.corrections.test") == DURATION_S
    model = json.loads(correction_model_json(engine.last.network))
    assert set(model["stations"]) == set(stations) and model["master"] in stations
    handle.close()
    assert not engine.sessions
