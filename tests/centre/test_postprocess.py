"""`augnet vrs` post-processing: inputs (points, coordinates files, folders), epoch alignment, the single-base
VRS geometry on real Dutch stations, and the command line (clear errors, no tracebacks)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from augnet.centre.postprocess import (
    MIN_NETWORK_DD,
    PostprocessError,
    Station,
    align_epochs,
    load_network,
    parse_point,
    process,
    read_coordinates,
    single_base_epoch,
    station_name,
    summary_lines,
    to_obsdata,
)
from augnet.gnss.geometry import ecef_to_geodetic, geodetic_deg_to_ecef
from augnet.gnss.rinex import read_obs
from augnet.gnss.rinex.obs import ObsHeader, empty_obs, to_rinex3_types

NL = "rinex/nl-network-2021"
L1_WAVELENGTH_M = 299792458.0 / 1575.42e6


def _cli(args):
    from augnet import cli

    cli._mount()
    return CliRunner().invoke(cli.app, args)


# --- points and coordinates ----------------------------------------------------------------------


def test_point_as_geodetic_or_ecef():
    p = parse_point("52.0, 4.5, 50")
    llh = ecef_to_geodetic(p[None])[0]
    assert np.degrees(llh[0]) == pytest.approx(52.0, abs=1e-9)
    assert np.degrees(llh[1]) == pytest.approx(4.5, abs=1e-9)
    assert llh[2] == pytest.approx(50.0, abs=1e-4)
    assert np.allclose(parse_point("3924687.702,301132.766,5001910.775"), [3924687.702, 301132.766, 5001910.775])


@pytest.mark.parametrize("text, words", [("52,4.5", "three numbers"), ("52,x,3", "not numbers"),
                                         ("95,4,0", "out of range"), ("1000000,0,0", "Earth's centre")])
def test_bad_point_is_refused_with_its_text(text, words):
    with pytest.raises(PostprocessError, match=words):
        parse_point(text)


def test_coordinates_file_both_forms_and_comments(tmp_path):
    f = tmp_path / "coords.txt"
    f.write_text("# surveyed\nDELF 3924687.702 301132.766 5001910.775\n\nzegv, 52.0, 4.5, 50  # geodetic\n")
    c = read_coordinates(f)
    assert set(c) == {"DELF", "ZEGV"}
    assert np.allclose(c["ZEGV"], geodetic_deg_to_ecef(52.0, 4.5, 50.0))


def test_coordinates_file_errors_name_file_and_line(tmp_path):
    f = tmp_path / "coords.txt"
    f.write_text("DELF 1 2 3\nZEGV 1 2\n")
    with pytest.raises(PostprocessError, match=r"coords.txt:2"):
        read_coordinates(f)
    f.write_text("# nothing\n")
    with pytest.raises(PostprocessError, match="no stations"):
        read_coordinates(f)


def test_station_names_from_file_names():
    h = ObsHeader(marker_name="DELFT-16")
    from pathlib import Path

    assert station_name(Path("delf0010.21o"), h) == "DELF"
    assert station_name(Path("delf0010.21o.gz"), h) == "DELF"
    assert station_name(Path("DELF00NLD_R_20210010000_01D_30S_MO.rnx"), h) == "DELF"
    assert station_name(Path("NORTH.obs"), h) == "NORTH"


# --- epoch alignment -------------------------------------------------------------------------------


def _station(name, times):
    h = ObsHeader(obs_types={"G": ["C1C", "L1C"]})
    return Station(name, None, empty_obs(h, times, ["G01"]), np.zeros(3), "test")


def test_alignment_keeps_epochs_two_stations_share():
    t0 = 1.3e9
    a = _station("A", t0 + np.arange(0, 60, 1.0))  # 1 s
    b = _station("B", t0 + np.arange(0, 120, 30.0))  # 30 s, runs on after A stops
    c = _station("C", t0 + np.array([0.0, 30.0, 90.0]))  # misses epochs
    times, rows = align_epochs([a, b, c])
    # 0 and 30 s: all three; 90 s: B and C; A's other 58 epochs and B's 60 s epoch have no partner
    assert list(np.round(times - t0)) == [0.0, 30.0, 90.0]
    assert list(rows["A"]) == [0, 30, -1]
    assert list(rows["B"]) == [0, 1, 3]
    assert list(rows["C"]) == [0, 1, 2]


def test_alignment_tolerates_sub_millisecond_tag_differences():
    t0 = 1.3e9
    a = _station("A", t0 + np.array([0.0, 5.0]))
    b = _station("B", t0 + np.array([0.0002, 5.0001]))
    times, rows = align_epochs([a, b])
    assert len(times) == 2 and list(rows["B"]) == [0, 1]


# --- folders ---------------------------------------------------------------------------------------


@pytest.mark.shared_data
def test_folder_errors_are_clear(tmp_path, shared_data):
    with pytest.raises(PostprocessError, match="not a folder"):
        load_network(tmp_path / "missing")
    with pytest.raises(PostprocessError, match="no RINEX navigation file"):
        load_network(tmp_path)
    shutil.copy(shared_data / NL / "cbw10010.21n.gz", tmp_path)
    with pytest.raises(PostprocessError, match="no RINEX observation files"):
        load_network(tmp_path)
    shutil.copy(shared_data / NL / "delf0010.21o", tmp_path)
    with pytest.raises(PostprocessError, match="a network needs at least 2"):
        load_network(tmp_path)
    shutil.copy(shared_data / NL / "zegv0010.21o", tmp_path)
    with pytest.raises(PostprocessError, match="--exclude NOPE"):
        load_network(tmp_path, exclude=["NOPE"])
    (tmp_path / "bad0010.21o").write_text("not rinex\n")
    with pytest.raises(PostprocessError, match="bad0010.21o: named like an observation file but not RINEX"):
        load_network(tmp_path)
    (tmp_path / "bad0010.21o").write_text(f"{'     2.11           OBSERVATION DATA    G':<60}RINEX VERSION / TYPE\n")
    with pytest.raises(PostprocessError, match="bad0010.21o"):  # the RINEX reader's error, with the file
        load_network(tmp_path)


@pytest.mark.shared_data
def test_coordinates_file_overrides_the_header_and_antenna_height_is_added(tmp_path, shared_data):
    d = tmp_path / "net"
    d.mkdir()
    for f in ("delf0010.21o", "zegv0010.21o", "cbw10010.21n.gz"):
        shutil.copy(shared_data / NL / f, d)
    moved = np.array([3924687.702, 301132.766, 5001910.775]) + [10.0, 0.0, 0.0]
    coords = tmp_path / "c.txt"
    coords.write_text(f"DELF {moved[0]} {moved[1]} {moved[2]}\n")
    inp = load_network(d, coords=coords)
    st = {s.name: s for s in inp.stations}
    # DELF's header: ANTENNA: DELTA H/E/N 0.05 up
    up = moved / np.linalg.norm(moved)
    assert np.linalg.norm(st["DELF"].xyz_m - moved) == pytest.approx(0.05, abs=1e-3)
    assert np.dot(st["DELF"].xyz_m - moved, up) == pytest.approx(0.05, abs=2e-3)
    assert "coordinates file" in st["DELF"].source and st["ZEGV"].source == "RINEX header"


@pytest.mark.shared_data
def test_gzip_observation_files_are_read(tmp_path, shared_data):
    import gzip

    for f in ("delf0010.21o", "zegv0010.21o"):
        with open(shared_data / NL / f, "rb") as src, gzip.open(tmp_path / (f + ".gz"), "wb") as dst:
            dst.write(src.read())
    inp = load_network(tmp_path, nav=shared_data / NL / "cbw10010.21n.gz")
    assert sorted(s.name for s in inp.stations) == ["DELF", "ZEGV"]


# --- the single-base geometry on real stations -----------------------------------------------------


@pytest.mark.shared_data
def test_single_base_vrs_at_the_master_reproduces_it(shared_data):
    """Moving DELF's observations to DELF's own position changes nothing; satellites without an ephemeris
    (all but G07 and G08 at 00:00 in cbw10010) cannot be moved and are left out."""
    from augnet.centre.observations import from_obsdata

    inp = load_network(shared_data / NL)
    delf = next(s for s in inp.stations if s.name == "DELF")
    ep = from_obsdata(delf.obs, 0, "DELF")
    out = single_base_epoch(ep, delf.xyz_m, delf.xyz_m[None], inp.nav, 0.0)
    assert list(out.sats) == ["G07", "G08"]
    k = [list(ep.sats).index(s) for s in out.sats]
    assert np.allclose(out.code_m, ep.code_m[k], atol=1e-6, rtol=0)
    assert np.allclose(out.phase_cyc, ep.phase_cyc[k], atol=1e-6, rtol=0)
    moved = single_base_epoch(ep, delf.xyz_m, parse_point("52.0,4.5,50")[None], inp.nav, 0.0)
    assert np.abs(moved.code_m - ep.code_m[k]).min() > 100.0  # 8 km away: the ranges change


@pytest.mark.slow
@pytest.mark.shared_data
def test_real_vrs_at_zegv_matches_zegvs_own_observations(shared_data):
    """ZEGV left out, the network (DELF, WSRA, ROVN) synthesises a VRS at ZEGV's surveyed position from DELF,
    35 km away. Against ZEGV's real observations, the G07-G08 double difference of code is within a few
    metres (receiver noise, multipath, 35 km of atmosphere) while DELF's unshifted code is kilometres off;
    and the DD carrier phase moves by centimetres from epoch to epoch, not by the hundreds of metres the
    geometry moves. (Only G07 and G08 have ephemerides in cbw10010 at 00:00-00:09: the file's other sets
    start at 02:00 or later, so the DD is of those two.)"""
    d = shared_data / NL
    inp = load_network(d, exclude=["ZEGV"])
    zegv = to_rinex3_types(read_obs(d / "zegv0010.21o"))
    delf = next(s for s in inp.stations if s.name == "DELF").obs
    res = process(inp, np.array(zegv.header.approx_position_m))
    assert res.network_epochs == 0 and set(res.vrs_masters) == {"DELF"}
    zi = {round(t): i for i, t in enumerate(zegv.times)}
    di = {round(t): i for i, t in enumerate(delf.times)}
    zs = {s: j for j, s in enumerate(zegv.sats)}
    ds = {s: j for j, s in enumerate(delf.sats)}
    dd_code, dd_raw, dd_phase = [], [], []
    for ep in res.epochs:
        i, j = zi[round(ep.t_gpst)], di[round(ep.t_gpst)]
        k = {s: n for n, s in enumerate(ep.sats)}
        assert {"G07", "G08"} <= set(k)

        def dd(z_type, other, col):
            return ((zegv.obs[z_type][i, zs["G07"]] - other("G07", col))
                    - (zegv.obs[z_type][i, zs["G08"]] - other("G08", col)))

        dd_code.append(dd("C1C", lambda s, c: ep.code_m[k[s], 0], 0))
        dd_phase.append(dd("L1C", lambda s, c: ep.phase_cyc[k[s], 0], 0) * L1_WAVELENGTH_M)
        dd_raw.append(dd("C1C", lambda s, c: delf.obs["C1C"][j, ds[s]], 0))
    dd_code, dd_raw, dd_phase = map(np.array, (dd_code, dd_raw, dd_phase))
    assert len(dd_code) >= 15
    assert np.abs(dd_code).max() < 3.0, dd_code
    assert np.abs(dd_raw).min() > 1000.0  # what the shift took out
    steps = np.abs(np.diff(dd_phase))
    assert np.median(steps) < 0.05, steps  # 30 s apart; one real cycle slip (3 cycles) may show
    assert np.abs(np.diff(dd_raw)).min() > 100.0


# --- command line ----------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.shared_data
def test_cli_on_real_dutch_stations(shared_data, tmp_path):
    """`augnet vrs` end to end on nl-network-2021: it runs, says what it could not solve, and writes RINEX
    3.04 whose header describes the VRS (our reader checks it here; RTKLIB reads it in test_vrs_rtklib)."""
    out = tmp_path / "vrs.obs"
    r = _cli(["vrs", "--record", str(shared_data / NL), "--at", "52.0,4.5,50", "--out", str(out)])
    assert r.exit_code == 0, r.output
    text = r.output
    for name in ("DELF", "ZEGV", "WSRA", "ROVN"):
        assert f"station {name}:" in text
    assert "baseline DELF-ZEGV (35." in text
    assert "no baseline fixed: corrections are single-base geometric shifts only" in text
    assert "network-corrected VRS epochs: 0 of 19" in text
    vrs = read_obs(out)
    h = vrs.header
    assert h.version == pytest.approx(3.04) and h.marker_name == "VRS"
    assert np.allclose(h.approx_position_m, parse_point("52.0,4.5,50"), atol=1e-3)
    assert h.obs_types["G"] == ["C1C", "L1C", "S1C", "C2W", "L2W", "S2W"]
    assert h.interval_s == 30.0 and len(vrs.times) == 19
    assert h.time_of_first_obs == vrs.times[0]
    assert any("VRS" in c and "augnet" in c for c in h.comments)
    assert any("stations: DELF, ROVN, WSRA, ZEGV" in c for c in h.comments)
    assert any("VRS master DELF" in c for c in h.comments)
    assert np.isfinite(vrs.obs["L1C"]).sum() >= 2 * 19


def test_cli_interval_writes_the_rover_rate_between_network_epochs(shared_data, tmp_path):
    """`--interval 1` on nl-network-2021 (30 s): the network's 19 epochs kept as they are, 1 s epochs between
    them, the header's interval and the summary saying how many were interpolated (decision 0222)."""
    plain, dense = tmp_path / "vrs30.obs", tmp_path / "vrs1.obs"
    r30 = _cli(["vrs", "--record", str(shared_data / NL), "--at", "52.0,4.5,50", "--out", str(plain)])
    assert r30.exit_code == 0, r30.output
    assert "VRS written at the network's 30 s" in r30.output and "--interval S" in r30.output
    r = _cli(["vrs", "--record", str(shared_data / NL), "--at", "52.0,4.5,50", "--out", str(dense), "--interval", "1"])
    assert r.exit_code == 0, r.output
    a, b = read_obs(plain), read_obs(dense)
    assert b.header.interval_s == 1.0 and np.all(np.diff(b.times) == 1.0)
    assert b.times[0] == a.times[0] and b.times[-1] == a.times[-1]
    at = {float(x): i for i, x in enumerate(b.times)}
    rows = [at[float(x)] for x in a.times]
    assert np.array_equal(a.obs["L1C"], b.obs["L1C"][rows], equal_nan=True)  # network epochs unchanged
    n_between = len(b.times) - len(a.times)
    assert n_between > 0 and f"{n_between} of them interpolated in time" in r.output
    assert "--interval S writes it at the rover's rate" not in r.output
    assert f"wrote {dense}: {len(b.times)} epochs" in r.output


