"""Correction decoding: a real NTRIP capture, garbage in the stream, and the realtime path end to end
(real base observations -> RTCM MSM7 frames -> decoder -> RTK with the real rover -> fixed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.gnss import time as gtime
from augnet.gnss.geometry import ecef_to_enu, geodetic_deg_to_ecef
from augnet.gnss.rtcm import Observables, encode_frame, observables_to_msm, phase_offset_cycles
from augnet.gnss.signals import by_rinex
from augnet.onboard.corrections import CorrectionDecoder
from augnet.onboard.observations import LLI_SLIP, choose_signals, epochs
from augnet.onboard.rtk import RtkFilter, RtkOptions, Status

pytestmark = pytest.mark.shared_data


def test_real_ntrip_capture_gives_base_position_and_one_epoch(shared_data):
    data = (shared_data / "rtcm/ntrip-USCL00CHL0.rtcm3").read_bytes()
    dec = CorrectionDecoder()
    t_ref = gtime.from_calendar(2023, 6, 1)
    out = []
    for i in range(0, len(data), 13):  # odd splits
        out += dec.feed(data[i:i + 13], t_ref)
    out += dec.flush()
    assert dec.base_position_m == pytest.approx([1762489.6191, -5027633.8438, -3496008.8438])
    assert len(out) == 1 and dec.stats.epochs == 1
    ep = out[0]
    # GPS, Galileo and BeiDou MSM (BeiDou's BDT time of week lands on the same GPST epoch)
    assert {s[0] for s in ep.sats} == {"G", "E", "C"}
    assert len(set(ep.sats)) == len(ep.sats)
    ok = np.isfinite(ep.code_m[:, 0])
    assert np.all((ep.code_m[ok, 0] > 1.9e7) & (ep.code_m[ok, 0] < 4.0e7))
    assert set(ep.signal[ep.sats == "C12"][0]) == {"2I", "6I"}


def test_garbage_between_frames_is_counted_not_raised(shared_data):
    data = (shared_data / "rtcm/ntrip-USCL00CHL0.rtcm3").read_bytes()
    rng = np.random.default_rng(0)
    noisy = bytearray()
    for i in range(0, len(data), 200):
        noisy += data[i:i + 200] + bytes(rng.integers(0, 256, 37, dtype=np.uint8))
    noisy[1500] ^= 0xFF  # and a corrupted frame
    dec = CorrectionDecoder()
    out = dec.feed(bytes(noisy), gtime.from_calendar(2023, 6, 1)) + dec.flush()
    # frames cut by garbage fail their CRC and are skipped; the intact ones still decode
    assert 10 <= dec.stats.frames < 35
    assert dec.stats.crc_failures > 0 and dec.reader.stats.bytes_skipped > 0
    assert dec.base_position_m == pytest.approx([1762489.6191, -5027633.8438, -3496008.8438])
    assert all(np.all(np.isfinite(e.wavelength_m[np.isfinite(e.code_m)])) for e in out)


def _msm7_frames(ep, tow_ms, offsets):
    """Encode one base epoch as GPS and Galileo MSM7 frames (the caster's side)."""
    frames = []
    systems = ("G", "E")
    for si, sys_ in enumerate(systems):
        rows = [i for i, s in enumerate(ep.sats) if s[0] == sys_]
        codes = sorted({c for i in rows for c in ep.signal[i] if c}, key=lambda c: by_rinex(sys_, c).msm_id)
        sig_ids = np.array([by_rinex(sys_, c).msm_id for c in codes])
        pr = np.full((len(rows), len(codes)), np.nan)
        cp = np.full_like(pr, np.nan)
        lam = np.array([by_rinex(sys_, c).wavelength_m for c in codes])
        for a, i in enumerate(rows):
            for f, c in enumerate(ep.signal[i]):
                if c:
                    b = codes.index(c)
                    pr[a, b] = ep.code_m[i, f]
                    cp[a, b] = ep.phase_cyc[i, f]
        off = np.array([[offsets.setdefault((ep.sats[i], c), int(v)) for c, v in zip(codes, row)]
                        for i, row in zip(rows, phase_offset_cycles(pr, cp, lam[None, :]))])
        obs = Observables(sys_, np.array([int(ep.sats[i][1:]) for i in rows]), sig_ids, pr, cp - off,
                          np.full_like(pr, np.nan), np.full_like(pr, 45.0), np.full_like(pr, 60000.0),
                          np.zeros(pr.shape, bool))
        frames.append(encode_frame(observables_to_msm(obs, 7, station_id=1, epoch=tow_ms,
                                                      multiple=0 if si == len(systems) - 1 else 1)))
    return frames


@pytest.mark.slow
def test_realtime_path_rtcm_corrections_to_a_fixed_rover(shared_data):
    from augnet.onboard.inputs import load_nav, load_obs

    d = shared_data / "rinex/static-1m-2024"
    nav, _, _ = load_nav([d / "base.nav"])
    systems = ("G", "E")
    base = load_obs(d / "base.obs")
    rover = load_obs(d / "rover.obs")
    b_ep = epochs(base, 2, systems, choose_signals(base, 2, systems))[:20]
    r_ep = epochs(rover, 2, systems, choose_signals(rover, 2, systems))[:20]
    base_pos = geodetic_deg_to_ecef(*(float(v) for v in (d / "base_position.txt").read_text().split()))
    truth = geodetic_deg_to_ecef(*(float(v) for v in (d / "rover_position.txt").read_text().split()))
    dec = CorrectionDecoder(systems)
    flt = RtkFilter(nav, base_pos, RtkOptions(systems=systems))
    offsets: dict = {}
    sols = []
    for be, re_ in zip(b_ep, r_ep):
        _, tow = gtime.week_tow(be.time)
        stream = b"".join(_msm7_frames(be, int(round(float(tow) * 1000)), offsets))
        got = []
        for i in range(0, len(stream), 50):
            got += dec.feed(stream[i:i + 50], re_.time)
        assert len(got) == 1
        assert got[0].time == pytest.approx(be.time, abs=1e-3)
        assert not np.any(got[0].lli & LLI_SLIP)
        sols.append(flt.step(re_, dec.last_epoch))
    assert all(s.status == Status.FIX for s in sols), [s.message for s in sols]
    err = np.array([np.linalg.norm(ecef_to_enu(s.position_m - truth, truth)) for s in sols])
    assert np.max(err) < 0.01
    assert dec.age_s(r_ep[-1].time) == pytest.approx(0.0, abs=1e-3)
    assert math.isinf(CorrectionDecoder().age_s(r_ep[-1].time))


def test_reference_station_indicator_marks_a_vrs_and_the_unit_treats_it_as_one():
    """RTCM 1005/1006 DF141 = 1 (a computed, non-physical station: a network VRS) reaches the filter, which
    then estimates the network's residual ionosphere; a change of base kind restarts it like a new base."""
    from augnet.gnss.ephemeris import NavigationData
    from augnet.gnss.rtcm.station import arp_message
    from augnet.onboard.unit import OnboardUnit

    xyz = geodetic_deg_to_ecef(39.5, 116.7, 30.0)
    msg = arp_message(4001, xyz)
    dec = CorrectionDecoder()
    dec.feed(encode_frame(msg), gtime.from_calendar(2026, 3, 10))
    assert dec.base_position_m == pytest.approx(xyz, abs=1e-3) and not dec.base_non_physical
    msg.fields["DF141"] = 1
    dec.feed(encode_frame(msg), gtime.from_calendar(2026, 3, 10))
    assert dec.base_non_physical
    unit = OnboardUnit(NavigationData([]), xyz)
    assert not unit.rtk.base_is_vrs
    unit.rtk.initialised = True
    unit.set_base_position(dec.base_position_m, non_physical=dec.base_non_physical)
    assert unit.rtk.base_is_vrs and not unit.rtk.initialised  # restarted as a VRS user
    unit.set_base_position(dec.base_position_m)  # unchanged: nothing restarts
    assert unit.rtk.base_is_vrs
