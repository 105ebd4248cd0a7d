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


def test_the_bound_of_a_suspect_masters_sessions_carries_its_offset(sky):
    """Sessions served by a station with an unmodelled offset d get (|u_j . d| + K sqrt(u' C u)) / K more sigma per
    satellite; sessions served by others keep theirs."""
    from augnet.centre.correction_bound import K_CORRECTION_BOUND
    from augnet.centre.engine import CentreEngine

    nav, xyz, t0, sats = sky
    d = np.array([0.03, -0.02, 0.05])
    cov = np.diag([1e-4, 1e-4, 4e-4])
    monitor = SimpleNamespace(unmodelled_offset=lambda s: (d, cov) if s == "EAST" else None)
    tr = transit(nav, sats, xyz["EAST"], t0)
    vis = np.flatnonzero(np.asarray(tr.valid))
    vrs = SimpleNamespace(master=["EAST", "WEST"], sats=np.array(sats)[vis], t_gpst=t0)
    sigma = np.full((2, len(vis)), 0.01)
    engine = SimpleNamespace(coordinates=monitor, stations=xyz, nav=nav)
    out = CentreEngine._with_station_offsets(engine, None, vrs, sigma.copy())
    llh = ecef_to_geodetic(xyz["EAST"])
    u = np.asarray(tr.line_of_sight)[vis] @ enu_rotation(llh[0], llh[1]).T
    want = 0.01 + (np.abs(u @ d) + K_CORRECTION_BOUND * np.sqrt(np.einsum("si,ij,sj->s", u, cov, u))) / K_CORRECTION_BOUND
    assert np.allclose(out[0], want)
    assert np.all(out[0] > 0.01 + np.abs(u @ d) / K_CORRECTION_BOUND - 1e-12)
    assert np.array_equal(out[1], sigma[1])


@pytest.mark.slow
def test_campaign_chain_excludes_a_station_published_8_cm_off():
    """The scenario chain (the centre engine the campaign and `augnet up` share) on the campaign's station-fault
    case, STA3 published (+4, -3, +6) cm off: STA3 alone is flagged during the warm-up, the alarm is on the bus,
    and no train is served from STA3 once the trains start."""
    import json

    from augnet.scenario.campaign import expand, load_campaign
    from augnet.scenario.runner import Chain, WarmUpWorld

    campaign = load_campaign("issue15")
    pair = next(p for p in expand(campaign) if p.case == "demo-station-faults")
    sc = pair.scenario.model_copy(update={"duration_s": 20.0})
    world = WarmUpWorld(sc, campaign.warm_up_s)
    chain = Chain(world, sc, None)
    masters, alarms = [], []
    keep = chain._network_epoch

    def spy(rep):
        if rep.vrs is not None:
            masters.append((rep.t_gpst - world.start_gpst, list(rep.vrs.master)))
        keep(rep)

    chain._network_epoch = spy
    for blk in world.epochs():
        chain.add_block(blk)
        for subject, payload in chain.engine.drain_outbox():
            a = json.loads(payload) if subject.startswith("augnet.alarms.") else {}
            if a.get("kind") == cm.KIND:
                alarms.append(a)
    assert [(a["subject"], a["cleared"]) for a in alarms] == [("STA3", False)]
    assert alarms[0]["t_gpst"] < world.start_gpst  # caught before the trains start
    est = chain.engine.coordinates.offsets["STA3"].offset_enu_m
    assert np.allclose(est[:2], (0.04, -0.03), atol=0.015)
    served = [m for t, ms in masters if t >= 0.0 for m in ms]
    assert served and "STA3" not in served
