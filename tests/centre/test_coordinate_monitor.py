"""The centre's monitor of published station coordinates (coordinate_monitor.py, decision 0254).

Fast tests feed it baseline epochs whose fixed DD residuals are the geometry of a station offset (unit vectors
from the simulator's broadcast orbits) plus noise; the slow test runs the centre engine on simulated station
streams with one station published 10 cm off (the path the campaign and `augnet up` share)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from augnet.centre import coordinate_monitor as cm
from augnet.gnss.ephemeris import transit
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation, enu_to_ecef

NOISE_M = 0.004  # white DD phase residual noise of the synthetic baselines (a few mm, like the simulator's)


@pytest.fixture(scope="module")
def sky():
    """Broadcast orbits and four stations of the network-70km scenario."""
    from stations.scenario import load_scenario
    from stations.world import World

    world = World(load_scenario("network-70km").model_copy(update={"duration_s": 2.0}))
    xyz = {r.id: r.ecef[0].copy() for r in world.receivers if not r.id.startswith("check")}
    return world.nav, xyz, float(world.t0), list(world.sats)


def _epochs(sky, offsets: dict, edges, seconds: float, rng, interval_s: float = 5.0, start_s: float = 0.0):
    """Network epochs whose baselines' fixed DD residuals are (u_j - u_r) . (d_b - d_a) + noise."""
    nav, xyz, t0, sats = sky
    names = list(xyz)
    for t in t0 + start_s + np.arange(0.0, seconds, interval_s):
        baselines = {}
        for a, b in edges:
            tr = transit(nav, sats, xyz[b], t)
            llh = ecef_to_geodetic(xyz[b])
            rot = enu_rotation(llh[0], llh[1])
            u = np.asarray(tr.line_of_sight)
            up = u @ rot[2]
            vis = np.flatnonzero(np.asarray(tr.valid) & (up > np.sin(np.radians(20))))
            s = np.array(sats)[vis]
            uv = u[vis]
            d = enu_to_ecef(np.asarray(offsets.get(b, (0, 0, 0)), float), xyz[b]).reshape(3) - \
                enu_to_ecef(np.asarray(offsets.get(a, (0, 0, 0)), float), xyz[a]).reshape(3)
            res = np.zeros(len(s))
            refs = {}
            for system in sorted({x[0] for x in s}):  # per system, its highest satellite is the reference
                k = np.flatnonzero(np.char.startswith(s.astype(str), system))
                ref = int(k[np.argmax(up[vis][k])])
                refs[system] = str(s[ref])
                res[k] = (uv[k] - uv[ref]) @ d + rng.normal(0.0, NOISE_M, len(k))
                res[ref] = 0.0
            baselines[f"{a}-{b}"] = SimpleNamespace(sats=s, fixed=np.ones(len(s), bool), dd_trop_m=res, refs=refs)
        yield SimpleNamespace(t_gpst=float(t), stations=names, station_xyz_m=np.array([xyz[n] for n in names]),
                              baselines=baselines)


SQUARE = [("NORTH", "EAST"), ("EAST", "SOUTH"), ("SOUTH", "WEST"), ("WEST", "NORTH")]


def _run(mon, sky, offsets, edges=SQUARE, seconds=120.0, seed=1, start_s=0.0):
    raised = []
    for ne in _epochs(sky, offsets, edges, seconds, np.random.default_rng(seed), start_s=start_s):
        raised += [(ne.t_gpst, a) for a in mon.update(ne, sky[0])]
    return raised


def test_an_offset_station_is_flagged_its_neighbours_are_not(sky):
    mon = cm.StationCoordinateMonitor()
    raised = _run(mon, sky, {"EAST": (0.04, -0.03, 0.06)})
    assert [(a.kind, a.subject, a.severity) for _, a in raised] == [(cm.KIND, "EAST", "critical")]
    assert mon.excluded == {"EAST"}
    est = mon.offsets["EAST"].offset_enu_m
    assert np.allclose(est[:2], (0.04, -0.03), atol=0.01)
    # a full window is the evidence: not before WINDOW_SAMPLES samples
    t_first = raised[0][0] - sky[2]
    assert t_first >= (cm.WINDOW_SAMPLES - 1) * cm.SAMPLE_INTERVAL_S
    # its estimated offset is not "unmodelled" any more: the station is excluded
    assert mon.unmodelled_offset("EAST") is None


