"""A VRS epoch planned ahead (masters, interpolated corrections and geometry from the previous network
epoch, before the epoch's observations exist) is the VRS epoch computed on the spot: for points that kept
their place, points that moved or are new since, and satellites that rose meanwhile."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.network import NetworkSolver
from augnet.centre.vrs import VrsPlan, synthesize
from augnet.gnss.geometry import geodetic_deg_to_ecef
from tests.centre.simdata import recorded_streams, station_epochs
from stations.scenario import load_scenario
from stations.world import World

pytestmark = pytest.mark.slow


EPOCHS = 40  # the network fixes its first ambiguities: the VRS carry interpolated corrections


@pytest.fixture(scope="module")
def solved():
    world = World(load_scenario("network-70km").model_copy(update={"duration_s": EPOCHS}))
    rows = [r for r, rx in enumerate(world.receivers) if not rx.id.startswith("check")]
    net = NetworkSolver({world.receivers[r].id: world.receivers[r].ecef[0] for r in rows})
    epochs, nes = [], []
    for block in world.epochs():
        per = {world.receivers[r].id: station_epochs(world, block, r) for r in rows}
        for e in range(len(block.t_gpst)):
            eps = {name: per[name][e] for name in per}
            epochs.append(eps)
            nes.append(net.update(eps, world.nav))
    return world, epochs, nes


def _points(n: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return geodetic_deg_to_ecef(rng.uniform(39.2, 39.8, n), rng.uniform(116.3, 117.1, n), rng.uniform(20, 80, n))


def _same(a, b):
    assert a.t_gpst == b.t_gpst and list(a.sats) == list(b.sats) and a.master == b.master
    np.testing.assert_array_equal(a.corrected, b.corrected)
    np.testing.assert_array_equal(a.model, b.model)
    np.testing.assert_array_equal(a.lli, b.lli)
    np.testing.assert_array_equal(np.isnan(a.code_m), np.isnan(b.code_m))
    np.testing.assert_allclose(a.code_m, b.code_m, rtol=0, atol=1e-6)  # a micrometre
    np.testing.assert_allclose(a.phase_cyc, b.phase_cyc, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(a.distance_to_master_m, b.distance_to_master_m)


def test_a_plan_made_ahead_gives_the_vrs_made_on_the_spot(solved):
    world, epochs, nes = solved
    ne, now = nes[-2], {k: v for k, v in epochs[-1].items() if v is not None}
    pts = _points(40)
    keys = [f"c{i}" for i in range(40)]
    # planned after the solve of the epoch before, without its data: with its satellites but one
    plan = VrsPlan(ne, world.nav, ne.t_gpst + 1.0, list(now))
    plan.rows_for(pts[:38], keys[:38])
    sats = sorted({str(s) for e in epochs[-2].values() if e is not None for s in e.sats})
    plan.add_sats(sats[1:])  # a satellite that "rises" at epoch 4 for the plan
    # meanwhile client 0 moved and clients 38, 39 are new
    pts2 = pts.copy()
    pts2[0] += [3000.0, -2000.0, 500.0]
    assert plan.fits(ne, world.nav, float(now[next(iter(now))].t_gpst), list(now), None)
    ahead = synthesize(ne, now, pts2, world.nav, plan=plan, keys=keys)
    spot = synthesize(ne, now, pts2, world.nav)
    _same(ahead, spot)
    assert ahead.corrected.any() and len(ahead.sats) > 10
    # rows kept (37 unchanged points), one re-planned for the move, two added
    assert len(plan.points) == 38 + 3


def test_a_plan_that_does_not_fit_is_not_used(solved):
    world, epochs, nes = solved
    ne, now = nes[-2], {k: v for k, v in epochs[-1].items() if v is not None}
    pts = _points(10)
    keys = list(range(10))
    wrong_epoch = VrsPlan(ne, world.nav, ne.t_gpst + 2.0, list(now))
    wrong_epoch.rows_for(pts, keys)
    missing_station = VrsPlan(ne, world.nav, ne.t_gpst + 1.0, sorted(now)[1:])
    missing_station.rows_for(pts, keys)
    spot = synthesize(ne, now, pts, world.nav)
    for plan in (wrong_epoch, missing_station):
        assert not plan.fits(ne, world.nav, ne.t_gpst + 1.0, list(now), None)
        _same(synthesize(ne, now, pts, world.nav, plan=plan, keys=keys), spot)


def test_the_engine_planning_ahead_and_serving_in_groups_sends_the_same_bytes():
    """What the centre process does (plan each next epoch after the solve, and sessions moved or opened
    meanwhile before the epoch comes; encode the sessions a group at a time) changes when the work is done,
    not one byte of any session's stream."""
    from augnet.centre.engine import CentreEngine
    from augnet.gnss.geometry import ecef_to_geodetic

    n = 25
    world, streams, stations = recorded_streams(n)
    pts = _points(9)
    out = []
    for planned in (False, True):
        eng = CentreEngine(stations, world.t0, network_name="t")
        eng.serve_group = 4 if planned else None
        groups = []
        eng.after_serve = groups.append
        got = {i: bytearray() for i in range(len(pts))}
        for i, p in enumerate(pts):
            lat, lon, h = ecef_to_geodetic(p)
            eng.open_session(f"c{i}", np.degrees(lat), np.degrees(lon), h, got[i].extend)
        for e in range(n):
            if e == 12:  # a train moves, one leaves, one arrives
                lat, lon, h = ecef_to_geodetic(pts[0] + [2000.0, 0.0, 0.0])
                eng.move_session("c0", np.degrees(lat), np.degrees(lon), h)
                eng.close_session("c5")
                lat, lon, h = ecef_to_geodetic(pts[5])
                eng.open_session("c9", np.degrees(lat), np.degrees(lon), h, got.setdefault(9, bytearray()).extend)
                if planned:  # as the centre process does between epochs: the moved and the new one planned now
                    plan = eng._plan
                    eng.update_plan()
                    for cid in ("c0", "c9"):
                        np.testing.assert_array_equal(plan.points[plan.keys[cid]], eng.sessions[cid].point_ecef)
            for name in stations:
                eng.feed(name, streams.epoch_bytes[name][e][1], float(e))
            eng.tick(e + 1.0)
            if planned:
                eng.prepare_next()
        if planned:
            assert groups.count(True) == n and groups.count(False) == 2 * n  # 3 groups an epoch, the last True
            assert eng.last.vrs.flags["planned"]  # the plan made after the solve was the one used
        out.append({k: bytes(v) for k, v in got.items()})
    assert out[0] == out[1] and all(len(v) > 1000 for v in out[0].values())
