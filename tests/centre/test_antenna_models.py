"""Receiver antenna models in the centre: the phase-centre correction enters the single differences, the DD
residuals refer to the antenna reference points, and the VRS is for a null antenna."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from augnet.centre.network import NetworkSolver
from augnet.centre.observations import StationEpoch, from_obsdata
from augnet.centre.postprocess import align_epochs, load_network, single_base_epoch, station_antennas
from augnet.centre.satellite_geometry import SatelliteGeometry
from augnet.centre.single_differences import above_mask
from augnet.centre.vrs import synthesize
from augnet.gnss.antex import FrequencyModel, ReceiverAntenna
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.geometry import enu_to_ecef

OFFSET_UP_M = 0.10  # a made-up antenna: its phase centre 10 cm above the ARP on both frequencies, no PCV


def offset_antenna(up_m: float = OFFSET_UP_M) -> ReceiverAntenna:
    zen = np.arange(0.0, 91.0, 5.0)
    f = FrequencyModel(np.array([0.0, 0.0, up_m]), zen, np.zeros(len(zen)))
    return ReceiverAntenna("TEST-OFFSET     NONE", {"G01": f, "G02": f})


def _epoch(name, sats, phase_cyc, code_m):
    n = len(sats)
    f = np.tile([1575.42e6, 1227.60e6], (n, 1))
    return StationEpoch(name, 0.0, np.array(sats), np.asarray(code_m, float), np.asarray(phase_cyc, float),
                        np.zeros((n, 2), np.int8), np.full((n, 2), 45.0), f, np.tile(["1C", "2W"], (n, 1)))


def _geometry(sats, el_deg, antenna_m=None):
    n = len(sats)
    el = np.radians(el_deg)
    return SatelliteGeometry(np.array(sats), np.full(n, 2.2e7), el, np.zeros(n), np.full(n, 3.0), np.ones(n), 0.0,
                             np.ones(n, bool), antenna_m)


def test_single_differences_get_the_antenna_correction_per_frequency():
    sats = ["G01", "G02", "G03"]
    el = [80.0, 40.0, 20.0]
    a = _epoch("A", sats, np.full((3, 2), 1.0e8), np.full((3, 2), 2.2e7))
    b = _epoch("B", sats, np.full((3, 2), 1.0e8 + 5.0), np.full((3, 2), 2.2e7 + 1.0))
    corr = np.array([[0.01, 0.02], [0.03, 0.05], [-0.01, 0.0]])
    plain = above_mask(a, b, _geometry(sats, el), _geometry(sats, el), 10.0)
    zero = above_mask(a, b, _geometry(sats, el), _geometry(sats, el, np.zeros((3, 2))), 10.0)
    with_b = above_mask(a, b, _geometry(sats, el), _geometry(sats, el, corr), 10.0)
    with_a = above_mask(a, b, _geometry(sats, el, corr), _geometry(sats, el), 10.0)
    assert np.array_equal(zero.phase_m, plain.phase_m) and np.array_equal(zero.code_m, plain.code_m)
    # b minus a: b's correction adds, a's subtracts, on code and phase alike
    assert with_b.phase_m - plain.phase_m == pytest.approx(corr, abs=1e-9)
    assert with_b.code_m - plain.code_m == pytest.approx(corr, abs=1e-9)
    assert with_a.phase_m - plain.phase_m == pytest.approx(-corr, abs=1e-9)
    assert with_b.ga.antenna_m is None and with_b.gb.antenna_m.shape == (3, 2)


def test_single_base_vrs_takes_the_masters_antenna_out():
    ep = _epoch("M", ["G01", "G02"], np.full((2, 2), 1.0e8), np.full((2, 2), 2.2e7))
    corr = np.array([[0.05, 0.06], [0.02, 0.03]])

    class _Nav:  # geometry_many needs ephemerides; the shift is tested elsewhere: the same point, no shift
        pass

    from augnet.centre import postprocess

    real = postprocess.geometry_many
    postprocess.geometry_many = lambda sats, t, clk, xyz, nav: (np.zeros((1, len(sats))), np.zeros((1, len(sats))),
                                                                 np.full((1, len(sats)), 0.5))
    try:
        plain = single_base_epoch(ep, np.zeros(3), np.zeros(3), _Nav(), 0.0)
        null = single_base_epoch(ep, np.zeros(3), np.zeros(3), _Nav(), 0.0, corr)
    finally:
        postprocess.geometry_many = real
    assert null.code_m - plain.code_m == pytest.approx(corr, abs=1e-6)
    lam = SPEED_OF_LIGHT_M_S / ep.freq_hz
    assert (null.phase_cyc - plain.phase_cyc) * lam == pytest.approx(corr, abs=1e-7)


# --- real data: catnet-2010-077, a station moved under a known offset antenna -------------------------------

EPOCHS = 100  # 50 min of 30 s data: every baseline fixes within the first half hour (decision 0150)


def _run(inp, xyz, antennas, epochs=EPOCHS):
    net = NetworkSolver(xyz, antennas=antennas)
    times, rows = align_epochs(inp.stations)
    by = {s.name: s for s in inp.stations}
    out = []
    for e in range(min(epochs, len(times))):
        eps = {n: from_obsdata(by[n].obs, int(r[e]), n) for n, r in rows.items() if r[e] >= 0}
        out.append((net.update(eps, inp.nav), eps))
    return out


def _fixed_residuals(run, baseline):
    """{(epoch, sat): (dd integers, dd iono, dd trop, min elevation)} where fixed, references left out."""
    got = {}
    for e, (ne, _) in enumerate(run):
        b = ne.baselines.get(baseline)
        if b is None:
            continue
        for k, s in enumerate(b.sats):
            if b.fixed[k] and s not in b.refs.values():
                ref = b.refs[s[0]]
                kr = int(np.flatnonzero(b.sats == ref)[0])
                got[(e, str(s), ref)] = (tuple(b.dd_n[k]), b.dd_iono_m[k], b.dd_trop_m[k],
                                         b.elevation_b_deg[k], b.elevation_b_deg[kr])
    return got


@pytest.fixture(scope="module")
def catnet(request):
    shared = request.getfixturevalue("shared_data")
    inp = load_network(shared / "rinex" / "catnet-2010-077", exclude=("UPC1", "UPC2"))
    return inp, shared


@pytest.mark.slow
@pytest.mark.shared_data
def test_an_offset_antenna_is_corrected_to_its_reference_point(catnet):
    """GARR told its ARP is 10 cm lower than it is, with an antenna whose phase centre is 10 cm above its ARP:
    the network sees the same phase centre as before, so its integers and DD residuals are those of the plain
    run (to the troposphere model's 10 cm height change, micrometres). Without the antenna model the DD
    non-dispersive residual moves by the offset projected on the two lines of sight."""
    inp, _ = catnet
    xyz = {s.name: s.xyz_m for s in inp.stations}
    lowered = dict(xyz)
    lowered["GARR"] = xyz["GARR"] + enu_to_ecef(np.array([0.0, 0.0, -OFFSET_UP_M]), xyz["GARR"]).reshape(3)
    plain = _fixed_residuals(_run(inp, xyz, None), "CREU-GARR")
    corrected = _fixed_residuals(_run(inp, lowered, {"GARR": offset_antenna()}), "CREU-GARR")
    moved = _fixed_residuals(_run(inp, lowered, None), "CREU-GARR")
    common = sorted(set(plain) & set(corrected) & set(moved))
    assert len(common) > 200  # the baseline fixed most of its satellites over the second half
    d_corr = np.array([[corrected[k][1] - plain[k][1], corrected[k][2] - plain[k][2]] for k in common])
    assert np.abs(d_corr).max() < 1e-4  # iono and trop: the model undoes the offset
    assert all(corrected[k][0] == plain[k][0] for k in common)
    # without the model: DD trop (b = GARR minus a, sat minus ref) grows by -offset (sin el - sin el_ref): the
    # station is modelled lower, so every range is modelled longer by offset * sin(el)
    expected = np.array([-OFFSET_UP_M * (math.sin(math.radians(moved[k][3])) - math.sin(math.radians(moved[k][4])))
                         for k in common])
    d_moved = np.array([moved[k][2] - plain[k][2] for k in common])
    assert np.abs(d_moved - expected).max() < 2e-3  # the residual smoother lags a slowly changing step
    assert np.abs(expected).max() > 0.02  # and the test sees a real change
    assert np.abs([moved[k][1] - plain[k][1] for k in common]).max() < 1e-3  # non-dispersive: no iono change


@pytest.mark.slow
@pytest.mark.shared_data
def test_catnet_antennas_from_the_headers_and_a_null_antenna_vrs(catnet):
    inp, shared = catnet
    antennas, notes = station_antennas(inp.stations, shared / "antex" / "igs05.atx.gz")
    assert {n: a.type_name for n, a in antennas.items()} == {"CREU": "TRM41249.00", "EBRE": "TRM29659.00",
                                                             "GARR": "TRM41249.00"}
    assert notes == []
    run = _run(inp, {s.name: s.xyz_m for s in inp.stations}, antennas, epochs=70)
    ne, eps = run[-1]
    assert set(ne.antenna_m) == {"CREU", "EBRE", "GARR"}
    point = np.array([[4789013.1051, 176610.1545, 4195034.8712]])  # UPC1
    null = synthesize(ne, eps, point, inp.nav)
    as_master = synthesize(dataclasses.replace(ne, antenna_m={}), eps, point, inp.nav)
    master = null.master[0]
    ep = eps[master]
    corr = ne.antenna_correction(ep)
    col = np.searchsorted(null.sats, ep.sats)
    ok = np.isfinite(null.code_m[0, col, 0])
    assert ok.sum() >= 5
    # the VRS observations are the master's referred to its ARP: its phase-centre correction added
    assert (null.code_m[0, col] - as_master.code_m[0, col])[ok] == pytest.approx(corr[ok], abs=1e-6)
    assert np.all(np.abs(corr[ok]) > 0.005)  # TRM antennas: 5-12 cm of up offset, seen from above the mask
