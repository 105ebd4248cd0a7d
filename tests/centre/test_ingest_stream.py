"""Station RTCM streams in, network epochs out; VRS streams out, readable by our decoder, pyrtcm and RTKLIB."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from pyrtcm import RTCMReader

from augnet.centre.ingest import EpochAligner, StationDecoder
from augnet.centre.network import NetworkSolver
from augnet.centre.vrs import synthesize
from augnet.centre.vrs_stream import VrsStreamEncoder
from augnet.gnss.ephemeris import NavigationData
from stations.rtcm_stream import RtcmStreams
from stations.scenario import load_scenario
from stations.world import World
from tests.centre.simdata import station_epochs
from tests.conftest import require_tool

DURATION_S = 30


@pytest.fixture(scope="module")
def sim():
    world = World(load_scenario("network-70km").model_copy(update={"duration_s": DURATION_S}))
    streams = RtcmStreams(world)
    blocks = []
    for blk in world.epochs():
        streams.add(blk)
        blocks.append(blk)
    return world, streams, blocks


@pytest.mark.slow
def test_station_streams_decode_to_the_simulated_observations(sim):
    world, streams, blocks = sim
    ids = world.receiver_ids
    for r, rid in enumerate(ids):
        dec = StationDecoder(rid, world.t0)
        data = bytes(streams.buffers[rid])
        got = []
        for i in range(0, len(data), 977):  # arbitrary chunking, as a socket delivers it
            got += dec.feed(data[i:i + 977])
        got += dec.flush()
        assert dec.stats.undecodable == 0
        assert len(got) == DURATION_S
        assert dec.arp_ecef is not None and np.linalg.norm(dec.arp_ecef - world.receivers[r].ecef[0]) < 1e-3
        assert dec.stats.ephemerides > 0
        want = [e for blk in blocks for e in station_epochs(world, blk, r)]
        for a, b in zip(got, want):
            assert a.t_gpst == pytest.approx(b.t_gpst, abs=1e-6)
            order = {s: k for k, s in enumerate(a.sats)}
            assert set(order) == set(b.sats)
            k = np.array([order[s] for s in b.sats])
            # MSM7 resolution: pseudorange 2^-29 ms (0.6 mm), phase 2^-31 ms (0.14 mm)
            np.testing.assert_allclose(a.code_m[k], b.code_m, atol=1e-3)
            np.testing.assert_allclose(a.phase_cyc[k] * (299792458.0 / a.freq_hz[k]),
                                       b.phase_cyc * (299792458.0 / b.freq_hz), atol=3e-4)


def test_aligner_releases_complete_epochs_and_does_not_wait_forever_for_a_silent_station():
    from augnet.centre.observations import StationEpoch

    def ep(name, t):
        z = np.zeros((1, 2))
        return StationEpoch(name, t, np.array(["G01"]), z, z, np.zeros((1, 2), np.int8), z, z + 1.5e9,
                            np.array([["1C", "2W"]]))

    al = EpochAligner(["A", "B", "C"], max_wait_s=1.0)
    al.add(ep("A", 100.0), now=0.0)
    al.add(ep("B", 100.0), now=0.1)
    assert al.ready(0.2) == []
    al.add(ep("C", 100.0), now=0.3)
    [(t, got)] = al.ready(0.3)
    assert t == 100.0 and set(got) == {"A", "B", "C"}
    al.add(ep("A", 101.0), now=1.0)
    al.add(ep("B", 101.0), now=1.0)
    al.add(ep("A", 102.0), now=2.0)
    [(t, got)] = al.ready(2.1)  # C is silent: epoch 101 goes after the wait, with A and B
    assert t == 101.0 and set(got) == {"A", "B"}
    al.add(ep("C", 101.0), now=2.2)  # too late: that epoch is solved
    assert al.late_dropped == 1


@pytest.mark.slow
def test_vrs_stream_round_trips_and_rtklib_reads_it(sim, tmp_path):
    world, streams, blocks = sim
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    net = NetworkSolver(stations)
    nav = NavigationData(world.ephemerides)
    enc = VrsStreamEncoder()
    points = {"T1": world.receivers[ids.index("check1")].ecef[0], "T2": stations["EAST"] + [3000.0, -2000.0, 500.0]}
    for k, (cid, p) in enumerate(points.items()):
        enc.add(cid, 4000 + k, p)
    out = {cid: bytearray() for cid in points}
    last = None
    for blk in blocks:
        per = {r: station_epochs(world, blk, i) for i, r in enumerate(ids)}
        for e in range(len(blk.t_gpst)):
            eps = {r: per[r][e] for r in stations}
            ne = net.update(eps, nav)
            vrs = synthesize(ne, eps, np.array(list(points.values())), nav)
            for cid, data in enc.encode(list(points), vrs, nav).items():
                out[cid] += data
            last = vrs
    # our decoder reads the VRS stream back to the synthesised values
    dec = StationDecoder("T1", world.t0)
    got = dec.feed(bytes(out["T1"])) + dec.flush()
    assert len(got) == DURATION_S
    assert np.linalg.norm(dec.arp_ecef - points["T1"]) < 1e-3
    v = last.station_epoch(0)
    g = got[-1]
    order = {s: k for k, s in enumerate(g.sats)}
    assert set(order) == set(v.sats)
    k = np.array([order[s] for s in v.sats])
    np.testing.assert_allclose(g.code_m[k], v.code_m, atol=1e-3)
    frac = (g.phase_cyc[k] - v.phase_cyc) % 1.0  # whole-cycle offsets are the stream's own choice
    assert np.all(np.minimum(frac, 1 - frac) < 2e-3)
    # pyrtcm parses every frame
    msgs = list(RTCMReader(__import__("io").BytesIO(bytes(out["T2"]))))
    types = {m[1].identity for m in msgs}
    assert {"1006", "1033", "1077", "1097", "1127"} <= types and {"1019", "1042", "1046"} <= types
    # RTKLIB converts it to RINEX with the VRS position in the header
    convbin = require_tool("convbin")
    src = tmp_path / "vrs.rtcm3"
    src.write_bytes(bytes(out["T1"]))
    run = subprocess.run([convbin, "-r", "rtcm3", "-tr", "2026/03/10 02:00:00", "-od", "-os", "-o",
                          str(tmp_path / "vrs.obs"), str(src)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    text = (tmp_path / "vrs.obs").read_text()
    header = text.split("END OF HEADER")[0]
    xyz = [float(v) for v in next(ln for ln in header.splitlines() if "APPROX POSITION XYZ" in ln).split()[:3]]
    assert np.linalg.norm(np.array(xyz) - points["T1"]) < 0.01
    assert text.count("> 2026") >= DURATION_S - 1
