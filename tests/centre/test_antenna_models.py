"""Receiver antenna models in the centre: the phase-centre correction enters the single differences, the DD
residuals refer to the antenna reference points, and the VRS is for a null antenna."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from augnet.centre.network import NetworkSolver
from augnet.centre.observations import StationEpoch, from_obsdata
from augnet.centre.postprocess import align_epochs, load_network, single_base_epoch
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


def test_vrs_header_is_a_null_antenna_when_every_station_is_modelled(tmp_path):
    from collections import Counter
    from pathlib import Path

    from augnet.centre.postprocess import Station, VrsResult, to_obsdata, write_vrs
    from augnet.gnss.rinex import read_obs

    ep = _epoch("VRS", ["G01", "G02"], np.full((2, 2), 1.0e8), np.full((2, 2), 2.2e7))
    ep.t_gpst = 1.0e9
    point = np.array([4789013.1, 176610.2, 4195034.9])
    ant = offset_antenna()

    def result(modelled):
        stations = [Station(n, Path(f"{n}.obs"), None, point, "test", "TRM41249.00     NONE",
                            ant if n in modelled else None) for n in ("A", "B")]
        return VrsResult(point, stations, [], "A", Counter(A=1), [ep], ["single-base"], [0], 1, 0, {})

    assert to_obsdata(result([])).header.antenna_type == ""
    assert to_obsdata(result(["A"])).header.antenna_type == ""  # B's antenna is still in B-mastered epochs
    hdr = to_obsdata(result(["A", "B"])).header
    assert hdr.antenna_type.split() == ["ADVNULLANTENNA", "NONE"] and hdr.antenna_delta_hen_m == (0.0, 0.0, 0.0)
    back = read_obs(write_vrs(result(["A", "B"]), tmp_path / "vrs.obs")).header
    assert back.antenna_type[:16].strip() == "ADVNULLANTENNA" and any("null antenna" in c for c in back.comments)


def test_live_engine_models_a_station_from_its_1033_descriptor(tmp_path):
    from augnet.centre.engine import CentreEngine
    from augnet.centre.ingest import StationDecoder
    from augnet.gnss.rtcm import encode_frame
    from augnet.gnss.rtcm.station import descriptor_message
    from tests.gnss.test_antex import tiny_antex

    frame = encode_frame(descriptor_message(7, "1234", "TEST1           SCIS", "TRIMBLE NETRS", "1.1"))
    dec = StationDecoder("NORTH", 1.0e9)
    dec.feed(frame)
    assert dec.antenna_descriptor == "TEST1           SCIS" and dec.receiver_descriptor == "TRIMBLE NETRS"
    p = tmp_path / "tiny.atx"
    p.write_text("\n".join(tiny_antex()) + "\n")
    xyz = {"NORTH": np.array([4.0e6, 1.0e5, 4.9e6]), "SOUTH": np.array([4.0e6, 1.5e5, 4.9e6])}
    eng = CentreEngine(xyz, 1.0e9, antex=str(p), antenna_types={"SOUTH": "NOPE"})
    eng.feed("NORTH", frame, 0.0)
    assert eng.network.antennas["NORTH"].radome_fallback  # SCIS not calibrated: NONE's values
    assert all(s.antenna["a"] is eng.network.antennas["NORTH"] for s in eng.network.solvers.values()
               if s.name_a == "NORTH")
    assert "SOUTH" not in eng.network.antennas and any("NOPE" in n for n in eng.antenna_notes)
    plain = CentreEngine(xyz, 1.0e9)  # without an ANTEX file the descriptor is kept, nothing modelled
    plain.feed("NORTH", frame, 0.0)
    assert plain.network.antennas == {} and plain.antenna_types["NORTH"] == "TEST1           SCIS"


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
    inp = load_network(shared / "rinex" / "catnet-2010-077", exclude=("UPC1", "UPC2"),
                       antex=shared / "antex" / "igs05.atx.gz")
    antennas = {s.name: s.antenna for s in inp.stations}
    assert {n: a.type_name for n, a in antennas.items()} == {"CREU": "TRM41249.00", "EBRE": "TRM29659.00",
                                                             "GARR": "TRM41249.00"}
    assert [s.antenna_note for s in inp.stations] == ["", "", ""]
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


CATNET_3H_EPOCHS = 360  # the first 3 h of 30 s data


@pytest.mark.slow
@pytest.mark.shared_data
def test_igs05_on_catnet_changes_no_integer_and_moves_ebre_baselines_iono(catnet):
    """The measurement of decision 0161 (run with -s to print it): IGS05 on the first 3 h changes no integer
    decision; the DD ionosphere moves by ~1 cm RMS on the baselines joining EBRE's TRM29659.00 to the
    TRM41249.00s (their L1-L2 offsets differ by 26 mm), by well under a millimetre between the two TRM41249.00."""
    inp, shared = catnet
    xyz = {s.name: s.xyz_m for s in inp.stations}
    from augnet.gnss.antex import antennas_for, read_antex

    antennas, _ = antennas_for(read_antex(shared / "antex" / "igs05.atx.gz"),
                               {s.name: s.antenna_type for s in inp.stations})
    plain = _run(inp, xyz, None, CATNET_3H_EPOCHS)
    modelled = _run(inp, xyz, antennas, CATNET_3H_EPOCHS)
    rms = {}
    for name in ("CREU-EBRE", "CREU-GARR", "EBRE-GARR"):
        a, b = _fixed_residuals(plain, name), _fixed_residuals(modelled, name)
        both = sorted(set(a) & set(b))
        changed = sum(a[k][0] != b[k][0] for k in both)
        d_iono = np.array([b[k][1] - a[k][1] for k in both])
        d_trop = np.array([b[k][2] - a[k][2] for k in both])
        rms[name] = float(np.sqrt(np.mean(d_iono**2)))
        print(f"{name}: fixed in both {len(both)}, only without {len(set(a) - set(b))}, only with "
              f"{len(set(b) - set(a))}, integers changed {changed}; RMS change DD iono {rms[name] * 1e3:.1f} mm, "
              f"DD non-dispersive {np.sqrt(np.mean(d_trop**2)) * 1e3:.1f} mm")
        assert len(both) > 1000 and changed == 0
    assert 0.005 < rms["CREU-EBRE"] < 0.03 and 0.005 < rms["EBRE-GARR"] < 0.03
    assert rms["CREU-GARR"] < 0.001
