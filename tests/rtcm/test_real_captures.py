"""Real captures (../shared/data/rtcm, recorded by others): every complete frame decodes; for every
supported type our values equal pyrtcm's and re-encoding gives the identical bytes."""

from __future__ import annotations

import pytest

from augnet.gnss.rtcm import MsmMessage, RtcmMessage, UnknownMessage, decode, encode, msm_to_observables, read_frames
from augnet.gnss.signals import UnknownSignal

from ._support import assert_same_fields, pyrtcm_fields

CAPTURES = ["GMSD7_20121014.rtcm3", "testglo.rtcm3", "ntrip-USCL00CHL0.rtcm3"]


@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize("name", CAPTURES)
def test_capture_decodes_and_reencodes_identically(shared_data, name):
    ff = read_frames(shared_data / "rtcm" / name)
    assert ff.frames and ff.stats.crc_failures == 0
    supported = 0
    for fr in ff.frames:
        msg = decode(fr)
        if isinstance(msg, UnknownMessage):
            assert encode(msg) == fr.payload
            continue
        supported += 1
        ours = msg.fields if isinstance(msg, RtcmMessage) else msg.to_fields()
        assert_same_fields(ours, pyrtcm_fields(fr.raw), f"{name} type {fr.msg_type}")
        assert encode(msg) == fr.payload, f"{name}: {fr.msg_type} re-encodes differently"
        # and from pyrtcm's values: what another decoder reports, our encoder turns back into the bytes
        assert encode(RtcmMessage(fr.msg_type, pyrtcm_fields(fr.raw))) == fr.payload
    assert supported > 0


@pytest.mark.shared_data
def test_gmsd7_partial_last_frame_is_reported(shared_data):
    ff = read_frames(shared_data / "rtcm" / "GMSD7_20121014.rtcm3")
    assert ff.truncated_tail_bytes > 0
    assert {1077, 1087, 1117, 1127, 1019, 1033} <= set(ff.stats.by_type)


@pytest.mark.shared_data
def test_capture_types_seen(shared_data):
    types = {fr.msg_type for fr in read_frames(shared_data / "rtcm" / "ntrip-USCL00CHL0.rtcm3").frames}
    assert {1005, 1006, 1033, 1019, 1042, 1045, 1046, 1077, 1097, 1127} <= types


@pytest.mark.shared_data
def test_real_msm7_observables_are_physical(shared_data):
    # GPS/BeiDou MSM7 of a real receiver: pseudoranges of 20,000-40,000 km, carrier phase equal to
    # the pseudorange within metres (plus an integer ambiguity the receiver set near zero), L1 Doppler
    # within the +-5 kHz a static receiver sees.
    n = 0
    for fr in read_frames(shared_data / "rtcm" / "GMSD7_20121014.rtcm3").frames:
        if fr.msg_type not in (1077, 1127):
            continue
        msg = decode(fr)
        assert isinstance(msg, MsmMessage)
        try:
            obs = msm_to_observables(msg)
        except UnknownSignal:
            continue
        pr = obs.pseudorange_m
        ok = ~(pr != pr)
        assert ((pr[ok] > 1.9e7) & (pr[ok] < 4.2e7)).all()
        lam = obs.wavelengths_m
        dphi = obs.phase_cycles * lam - pr
        assert (abs(dphi[ok & (dphi == dphi)]) < 2000).all()
        dop = obs.doppler_hz[obs.doppler_hz == obs.doppler_hz]
        assert (abs(dop) < 5000).all()
        n += 1
    assert n > 400
