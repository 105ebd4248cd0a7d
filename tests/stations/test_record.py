"""Recording: same seed -> same bytes; the RTCM stream decodes (pyrtcm, RTKLIB convbin) to the
same observables as the RINEX file; truth and atmosphere files line up with the observations."""

from __future__ import annotations

import csv
import hashlib
import json
import subprocess
from collections import Counter

import numpy as np
import pytest
from pyrtcm import RTCMReader

from augnet.gnss.rinex.nav import read_nav
from augnet.gnss.rinex.obs import read_obs
from stations.record import record
from stations.scenario import load_scenario
from tests.conftest import require_tool


def _digest(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def demo_recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    sc = load_scenario("demo").model_copy(update=dict(duration_s=30.0))
    summary = record(sc, out)
    return sc, out, summary


def test_files_written(demo_recording):
    sc, out, summary = demo_recording
    names = {p.name for p in out.iterdir()}
    ids = [s.id for s in sc.stations] + [t.id for t in sc.trains]
    for rid in ids:
        assert f"{rid}.obs" in names and f"{rid}.rtcm3" in names
    assert {"nav.rnx", "truth.csv", "atmosphere.csv", "scenario.json"} <= names
    resolved = json.loads((out / "scenario.json").read_text())
    assert resolved["errors"]["ionosphere_resolved"]["vtec_tecu"] == 15.0
    assert resolved["seed"] == sc.seed


@pytest.mark.slow
def test_same_seed_same_bytes(demo_recording, tmp_path):
    sc, out, _ = demo_recording
    record(sc, tmp_path / "again")
    assert _digest(out) == _digest(tmp_path / "again")
    record(sc.model_copy(update=dict(seed=sc.seed + 1)), tmp_path / "other")
    other = _digest(tmp_path / "other")
    assert other["STA1.obs"] != _digest(out)["STA1.obs"]


def test_rtcm_stream_content(demo_recording):
    sc, out, _ = demo_recording
    counts = Counter()
    with open(out / "STA1.rtcm3", "rb") as f:
        for raw, msg in RTCMReader(f):
            counts[msg.identity] += 1
    n = 30
    assert counts["1077"] >= n and counts["1097"] >= n and counts["1127"] >= n
    assert counts["1005"] == n // sc.rtcm_station_interval_s and counts["1033"] == counts["1005"]
    assert counts["1019"] > 0 and counts["1046"] > 0 and counts["1042"] > 0
    with open(out / "G101.rtcm3", "rb") as f:
        train = Counter(msg.identity for _, msg in RTCMReader(f))
    assert "1005" not in train and train["1077"] >= n


def test_nav_file_reads_back(demo_recording):
    _, out, _ = demo_recording
    nav = read_nav(out / "nav.rnx")
    systems = Counter(e.system for e in nav.ephemerides)
    assert systems["G"] >= 27 and systems["E"] >= 24 and systems["C"] >= 32


def test_truth_and_atmosphere_line_up(demo_recording):
    sc, out, _ = demo_recording
    rows = list(csv.DictReader(open(out / "truth.csv")))
    assert len(rows) == 30 * (len(sc.stations) + len(sc.trains))
    trains = [r for r in rows if r["kind"] == "train"]
    assert all(r["track"].startswith("L1-") and float(r["km"]) > 0 for r in trains)
    obs = read_obs(out / "STA2.obs")
    atmo = [r for r in csv.DictReader(open(out / "atmosphere.csv")) if r["receiver"] == "STA2"]
    n_tracked = int((~np.isnan(obs.obs["C1C"]) | ~np.isnan(obs.obs["C2I"])).sum())
    assert len(atmo) == n_tracked
    assert all(float(r["elevation_deg"]) >= sc.elevation_mask_deg for r in atmo)


@pytest.mark.rtklib
def test_convbin_reads_our_rtcm_as_our_rinex(tmp_path):
    convbin = require_tool("convbin")
    sc = load_scenario("baseline-10km").model_copy(update=dict(duration_s=20.0))
    record(sc, tmp_path)
    subprocess.run([convbin, "-r", "rtcm3", "-tr", "2026/03/10 02:00:00", "-v", "3.04", "-od", "-os",
                    "-o", str(tmp_path / "conv.obs"), str(tmp_path / "A.rtcm3")],
                   check=True, capture_output=True, timeout=60)
    ours = read_obs(tmp_path / "A.obs")
    conv = read_obs(tmp_path / "conv.obs")
    assert len(conv.times) == len(ours.times)
    checked = 0
    for typ, tol in (("C1C", 0.002), ("L1C", 0.002), ("C2W", 0.002), ("L2W", 0.002), ("C5Q", 0.002),
                     ("L5Q", 0.002), ("C2I", 0.002), ("L6I", 0.002), ("D1C", 0.002)):
        for j, sat in enumerate(ours.sats):
            if sat not in conv.sats or typ not in conv.obs:
                continue
            a = ours.obs[typ][:, j]
            b = conv.obs[typ][:, conv.sat_index(sat)]
            both = ~np.isnan(a) & ~np.isnan(b)
            if both.any():
                assert np.max(np.abs(a[both] - b[both])) <= tol, (typ, sat)
                checked += both.sum()
    assert checked > 1000


def test_recording_reads_back(demo_recording):
    from stations.recording import load_atmosphere, load_scenario_json, load_truth

    sc, out, _ = demo_recording
    truth = load_truth(out)
    assert set(truth) == {s.id for s in sc.stations} | {t.id for t in sc.trains}
    g = truth["G101"]
    assert g.kind == "train" and len(g.t_gpst) == 30 and g.track[0] == "L1-1"
    assert np.all(np.diff(g.km) > 0.03)  # 160 km/h: 44 m per second
    assert np.allclose(g.at(g.t_gpst[5]), g.ecef_m[5])
    with pytest.raises(KeyError):
        g.at(g.t_gpst[0] + 0.5)
    sta = truth["STA1"]
    assert np.ptp(sta.ecef_m, axis=0).max() == 0.0 and np.isnan(sta.km).all()
    atmo = load_atmosphere(out)
    sel = (atmo["receiver"] == "STA1") & (atmo["sat"] == atmo["sat"][0])
    assert sel.sum() == 30
    assert np.all(atmo["tropo_m"] > 2.0) and np.all(atmo["iono_l1_m"] >= 0.0)
    assert load_scenario_json(out)["name"] == "demo"


def test_msm_keeps_the_phase_through_a_phase_reset_of_kilometres():
    """An unflagged phase reset moves the phase up to 5 km from the code (decision 0272); MSM carries phase within
    1171 m of the rough range, so the station re-aligns it by whole cycles and restarts its lock time, as a real
    receiver's stream must: no phase is lost, and the sent phase changes by whole cycles only at a lock restart."""
    from augnet.gnss.rtcm.codec import MessageReader
    from augnet.gnss.rtcm.msm import MsmMessage
    from augnet.gnss.rtcm.observables import msm_to_observables
    from stations.rtcm_stream import RtcmStreams
    from stations.world import World

    sc = load_scenario("network-70km")
    errors = sc.errors.model_copy(update=dict(phase_resets_per_hour=60.0))  # ~1 reset per satellite-minute
    world = World(sc.model_copy(update=dict(duration_s=120.0, errors=errors)))
    streams = RtcmStreams(world)
    streams.keep_epochs = True
    r = world.receiver_ids.index("NORTH")
    phase, code = [], []
    for blk in world.epochs():
        streams.add(blk)
        phase.append(blk.phase_cyc[:, r])
        code.append(blk.pseudorange_m[:, r])
    phase, code = np.concatenate(phase), np.concatenate(code)
    assert (np.abs(phase * world.wavelength_m - code) > 1171.0).any()  # beyond what MSM carries unaligned
    col = {s: j for j, s in enumerate(world.sats)}
    sent, lock = np.full(phase.shape, np.nan), np.full(phase.shape, np.nan)
    for e, (_, data) in enumerate(streams.epoch_bytes["NORTH"]):
        for msg in MessageReader().feed(data):
            if isinstance(msg, MsmMessage):
                obs = msm_to_observables(msg)
                for k, prn in enumerate(obs.sat_ids):
                    j = col[f"{obs.system}{int(prn):02d}"]
                    for m, sid in enumerate(obs.sig_ids):
                        kk = int(np.flatnonzero(streams._sig_ids[obs.system] == sid)[0])
                        sent[e, j, kk] = obs.phase_cycles[k, m]
                        lock[e, j, kk] = obs.lock_ms[k, m]
    have = np.isfinite(phase)
    assert np.isfinite(sent[have]).all()  # every phase went out valid
    off = phase - sent
    assert np.nanmax(np.abs(off - np.rint(off))) < 0.01  # whole cycles (MSM7 phase resolution ~0.1 mm)
    step = np.abs(np.diff(np.rint(off), axis=0)) > 0
    restarted = np.diff(lock, axis=0) < 0
    assert step.any() and restarted[step].all()


@pytest.mark.rtklib
def test_an_announced_slip_reaches_rtklib_through_the_msm_lock_time(tmp_path):
    """A receiver that announces its slips (errors.by_receiver, decision 0273) restarts the MSM lock time (DF407)
    at each one; RTKLIB reads a lock time that went down as loss of lock (rtcm3.c lossoflock), so convbin's RINEX
    carries the LLI of every slip and reset our RINEX carries, and none where the same receiver keeps them quiet."""
    convbin = require_tool("convbin")
    base = load_scenario("baseline-10km")
    errors = base.errors.model_copy(update=dict(phase_resets_per_hour=30.0, unflagged_slips_per_hour=60.0,
                                                data_gaps_per_hour=0.0))
    sc = base.model_copy(update=dict(duration_s=120.0, errors=errors))
    data = sc.model_dump(mode="json")
    data["errors"]["by_receiver"] = [{"receivers": ["B"], "announced": True}]
    from stations.scenario import parse_scenario

    flagged = {}
    for label, scen in (("quiet", sc), ("announced", parse_scenario(data))):
        out = tmp_path / label
        record(scen, out)
        subprocess.run([convbin, "-r", "rtcm3", "-tr", "2026/03/10 02:00:00", "-v", "3.04", "-od", "-os",
                        "-o", str(out / "conv.obs"), str(out / "B.rtcm3")], check=True, capture_output=True, timeout=60)
        ours, conv = read_obs(out / "B.obs"), read_obs(out / "conv.obs")
        assert np.array_equal(ours.times, conv.times)
        ours_set, conv_set = set(), set()
        for typ in ("L1C", "L2W", "L5Q", "L2I", "L6I"):
            for j, sat in enumerate(ours.sats):
                if sat not in conv.sats:
                    continue
                a, b = ours.lli[typ][:, j], conv.lli[typ][:, conv.sat_index(sat)]
                seen = ~np.isnan(ours.obs[typ][:, j])
                inside = seen & np.r_[False, seen[:-1]]  # not an arc's first epoch
                ours_set |= {(e, sat, typ) for e in np.flatnonzero(inside & ((a & 1) != 0))}
                conv_set |= {(e, sat, typ) for e in np.flatnonzero(inside & ((b & 1) != 0))}
        flagged[label] = (ours_set, conv_set)
    ours_a, conv_a = flagged["announced"]
    print({k: (len(a), len(b)) for k, (a, b) in flagged.items()})
    assert len(ours_a) > 20 and ours_a <= conv_a
    ours_q, conv_q = flagged["quiet"]
    assert not ours_q and len(conv_q) < len(ours_a) / 2  # quiet: only the MSM re-alignments of long resets
