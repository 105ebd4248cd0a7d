"""An hour of `network-70km` (quiet ionosphere, four stations 50-70 km apart): no wrong fix against the
simulator's truth, and the time each satellite arc takes to fix (reported)."""

from __future__ import annotations

import numpy as np

from augnet.centre.network import NetworkSolver
from stations.scenario import load_scenario
from stations.world import World
from tests.centre.simdata import station_epochs, truth_dd_ambiguity

HOUR_S = 3600


def test_an_hour_without_a_wrong_fix():
    world = World(load_scenario("network-70km").model_copy(update={"duration_s": HOUR_S}))
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    net = NetworkSolver(stations)
    checked, wrong = 0, []
    arc_start, time_to_fix, fractions = {}, {}, {}
    for blk in world.epochs():
        per = {r: station_epochs(world, blk, i) for i, r in enumerate(ids)}
        for e in range(len(blk.t_gpst)):
            ne = net.update({r: per[r][e] for r in stations}, world.nav)
            epoch = int(blk.epoch_index[e])
            for solver in net.solvers.values():
                res = ne.baselines[solver.name]
                if res is None:
                    continue
                fractions.setdefault(solver.name, []).append(res.fixed_fraction)
                ra, rb = ids.index(solver.name_a), ids.index(solver.name_b)
                for k, s in enumerate(res.sats):
                    key = (solver.name, str(s))
                    arc_start.setdefault(key, epoch)
                    if res.fixed[k] and s not in res.refs.values():
                        checked += 1
                        time_to_fix.setdefault(key, epoch - arc_start[key])
                        truth = truth_dd_ambiguity(world, blk, e, ra, rb, str(s), res.refs[s[0]])
                        if not np.array_equal(truth, res.dd_n[k]):
                            wrong.append((epoch, key))
    ttf = np.array(list(time_to_fix.values()), float)
    print(f"\nnetwork-70km, 1 h: {checked} fixed DD ambiguity-epochs checked, {len(wrong)} wrong; "
          f"{len(ttf)} of {len(arc_start)} satellite arcs fixed, time to fix median {np.median(ttf):.0f} s, "
          f"75 % {np.percentile(ttf, 75):.0f} s; mean fixed fraction after 10 min "
          + ", ".join(f"{k} {np.mean(v[600:]):.2f}" for k, v in fractions.items()))
    assert checked > 100_000
    assert wrong == []
    assert all(np.mean(v[600:]) > 0.8 for v in fractions.values())