def test_cli_errors_without_traceback(tmp_path):
    r = _cli(["vrs", "--record", str(tmp_path / "nope"), "--at", "52,4.5,0", "--out", str(tmp_path / "v.obs")])
    assert r.exit_code == 2 and "not a folder" in r.output and "Traceback" not in r.output
    r = _cli(["vrs", "--record", str(tmp_path), "--at", "52,4.5", "--out", str(tmp_path / "v.obs")])
    assert r.exit_code == 2 and "--at" in r.output


def test_summary_states_the_no_fix_case():
    from collections import Counter

    from augnet.centre.postprocess import BaselineSummary, VrsResult

    res = VrsResult(point_ecef_m=parse_point("52,4.5,0"), stations=[], excluded=["check1: rover"], master="A",
                    vrs_masters=Counter({"A": 2}), epochs=[], epoch_mode=[], corrected_sats=[], times_processed=2,
                    skipped_epochs=2, baselines={"A-B": BaselineSummary("A-B", 50.0)})
    lines = "\n".join(summary_lines(res))
    assert "A-B (50.0 km): never solved" in lines
    assert "no baseline fixed" in lines and "not used: check1" in lines
    with pytest.raises(PostprocessError, match="no VRS epoch"):
        to_obsdata(res)


# --- a recording -----------------------------------------------------------------------------------


