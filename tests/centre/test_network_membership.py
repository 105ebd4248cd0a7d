"""Stations joining and leaving a running network (issue 19): the network engine and the centre engine keep
their other baselines' fixed integers, new baselines fix against the simulator's truth, a leaving master and
the VRS sessions it served are re-homed."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.engine import CentreEngine
from augnet.centre.network import MEMBERSHIP_KIND, NetworkSolver
from augnet.gnss.geometry import ecef_to_geodetic, geodetic_deg_to_ecef
from stations.network_truth import true_dd_integers
from stations.scenario import load_scenario
from stations.world import World
from tests.centre.simdata import recorded_streams, station_epochs

pytestmark = pytest.mark.slow

JOIN_AT = 50  # epoch the fourth station joins (the first three have fixed by then: first fix <= 40 s here)
DURATION_S = 110
FIX_WITHIN = 40  # epochs after joining by which its baselines must have fixed (the network's own first fix: 60)


def _fixed(res) -> dict[str, tuple]:
    return {str(s): tuple(res.dd_n[k]) for k, s in enumerate(res.sats) if res.fixed[k]}


@pytest.fixture(scope="module")
def joined():
    sc = load_scenario("network-70km").model_copy(update={"duration_s": DURATION_S})
    world = World(sc)
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    net = NetworkSolver({k: v for k, v in stations.items() if k != "WEST"})
    out = {"before": {}, "after": {}, "wrong": 0, "checked": 0, "first_fix": {}, "changes": []}
    n = 0
    for block in world.epochs():
        per = {r: station_epochs(world, block, i) for i, r in enumerate(ids)}
        for e in range(len(block.t_gpst)):
            if n == JOIN_AT:
                kept = {s.name: id(s) for s in net.solvers.values()}
                out["changes"].append(net.add_station("WEST", stations["WEST"]))
                out["kept_same_solver"] = all(id(s) == kept[s.name] for s in net.solvers.values()
                                              if s.name in kept)
            ne = net.update({r: per[r][e] for r in stations}, world.nav)
            if n == JOIN_AT - 1:
                out["before"] = {k: _fixed(b) for k, b in ne.baselines.items() if b is not None}
            if n == JOIN_AT:
                out["after"] = {k: _fixed(b) for k, b in ne.baselines.items() if b is not None}
            for solver in net.solvers.values():
                res = ne.baselines[solver.name]
                if res is None or "WEST" not in solver.name:
                    continue
                k = np.flatnonzero(res.fixed & ~res.is_reference())
                if k.size:
                    truth = true_dd_integers(world, block, e, ids.index(solver.name_a),
                                             ids.index(solver.name_b), res.sats[k], res.refs)
                    out["checked"] += k.size
                    out["wrong"] += int((~(truth == res.dd_n[k]).all(axis=1)).sum())
                if res.fixed_fraction > 0:
                    out["first_fix"].setdefault(solver.name, n)
            n += 1
    out["net"] = net
    out["last"] = ne
    return out


def test_a_joining_station_gets_baselines_to_its_nearest_and_they_fix_right(joined):
    change = joined["changes"][0]
    assert change.added == ("NORTH-WEST", "SOUTH-WEST")  # its two nearest, as the network's rule picks
    assert set(joined["last"].baselines) == {"NORTH-EAST", "NORTH-SOUTH", "EAST-SOUTH", "NORTH-WEST", "SOUTH-WEST"}
    assert "WEST" in joined["last"].present and "WEST" in joined["last"].stations
    assert set(joined["first_fix"]) == {"NORTH-WEST", "SOUTH-WEST"}
    assert max(joined["first_fix"].values()) <= JOIN_AT + FIX_WITHIN, joined["first_fix"]
    assert joined["checked"] > 100 and joined["wrong"] == 0
    # chained to the master: the new station has DD residuals in the correction model
    row = joined["last"].stations.index("WEST")
    assert np.isfinite(joined["last"].dd_iono_m[row]).sum() >= 4


def test_existing_baselines_keep_their_fixed_integers_across_a_join(joined):
    assert joined["kept_same_solver"]
    before, after = joined["before"], joined["after"]
    assert set(before) == {"NORTH-EAST", "NORTH-SOUTH", "EAST-SOUTH"}
    for name, fixed in before.items():
        assert fixed, f"{name} had nothing fixed before the join"
        same = {s: n for s, n in after[name].items() if s in fixed}
        assert len(same) >= len(fixed) - 1, (name, fixed, after[name])  # a setting satellite may leave
        assert all(fixed[s] == n for s, n in same.items())


def _at(lat, lon):
    return geodetic_deg_to_ecef(lat, lon, 50.0)


def test_membership_errors_are_clear():
    net = NetworkSolver({"A": _at(39.5, 116.3), "B": _at(39.5, 116.7)})
    with pytest.raises(ValueError, match="already in the network"):
        net.add_station("A", _at(39.8, 116.5))
    with pytest.raises(ValueError, match="finite"):
        net.add_station("C", [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="Earth"):
        net.add_station("C", [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="same place"):
        net.add_station("C", _at(39.5, 116.3) + 0.2)
    with pytest.raises(ValueError, match="not in the network"):
        net.remove_station("Z")
    assert net.names == ["A", "B"]  # nothing refused changed the network
    net.remove_station("A")
    assert net.names == ["B"] and net.master == "B" and not net.solvers
    with pytest.raises(ValueError, match="last station"):
        net.remove_station("B")


def test_a_leaving_station_splits_nothing():
    # a chain A - B - C: B leaving would leave A and C apart; the rule's shortest joining baseline is added
    net = NetworkSolver({"A": _at(39.5, 116.3), "B": _at(39.5, 116.65), "C": _at(39.5, 117.0)},
                        edges=[("A", "B"), ("B", "C")])
    change = net.remove_station("B")
    assert change.dropped == ("A-B", "B-C") and change.added == ("A-C",)
    assert [s.name for s in net.solvers.values()] == ["A-C"] and net.master in ("A", "C")


def test_a_moved_station_restarts_only_its_baselines():
    net = NetworkSolver({"A": _at(39.5, 116.3), "B": _at(39.5, 116.65), "C": _at(39.8, 116.5)})
    kept = net.solvers[(0, 1)]
    change = net.move_station("C", _at(39.2, 116.5))
    assert change.action == "move" and set(change.dropped) == {"A-C", "B-C"} and set(change.added) == {"A-C", "B-C"}
    assert net.solvers[(0, 1)] is kept and np.allclose(net.xyz[2], _at(39.2, 116.5))
    with pytest.raises(ValueError, match="same place"):
        net.move_station("C", _at(39.5, 116.3))


ENGINE_S = 45
LEAVE_AT = 30


def test_engine_join_and_leave_rehome_sessions():
    world, streams, stations = recorded_streams(ENGINE_S)
    first = {k: v for k, v in stations.items() if k != "WEST"}
    engine = CentreEngine(first, world.t0, network_name="test")
    west = stations["WEST"]
    lat, lon, h = ecef_to_geodetic(west)
    got = bytearray()
    # 45 km west of the centre: outside the three stations' area, inside once WEST has joined
    assert engine.area.check(np.degrees(lat), np.degrees(lon) - 0.05, h).refused
    now, masters, alarms = 0.0, [], []
    for e in range(ENGINE_S):
        if e == 5:
            engine.add_station("WEST", west)
            with pytest.raises(ValueError, match="already"):
                engine.add_station("WEST", west)
            assert engine.area.check(np.degrees(lat), np.degrees(lon) - 0.05, h).kind == "inside"
            engine.open_session("c1", np.degrees(lat), np.degrees(lon) - 0.05, h, got.extend)
        if e == LEAVE_AT:
            change = engine.remove_station("WEST")
            assert change.dropped == ("NORTH-WEST", "SOUTH-WEST")
            assert "WEST" not in engine.decoders and "WEST" not in engine.area.names
        for name in stations:
            engine.feed(name, streams.epoch_bytes[name][e][1], now)
        now += 1.0
        for r in engine.tick(now):
            alarms += [a for a in r.network.alarms if a.kind == MEMBERSHIP_KIND]
            if r.vrs is not None:
                masters.append((e, r.vrs.master[0]))
    before = [m for e, m in masters if e < LEAVE_AT]
    after = [m for e, m in masters if e > LEAVE_AT]
    assert before and before[-1] == "WEST"  # the session's nearest station served it
    assert after and "WEST" not in after  # re-homed to another master
    assert engine.sessions["c1"].epochs_sent >= ENGINE_S - 10
    assert "WEST" not in engine.last.network.stations and "NORTH-WEST" not in engine.last.network.baselines
    assert [(a.cleared, a.severity) for a in alarms] == [(True, "info"), (False, "warning")]
    assert "1 VRS session(s) re-homed" in alarms[-1].message
