"""The network engine's integer decisions under the simulator's four ionosphere levels (network-70km, four
baselines of ~50 km): every fixed DD integer against the truth over a cold start.

The ionosphere prior the baselines start with (1.5 ppm) is a quiet day's; the network then learns the day's
level from its fixed satellites (`baseline.day_ionosphere_ppm`, pooled over the baselines by
`NetworkSolver._share_day_ionosphere`) and uses it, lower or higher. Quiet and moderate days fix without a wrong
integer; an active or storm day does not yet: the first fixes rest on a prior the day disproves (a sample of the
satellites fixed first is biased low), and BeiDou's B1I/B3I pair (4, 5), 3.6 cm apart in the ionosphere-free
phase, passes validation. That defect is carried by the strict xfail below with its measured counts.
"""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.network import NetworkSolver
from stations.scenario import load_scenario
from stations.world import World
from tests.centre.simdata import station_epochs

DURATION_S = 90


def _cold_start(level: str, duration_s: int = DURATION_S) -> dict:
    sc = load_scenario("network-70km")
    iono = sc.errors.ionosphere.model_copy(update={"level": level})
    sc = sc.model_copy(update={"duration_s": duration_s, "errors": sc.errors.model_copy(update={"ionosphere": iono})})
    world = World(sc)
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    net = NetworkSolver(stations)
    col = {s: j for j, s in enumerate(world.sats)}
    checked, wrong, fraction = 0, set(), {}
    for blk in world.epochs():
        per = {r: station_epochs(world, blk, i) for i, r in enumerate(ids)}
        for e in range(len(blk.t_gpst)):
            ne = net.update({r: per[r][e] for r in stations}, world.nav)
            for solver in net.solvers.values():
                res = ne.baselines[solver.name]
                if res is None:
                    continue
                fraction[solver.name] = res.fixed_fraction
                k = np.flatnonzero(res.fixed & ~res.is_reference())
                if not k.size:
                    continue
                ra, rb = ids.index(solver.name_a), ids.index(solver.name_b)
                j = np.array([col[str(s)] for s in res.sats[k]])
                jr = np.array([col[res.refs[str(s)[0]]] for s in res.sats[k]])
                amb = blk.ambiguity_cyc[e][:, :, :2]
                truth = (amb[rb, j] - amb[ra, j]) - (amb[rb, jr] - amb[ra, jr])
                checked += k.size
                for i in np.flatnonzero(~(truth == res.dd_n[k]).all(axis=1)):
                    wrong.add((solver.name, str(res.sats[k[i]])))
    levels = {s.name: s.iono_day_ppm for s in net.solvers.values()}
    return dict(checked=checked, wrong=sorted(wrong), fraction=fraction, day_ppm=levels)


@pytest.mark.parametrize("level", ["quiet", "moderate"])
def test_quiet_and_moderate_days_fix_without_a_wrong_integer(level):
    out = _cold_start(level)
    print(f"\n{level}: {out['checked']} fixed DD ambiguity-epochs, wrong {out['wrong']}, fixed fraction at "
          f"{DURATION_S} s {out['fraction']}, the day's ionosphere level [ppm] {out['day_ppm']}")
    assert out["checked"] > 2000
    assert out["wrong"] == []
    assert all(v is not None for v in out["day_ppm"].values())
    assert min(out["fraction"].values()) > 0.3


def test_the_days_level_follows_the_ionosphere():
    quiet = _cold_start("quiet", 40)["day_ppm"]
    moderate = _cold_start("moderate", 40)["day_ppm"]
    assert all(v is not None for v in list(quiet.values()) + list(moderate.values()))
    assert max(quiet.values()) < min(moderate.values())


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "known defect (measured 2026-11-22): on an active or storm day the network fixes wrong integers. Cold starts "
    "at 0/1200/2400 s, 300 s each: active 3 wrong satellite arcs (BeiDou C01 on NORTH-EAST and SOUTH-WEST, C21 "
    "on NORTH-WEST, all the B1I/B3I pair (4, 5)), 772 of 39,272 fixed DD ambiguity-epochs; storm 6,047 of "
    "19,019, from the first fixes at 13 s on. The code before the day's level was learned did the same (455 and "
    "6,516). Causes: the quiet-day default prior before the first fixes, and a day's level learned from the "
    "satellites fixed first (biased low); a measured ionosphere rate (SD geometry-free phase) raising the prior "
    "and the random walk was tried and did not remove the (4, 5) fixes"))
def test_storm_day_fixes_no_wrong_integer():
    out = _cold_start("storm", 60)
    assert out["wrong"] == [], out["wrong"]