@pytest.mark.slow
def test_recording_before_any_fix_is_single_base_whatever_the_master(tmp_path):
    """The first 20 s of network-70km: a VRS epoch may claim network corrections only for satellites some
    baseline has fixed -- also with the point's nearest station as network master, where the interpolation
    hands back the master's zero for satellites no baseline fixed (that once made every satellite
    "corrected" from the first epoch). So the choice of master changes nothing about which epochs are
    network epochs, the first epochs (before any ambiguity can be fixed) are single-base, and BeiDou (fixed
    first, in seconds, on these baselines) is what the early network epochs carry. The check receiver is left
    out as a rover, and the VRS keeps the master's satellites above the point."""
    from stations.record import record
    from stations.scenario import load_scenario

    sc = load_scenario("network-70km").model_copy(update={"duration_s": 20})
    record(sc, tmp_path, rtcm=False)
    inp = load_network(tmp_path)
    assert sorted(s.name for s in inp.stations) == ["EAST", "NORTH", "SOUTH", "WEST"]
    assert inp.excluded == ["check1: check receiver (rover), not a reference station"]
    point = parse_point("39.5,116.7,35")
    nearest = min(inp.stations, key=lambda s: np.linalg.norm(s.xyz_m - point)).name
    res = process(inp, point, master=nearest)
    default = process(inp, point)
    assert len(res.epochs) == 20
    assert res.epoch_mode == default.epoch_mode  # the master's zero is never a correction
    assert res.epoch_mode[:5] == ["single-base"] * 5
    assert res.network_epochs < len(res.epochs)
    if res.network_epochs == 0:
        assert "no baseline fixed: corrections are single-base geometric shifts only" in "\n".join(summary_lines(res))
    for ep, mode in zip(res.epochs, res.epoch_mode):  # single-base: the master's sky; network: the corrected
        assert len(ep.sats) >= (20 if mode == "single-base" else MIN_NETWORK_DD + 1)
    # what each epoch carries, counted truthfully: network satellites are the corrected ones, the rest of the
    # written satellite-epochs single-base with a finite error; no float model by default (decision 0230)
    from augnet.centre.vrs_modes import FLOAT_MODEL, NETWORK, SINGLE_BASE

    tally = res.mode_tally
    modes = np.array(res.epoch_mode)
    assert tally.counts[NETWORK] == sum(res.corrected_sats)
    assert tally.counts[SINGLE_BASE] == sum(len(ep.sats) for ep, m in zip(res.epochs, modes) if m == "single-base")
    assert tally.counts[FLOAT_MODEL] == 0
    sig = np.array(res.epoch_sigma_m)
    assert len(sig) == len(res.epochs)
    assert np.all(np.isfinite(sig[modes == "single-base"]) & (sig[modes == "single-base"] > 0))
    assert np.all(np.isnan(sig[modes == "network"]))  # the network's sigma is not estimated: not invented
    summary = "\n".join(summary_lines(res))
    assert f"VRS carries single-base: {tally.counts[SINGLE_BASE]} satellite-epochs" in summary