def test_no_offset_no_alarm(sky):
    mon = cm.StationCoordinateMonitor()
    assert _run(mon, sky, {}, seconds=300.0) == []
    assert mon.verdicts and all(not v.fires for v in mon.verdicts.values())


def test_one_baseline_cannot_say_which_station(sky):
    """Two stations: the baseline fires, but nothing attributes the error to one of them."""
    mon = cm.StationCoordinateMonitor()
    assert _run(mon, sky, {"EAST": (0.0, 0.10, 0.0)}, edges=[("NORTH", "EAST")]) == []
    assert mon.verdicts["NORTH-EAST"].fires
    assert mon.excluded == set()


def test_a_suspect_below_the_threshold_widens_the_bound(sky):
    """An offset too small to flag yet large against the noise is handed to the correction bound."""
    mon = cm.StationCoordinateMonitor()
    _run(mon, sky, {"EAST": (0.012, 0.0, 0.0)})
    assert mon.excluded == set()
    got = mon.unmodelled_offset("EAST")
    assert got is not None and abs(got[0][0] - 0.012) < 0.006
    assert mon.unmodelled_offset("WEST") is None  # far from its neighbours' noise: nothing to add


def test_corrected_coordinates_clear_the_alarm(sky):
    mon = cm.StationCoordinateMonitor()
    _run(mon, sky, {"EAST": (0.0, 0.10, 0.0)})
    assert mon.excluded == {"EAST"}
    raised = _run(mon, sky, {}, start_s=120.0)  # the operator fixed the published position
    assert [(a.subject, a.cleared) for _, a in raised] == [("EAST", True)]
    assert mon.excluded == set()


@pytest.mark.slow
def test_engine_excludes_a_station_published_10_cm_off():
    """The centre engine on simulated streams, WEST published 10 cm north of its antenna: a station-coordinates
    alarm on the bus, and a VRS session at WEST is served from another station from then on."""
    import json

    from augnet.centre.engine import CentreEngine
    from tests.centre.simdata import recorded_streams

    duration = 150
    world, streams, stations = recorded_streams(duration)
    published = dict(stations)
    published["WEST"] = stations["WEST"] + enu_to_ecef(np.array([0.0, 0.10, 0.0]), stations["WEST"]).reshape(3)
    engine = CentreEngine(published, world.t0, network_name="test")
    lat, lon, h = ecef_to_geodetic(stations["WEST"] + enu_to_ecef(np.array([3000.0, 0.0, 0.0]),
                                                                  stations["WEST"]).reshape(3))
    engine.open_session("train", np.degrees(lat), np.degrees(lon), h, lambda b: None)
    alarms, masters = [], []
    now = 0.0
    for e in range(duration):
        for name in stations:
            engine.feed(name, streams.epoch_bytes[name][e][1], now)
        now += 1.0
        for rep in engine.tick(now):
            if rep.vrs is not None:
                masters.append((rep.t_gpst, rep.vrs.master[0]))
        for subject, payload in engine.drain_outbox():
            if subject == "augnet.alarms.test":
                a = json.loads(payload)
                if a["kind"] == cm.KIND:
                    alarms.append(a)
    assert [(a["subject"], a["cleared"]) for a in alarms] == [("WEST", False)]
    t_alarm = alarms[0]["t_gpst"]
    assert any(m == "WEST" for t, m in masters if t < t_alarm)  # its nearest station served it before
    after = [m for t, m in masters if t > t_alarm + 1.0]
    assert after and "WEST" not in after
    assert engine.last.network.vrs_excluded == {"WEST"}
