"""Every supported message type: what we encode, pyrtcm decodes to the same field values, and our
decoder reads back the same message (Hypothesis over random valid contents)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from augnet.gnss.rtcm import (
    DecodeError,
    EncodeError,
    MsmMessage,
    RtcmMessage,
    SUPPORTED_TYPES,
    decode,
    encode,
    encode_frame,
    text_fields,
)
from augnet.gnss.rtcm.layouts import LAYOUTS, msm_kind

from ._support import assert_same_fields, fixed_message_fields, msm_messages, pyrtcm_fields

FIXED_TYPES = sorted(LAYOUTS)
MSM_TYPES = [t for t in SUPPORTED_TYPES if msm_kind(t)]
SETTINGS = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def test_supported_types_cover_the_issue():
    for t in (1005, 1006, 1033, 1019, 1042, 1045, 1046, 1074, 1077, 1094, 1097, 1124, 1127):
        assert t in SUPPORTED_TYPES


@pytest.mark.parametrize("msg_type", FIXED_TYPES)
@SETTINGS
@given(data=st.data())
def test_fixed_messages_against_pyrtcm(msg_type, data):
    fields = data.draw(fixed_message_fields(msg_type))
    raw = encode_frame(RtcmMessage(msg_type, fields))
    assert_same_fields(fields, pyrtcm_fields(raw), f"type {msg_type}")
    back = decode(raw[3:-3])
    assert isinstance(back, RtcmMessage) and back.fields == fields
    assert encode(back) == raw[3:-3]


@pytest.mark.parametrize("msg_type", MSM_TYPES)
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_msm_against_pyrtcm(msg_type, data):
    msg = data.draw(msm_messages(msg_type))
    raw = encode_frame(msg)
    assert_same_fields(msg.to_fields(), pyrtcm_fields(raw), f"type {msg_type}")
    back = decode(raw[3:-3])
    assert isinstance(back, MsmMessage)
    assert back.to_fields() == msg.to_fields()
    assert encode(back) == raw[3:-3]
    assert encode(RtcmMessage(msg_type, msg.to_fields())) == raw[3:-3]  # pyrtcm-style values in


def test_1005_known_station():
    # A station at the RTCM test location style coordinates, checked field by field after pyrtcm.
    fields = {"DF003": 2003, "DF021": 0, "DF022": 1, "DF023": 0, "DF024": 1, "DF141": 0,
              "DF025": -2_180_000.1234, "DF142": 1, "DF001_1": 0, "DF026": 4_380_000.5678, "DF364": 0,
              "DF027": 4_080_000.9012}
    raw = encode_frame(RtcmMessage(1005, fields))
    theirs = pyrtcm_fields(raw)
    assert theirs["DF003"] == 2003
    assert theirs["DF025"] == pytest.approx(-2_180_000.1234, abs=5e-5)
    assert theirs["DF027"] == pytest.approx(4_080_000.9012, abs=5e-5)
    assert len(raw) == 19 + 6  # 1005 is 152 bits


def test_1033_strings_round_trip():
    fields = {"DF003": 17, **text_fields("DF030", "DF029", "TRM59800.00     NONE"), "DF031": 0,
              **text_fields("DF033", "DF032", ""), **text_fields("DF228", "DF227", "AUGNET VRS"),
              **text_fields("DF230", "DF229", "0.1.0"), **text_fields("DF232", "DF231", "SN42")}
    msg = decode(encode(RtcmMessage(1033, fields)))
    assert msg.text("DF228") == "AUGNET VRS" and msg.text("DF030") == "TRM59800.00     NONE"
    assert msg.text("DF033") == ""


def test_encode_rejects_out_of_range_and_missing():
    fields = _example_fixed(1005)
    with pytest.raises(EncodeError, match="DF025"):
        encode(RtcmMessage(1005, fields | {"DF025": 1e8}))  # 38-bit field at 0.1 mm: +-13,743 km
    del fields["DF026"]
    with pytest.raises(EncodeError, match="DF026"):
        encode(RtcmMessage(1005, fields))


def test_msm_encode_rejects_more_than_64_cells():
    msg = MsmMessage(msg_type=1077, station_id=1, epoch=0, sat_ids=np.arange(1, 23), sig_ids=np.array([2, 8, 15]),
                     cell_mask=np.ones((22, 3), bool), rough_ms=np.zeros(22, int), rough_mod=np.zeros(22, int),
                     rough_rate=np.zeros(22, int), fine_pr=np.zeros(66, int), fine_ph=np.zeros(66, int),
                     lock=np.zeros(66, int), half_cycle=np.zeros(66, int), cnr=np.zeros(66, int),
                     fine_rate=np.zeros(66, int))
    with pytest.raises(EncodeError, match="64"):
        encode(msg)


def test_msm_encode_rejects_field_out_of_range():
    msg = MsmMessage(msg_type=1074, station_id=1, epoch=0, sat_ids=np.array([3]), sig_ids=np.array([2]),
                     cell_mask=np.ones((1, 1), bool), rough_ms=np.array([256]), rough_mod=np.array([0]),
                     fine_pr=np.array([0]), fine_ph=np.array([0]), lock=np.array([0]), half_cycle=np.array([0]),
                     cnr=np.array([0]))
    with pytest.raises(EncodeError, match="DF397"):
        encode(msg)


@pytest.mark.parametrize("msg_type", [1005, 1019, 1042, 1046, 1077, 1124])
def test_truncated_payload_is_a_decode_error(msg_type):
    if msg_type in LAYOUTS:
        payload = encode(RtcmMessage(msg_type, _example_fixed(msg_type)))
    else:
        payload = encode(_example_msm(msg_type))
    for cut in (2, len(payload) // 2, len(payload) - 2):
        with pytest.raises(DecodeError):
            decode(payload[:cut])


def _example_fixed(msg_type):
    from augnet.gnss.rtcm.layouts import Repeat

    return {item: 0 for item in LAYOUTS[msg_type] if not isinstance(item, Repeat) and item != "DF002"}


def _example_msm(msg_type):
    nsat, nsig = 10, 2
    kind = msm_kind(msg_type)
    z = np.zeros(nsat * nsig, dtype=np.int64)
    rates = {"rough_rate": np.zeros(nsat, np.int64), "fine_rate": z} if kind[1] in (5, 7) else {}
    return MsmMessage(msg_type=msg_type, station_id=5, epoch=1000, sat_ids=np.arange(1, nsat + 1),
                      sig_ids=np.array([2, 15]), cell_mask=np.ones((nsat, nsig), bool),
                      rough_ms=np.full(nsat, 70), rough_mod=np.zeros(nsat, np.int64), fine_pr=z, fine_ph=z,
                      lock=z, half_cycle=z, cnr=z, **rates)


def test_unknown_type_passes_through():
    payload = bytes([0x3F, 0xE0]) + bytes(10)  # 1022: not interpreted
    msg = decode(payload)
    assert msg.msg_type == 1022 and encode(msg) == payload


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(SUPPORTED_TYPES), st.binary(max_size=200))
def test_decode_of_arbitrary_payload_raises_only_decode_error(msg_type, body):
    # A CRC can be valid over garbage (a buggy sender); decoding must fail cleanly, never crash.
    payload = bytes([msg_type >> 4, ((msg_type & 0xF) << 4) | (body[0] >> 4 if body else 0)]) + body[1:]
    try:
        msg = decode(payload)
    except DecodeError:
        return
    assert msg.msg_type == msg_type


def test_message_reader_counts_undecodable_frames():
    from augnet.gnss.rtcm import MessageReader, frame

    good = encode_frame(_example_msm(1077))
    short = frame(good[3:40])  # a CRC-valid frame holding a truncated 1077
    r = MessageReader()
    msgs = r.feed(b"\x00junk" + short + good + good[:10])
    msgs += r.close()
    assert [m.msg_type for m in msgs] == [1077]
    assert r.decode_errors == 1 and "1077" in r.last_error
    assert r.frames.stats.frames_ok == 2 and r.frames.stats.truncated_bytes == 10
