"""The network engine's fixed DD integers against the simulator's truth: the one check of them.

The simulator knows every receiver's carrier-phase ambiguity; the centre never reads it. This runs the centre's
network engine on a scenario's reference stations (in process, first two signals, as the centre's signal plan)
and compares every fixed double-difference integer (b - a, satellite - reference, N1 and N2) with the truth
at the same epoch. `augnet sim calibrate`'s harsh preset and the ionosphere-level tests use it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

N_SIGNALS = 2  # the centre's dual-frequency plan: the scenario's first two signals per system


@dataclass
class NetworkRun:
    fixed_fraction: dict  # baseline -> mean fixed fraction of its DD ambiguities over the run
    checked: int  # fixed DD ambiguity-epochs compared with the truth
    wrong: dict  # baseline -> fixed DD ambiguity-epochs whose integers differ from the truth
    wrong_sats: set = field(default_factory=set)  # (baseline, satellite) fixed wrong at some epoch
    last_fixed_fraction: dict = field(default_factory=dict)  # baseline -> fixed fraction at its last epoch
    day_ppm: dict = field(default_factory=dict)  # baseline -> the day's ionosphere level at the end [ppm]


def station_epoch(world, block, e: int, i: int):
    """Receiver i's epoch e of a simulator block as the centre's `StationEpoch` (first two signals)."""
    from augnet.centre.observations import StationEpoch

    o = block.observed[e, i].any(axis=1)
    k = slice(0, N_SIGNALS)
    return StationEpoch(world.receivers[i].id, float(block.t_gpst[e]), np.array(world.sats)[o],
                        block.pseudorange_m[e, i][o][:, k], block.phase_cyc[e, i][o][:, k], block.lli[e, i][o][:, k],
                        block.cnr_dbhz[e, i][o][:, k], world.freq_hz[o][:, k], world.codes[o][:, k])


def true_dd_integers(world, block, e: int, ra: int, rb: int, sats, refs) -> np.ndarray:
    """Truth DD integer ambiguities (receiver rb - ra, each of `sats` minus its reference in `refs`), (n, 2)."""
    col = {s: j for j, s in enumerate(world.sats)}
    j = np.array([col[str(s)] for s in sats], dtype=int)
    jr = np.array([col[refs[str(s)[0]]] for s in sats], dtype=int)
    amb = block.ambiguity_cyc[e][:, :, :N_SIGNALS]
    return (amb[rb, j] - amb[ra, j]) - (amb[rb, jr] - amb[ra, jr])


def network_against_truth(scenario, stations=None) -> NetworkRun:
    """The centre's network engine on a scenario's reference `stations` (default: every receiver but the
    check receivers), every fixed DD integer against the simulator's ambiguities."""
    from augnet.centre.network import NetworkSolver
    from stations.world import World

    world = World(scenario)
    ids = world.receiver_ids
    if stations is None:
        stations = [r for r in ids if not r.startswith("check")]
    net = NetworkSolver({r.id: r.ecef[0] for r in world.receivers if r.id in stations})
    frac: dict = {}
    run = NetworkRun({}, 0, {})
    for blk in world.epochs():
        for e in range(len(blk.t_gpst)):
            ne = net.update({r: station_epoch(world, blk, e, ids.index(r)) for r in stations}, world.nav)
            for solver in net.solvers.values():
                res = ne.baselines[solver.name]
                if res is None:
                    continue
                frac.setdefault(solver.name, []).append(res.fixed_fraction)
                run.last_fixed_fraction[solver.name] = res.fixed_fraction
                k = np.flatnonzero(res.fixed & ~res.is_reference())
                if not k.size:
                    continue
                truth = true_dd_integers(world, blk, e, ids.index(solver.name_a), ids.index(solver.name_b),
                                         res.sats[k], res.refs)
                bad = ~(truth == res.dd_n[k]).all(axis=1)
                run.checked += k.size
                run.wrong[solver.name] = run.wrong.get(solver.name, 0) + int(bad.sum())
                run.wrong_sats |= {(solver.name, str(s)) for s in res.sats[k[bad]]}
    run.fixed_fraction = {k: float(np.mean(v)) for k, v in frac.items()}
    run.day_ppm = {s.name: s.ionosphere.day_ppm for s in net.solvers.values()}
    return run
