"""Proprietary message 4001 (the centre's correction-error overbound): round trip, sigma rounded up, pyrtcm
parses the frame generically, and our generic decoder (an old client) passes it through as unknown."""

from __future__ import annotations

import numpy as np
import pytest
from pyrtcm import RTCMReader

from augnet.gnss.rtcm import DecodeError, EncodeError, MessageReader, UnknownMessage, decode
from augnet.gnss.rtcm.correction_bound import (
    CORRECTION_BOUND_MESSAGE,
    SIGMA_MAX_M,
    SIGMA_RESOLUTION_M,
    CorrectionBoundMessage,
    decode_correction_bound,
    encode_correction_bound,
    encode_correction_bound_frame,
)
from augwire.rtcm_framing import RtcmStreamReader


def _message(n: int = 12, seed: int = 3) -> CorrectionBoundMessage:
    rng = np.random.default_rng(seed)
    letters = "GECRJ"
    sats = [f"{letters[i % 5]}{1 + (7 * i) % 63:02d}" for i in range(n)]
    sigma = rng.uniform(0.0, 0.2, n)
    sigma[1] = np.nan  # no bound for one satellite
    sigma[2] = 5.0  # beyond the range
    return CorrectionBoundMessage(station_id=4001 % 4096, epoch_ms=345_600_123, train_id=513,
                                  sats=sats, sigma_m=sigma, ionosphere_level_ppm=2.37)


def test_round_trip_keeps_ids_and_rounds_sigma_up():
    msg = _message()
    out = decode_correction_bound(encode_correction_bound(msg))
    assert (out.station_id, out.epoch_ms, out.train_id) == (msg.station_id, msg.epoch_ms, msg.train_id)
    assert out.sats == msg.sats
    assert out.ionosphere_level_ppm == pytest.approx(2.37, abs=0.005)
    ok = np.isfinite(msg.sigma_m) & (msg.sigma_m <= SIGMA_MAX_M)
    assert np.all(out.sigma_m[ok] >= msg.sigma_m[ok])  # an overbound never shrinks in transit
    assert np.all(out.sigma_m[ok] - msg.sigma_m[ok] < SIGMA_RESOLUTION_M + 1e-12)
    assert np.isnan(out.sigma_m[~ok]).all()  # none, or beyond range: unbounded at the rover


def test_frame_through_our_framer_and_pyrtcm():
    data = encode_correction_bound_frame(_message())
    frames = RtcmStreamReader().feed(data)
    assert len(frames) == 1 and frames[0].payload == encode_correction_bound(_message())
    parsed = RTCMReader.parse(data)  # pyrtcm: CRC checked, no layout for 4001, parsed generically
    assert parsed.identity == str(CORRECTION_BOUND_MESSAGE)


def test_old_client_ignores_it():
    data = encode_correction_bound_frame(_message())
    assert isinstance(decode(encode_correction_bound(_message())), UnknownMessage)
    reader = MessageReader()
    msgs = reader.feed(data)
    assert reader.decode_errors == 0 and [m.msg_type for m in msgs] == [CORRECTION_BOUND_MESSAGE]


def test_bad_input_is_a_clear_error():
    msg = _message()
    with pytest.raises(EncodeError):
        encode_correction_bound(CorrectionBoundMessage(1, 0, 1, ["G01", "G02"], np.array([0.01])))
    with pytest.raises(EncodeError):
        encode_correction_bound(CorrectionBoundMessage(1, 0, 1, ["X01"], np.array([0.01])))
    with pytest.raises(EncodeError):
        encode_correction_bound(CorrectionBoundMessage(1, 0, 1, ["G01"], np.array([-0.01])))
    payload = encode_correction_bound(msg)
    with pytest.raises(DecodeError):
        decode_correction_bound(payload[:10])
    with pytest.raises(DecodeError):
        decode_correction_bound(bytes([1006 >> 4, (1006 & 15) << 4]) + bytes(18))
