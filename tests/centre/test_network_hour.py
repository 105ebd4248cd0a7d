"""An hour of `network-70km` (quiet ionosphere; four stations on a square of 50 km sides, the baselines along its
sides): no wrong fix against the simulator's truth, and how long fixing takes.

Time to fix, two definitions (issue 5 asks "every baseline's ambiguities fixed within a median 60 s"):

* per baseline, from a cold start: seconds from a solver's first epoch until the baseline has fixed its first
  satellite, half, and 80 % of the satellites it may fix (DD ambiguities on both frequencies of the satellites
  above `fix_min_elevation_deg` at both stations, references excluded). Three cold starts on the same data:
  the hour's solver at 0 s, and two more solvers started at 20 and 40 minutes, run for 5 minutes each;
* per new satellite arc (a satellite rising, or back after a gap or a slip, after the solver started): seconds
  from the first epoch the satellite may be fixed (above the fixing mask at both stations) until it is fixed.
  Arcs that end, or outlast the hour, before a fix are counted as censored; arcs already there at a cold start
  belong to the first definition.

Every fixed DD ambiguity of every solver, every epoch, is checked against the truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.network import NetworkSolver
from stations.scenario import load_scenario
from stations.world import World
from tests.centre.simdata import station_epochs, truth_dd_ambiguity

HOUR_S = 3600
COLD_STARTS_S = (1200, 2400)  # extra solvers, besides the hour's own start at 0 s
COLD_RUN_S = 300
SHARES = (0.5, 0.8)  # fixed share of the fixable satellites for the cold-start figures


class _Timing:
    """Per baseline, time from the solver's start to its first fix and to the SHARES; per arc, time to fix."""

    def __init__(self, t0: int, arcs: bool):
        self.t0 = t0
        self.first: dict[str, dict] = {}  # baseline -> {"first": s, 0.5: s, ...}
        self.arcs = arcs
        self.open: dict[tuple[str, str], dict] = {}
        self.closed: list[dict] = []

    def epoch(self, epoch: int, name: str, res) -> None:
        ref = res.is_reference()
        can = res.eligible & ~ref
        fixed = res.fixed & can
        rec = self.first.setdefault(name, {})
        if fixed.any():
            rec.setdefault("first", epoch - self.t0)
        for share in SHARES:
            if can.sum() >= 4 and fixed.sum() >= share * can.sum():
                rec.setdefault(share, epoch - self.t0)
        if not self.arcs:
            return
        for k, s in enumerate(map(str, res.sats)):
            key = (name, s)
            arc = self.open.get(key)
            if arc is None or arc["last"] != epoch - 1 or s in res.slips:
                if arc is not None:
                    self.closed.append(arc)
                arc = self.open[key] = dict(start=epoch, cold=epoch == self.t0, eligible=None, fixed=None,
                                            was_ref=False, last=epoch)
            arc["last"] = epoch
            arc["was_ref"] |= bool(ref[k] and arc["fixed"] is None)
            if res.eligible[k] and arc["eligible"] is None:
                arc["eligible"] = epoch
            if fixed[k] and arc["fixed"] is None:
                arc["fixed"] = epoch

    def new_arcs(self):
        """(times to fix of the new arcs, number censored)."""
        arcs = [a for a in self.closed + list(self.open.values())
                if not a["cold"] and a["eligible"] is not None and not a["was_ref"]]
        ttf = [a["fixed"] - a["eligible"] for a in arcs if a["fixed"] is not None]
        return np.array(ttf, float), sum(a["fixed"] is None for a in arcs)


