"""The 4001 correction bound in the centre's VRS stream: off unless asked for; when on, every epoch's bytes
end with a 4001 that our decoder reads and pyrtcm parses, and a client that does not know 4001 still gets
every VRS epoch."""

from __future__ import annotations

import numpy as np
import pytest
from pyrtcm import RTCMReader

from augnet.centre.correction_bound import CorrectionBound
from augnet.centre.engine import CentreEngine, CentreStreamFactory
from augnet.centre.ingest import StationDecoder
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.gnss.rtcm import RtcmStreamReader
from augnet.gnss.rtcm.correction_bound import CORRECTION_BOUND_MESSAGE, decode_correction_bound
from ntrip_caster.gga import GgaFix
from tests.centre.simdata import recorded_streams

pytestmark = pytest.mark.slow

DURATION_S = 20


# the recorded run is shorter than the bound's warm-up (MIN_WINDOW_EPOCHS): a shorter one here, so that the
# stream carries finite bounds within it
WARM_UP_EPOCHS = 5


def _serve(**engine_options):
    world, streams, stations = recorded_streams(DURATION_S)
    engine = CentreEngine(stations, world.t0, network_name="test", **engine_options)
    if engine.correction_bound is not None:
        engine.correction_bound = CorrectionBound(min_window_epochs=WARM_UP_EPOCHS)
    got = bytearray()
    check = world.receivers[world.receiver_ids.index("check1")].ecef[0]
    lat, lon, h = ecef_to_geodetic(check)
    CentreStreamFactory(engine).open("client-1", "VRS", GgaFix(np.degrees(lat), np.degrees(lon), h, 1, 12, "GN",
                                                                b""), got.extend)
    now = 0.0
    for e in range(DURATION_S):
        for name in stations:
            engine.feed(name, streams.epoch_bytes[name][e][1], now)
        now += 1.0
        engine.tick(now)
    engine.tick(now + 5.0)
    return world, bytes(got)


def _frames(data: bytes):
    reader = RtcmStreamReader()
    return reader.feed(data) + reader.close()


def test_correction_bound_is_off_by_default():
    _, data = _serve()
    assert data and CORRECTION_BOUND_MESSAGE not in {f.msg_type for f in _frames(data)}


def test_correction_bound_on_sends_4001_that_decoders_read_and_old_clients_skip():
    world, data = _serve(correction_bound=True)
    frames = _frames(data)
    bounds = [decode_correction_bound(f.payload) for f in frames if f.msg_type == CORRECTION_BOUND_MESSAGE]
    assert len(bounds) >= DURATION_S - 1  # one per served epoch (the first waits for the network's first)
    late = bounds[-1]
    assert late.sats and np.isfinite(late.sigma_m).any()  # the window has filled: bounds, not "none"
    finite = late.sigma_m[np.isfinite(late.sigma_m)]
    assert np.all((finite >= 0) & (finite < 1.0))
    # zero only for a system's reference satellite, whose DD correction is zero by construction
    assert np.sum(finite == 0) <= len({s[0] for s in late.sats})
    # pyrtcm parses every frame of the stream, the 4001 generically
    ids = [RTCMReader.parse(f.raw).identity for f in frames]
    assert str(CORRECTION_BOUND_MESSAGE) in ids
    # a client that knows nothing of 4001 (our station decoder) gets every VRS epoch
    dec = StationDecoder("VRS", world.t0)
    assert len(dec.feed(data) + dec.flush()) == DURATION_S