@pytest.fixture(scope="module")
def hour():
    world = World(load_scenario("network-70km").model_copy(update={"duration_s": HOUR_S}))
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    solvers = {0: NetworkSolver(stations)}
    timing = {0: _Timing(0, arcs=True)}
    checked, wrong, fractions = 0, [], {}
    col = {s: j for j, s in enumerate(world.sats)}
    for blk in world.epochs():
        per = {r: station_epochs(world, blk, i) for i, r in enumerate(ids)}
        for e in range(len(blk.t_gpst)):
            epoch = int(blk.epoch_index[e])
            if epoch in COLD_STARTS_S:
                solvers[epoch] = NetworkSolver(stations)
                timing[epoch] = _Timing(epoch, arcs=False)
            for t0 in [t0 for t0 in solvers if t0 and epoch >= t0 + COLD_RUN_S]:
                del solvers[t0]
            for t0, net in solvers.items():
                ne = net.update({r: per[r][e] for r in stations}, world.nav)
                for solver in net.solvers.values():
                    res = ne.baselines[solver.name]
                    if res is None:
                        continue
                    timing[t0].epoch(epoch, solver.name, res)
                    if t0 == 0:
                        fractions.setdefault(solver.name, []).append(res.fixed_fraction)
                    # every fixed DD against the truth (vectorised truth_dd_ambiguity)
                    ra, rb = ids.index(solver.name_a), ids.index(solver.name_b)
                    k = np.flatnonzero(res.fixed & ~res.is_reference())
                    if not k.size:
                        continue
                    j = np.array([col[str(s)] for s in res.sats[k]])
                    jr = np.array([col[res.refs[str(s)[0]]] for s in res.sats[k]])
                    amb = blk.ambiguity_cyc[e][:, :, :2]
                    truth = (amb[rb, j] - amb[ra, j]) - (amb[rb, jr] - amb[ra, jr])
                    checked += k.size
                    if epoch % 600 == 0:  # the vectorised truth is simdata's
                        assert all(np.array_equal(truth[i], truth_dd_ambiguity(world, blk, e, ra, rb, str(s),
                                                                               res.refs[str(s)[0]]))
                                   for i, s in enumerate(res.sats[k]))
                    for i in np.flatnonzero(~(truth == res.dd_n[k]).all(axis=1)):
                        wrong.append((t0, epoch, solver.name, str(res.sats[k[i]])))
    cold = {key: np.array([rec.get(key, np.inf) for tm in timing.values() for rec in tm.first.values()], float)
            for key in ("first",) + SHARES}
    ttf, censored = timing[0].new_arcs()
    out = dict(checked=checked, wrong=wrong, cold=cold, arc_ttf=ttf, arc_censored=censored,
               fraction_after_10_min={k: float(np.mean(v[600:])) for k, v in fractions.items()})

    def med(v):
        return f"{np.median(v):.0f} s" if np.isfinite(np.median(v)) else "not reached"

    print(f"\nnetwork-70km, 1 h, cold starts at 0/{'/'.join(str(t) for t in COLD_STARTS_S)} s: {checked} fixed DD "
          f"ambiguity-epochs checked, {len(wrong)} wrong. Per baseline from a cold start ({len(cold['first'])}): "
          f"first fix median {med(cold['first'])} (max {cold['first'].max():.0f} s), half of the fixable "
          f"satellites median {med(cold[0.5])}, 80 % median {med(cold[0.8])} ({np.isfinite(cold[0.8]).sum()} "
          f"reached). New arcs: {len(ttf)} fixed, time from eligible to fixed median "
          f"{med(ttf) if len(ttf) else '-'}, {censored} censored. Mean fixed fraction after 10 min: "
          + ", ".join(f"{k} {v:.2f}" for k, v in out["fraction_after_10_min"].items()))
    return out


def test_an_hour_and_three_cold_starts_without_a_wrong_fix(hour):
    assert hour["checked"] > 100_000
    assert hour["wrong"] == []


def test_time_to_fix_and_fixed_share(hour):
    """Measured with honest (multipath-aware) float covariances: the high GPS and BeiDou satellites fix within a
    minute of a cold start, half of the fixable ones within a few minutes; the rest, Galileo E1/E5a above all
    (its near-equivalent integer pair (3, 4) differs by 6 mm in the ionosphere-free phase and needs the DD
    ionosphere to ~7 cm), take many minutes on these 50 km baselines."""
    cold = hour["cold"]
    assert np.median(cold["first"]) <= 60, cold["first"]
    assert np.isfinite(cold["first"]).all(), cold["first"]
    assert np.median(cold[0.5]) <= 300, cold[0.5]
    assert all(f > 0.8 for f in hour["fraction_after_10_min"].values()), hour["fraction_after_10_min"]


@pytest.mark.xfail(strict=True, reason="issue 5 goal not met: every baseline's fixable ambiguities within a median "
                   "60 s. Measured (1 h + 2 cold starts of 5 min, 12 baseline cold starts): first fix median 12 s "
                   "(max 13 s), half of the fixable satellites median 232 s, 80 % reached only on the hour's "
                   "solver (4 of 12); the hour's new arcs (rising Galileo satellites) fix after ~30 min or not at "
                   "all. Limits: station multipath correlated over minutes (code and phase), the quiet-day DD "
                   "ionosphere prior, and Galileo E1/E5a's (3, 4) pair; see augnet/centre/baseline.py")
def test_issue_goal_median_60_s(hour):
    assert np.median(hour["cold"][0.8]) <= 60
    ttf = hour["arc_ttf"]
    assert len(ttf) and np.median(ttf) <= 60
