"""Integrity on simulated faults: a satellite clock step is excluded within two epochs with an alarm; a
station that stops is reported and the network carries on without it."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.network import NetworkSolver
from augnet.centre.vrs import synthesize
from stations.scenario import Fault, load_scenario
from stations.world import World
from tests.centre.simdata import station_epochs

pytestmark = pytest.mark.slow

FAULT_AT_S = 40.0


def _world(faults, duration_s):
    base = load_scenario("network-70km")
    return World(base.model_copy(update={"duration_s": duration_s, "faults": faults}))


def _visible_satellite():
    w = _world([], 2)
    blk = w.run()[0]
    seen = blk.observed[0, :, :, 0].all(axis=0) & (blk.elevation_rad[0].min(axis=0) > np.radians(30))
    return w.sats[int(np.flatnonzero(seen)[0])]


def _run(world, on_epoch):
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    net = NetworkSolver(stations)
    for block in world.epochs():
        per = {r: station_epochs(world, block, i) for i, r in enumerate(ids)}
        for e in range(len(block.t_gpst)):
            eps = {r: (per[r][e] if len(per[r][e].sats) else None) for r in stations}
            ne = net.update(eps, world.nav)
            on_epoch(float(block.t_gpst[e] - world.t0), ne, eps, per["check1"][e], world)


def test_satellite_clock_step_is_excluded_within_two_epochs_with_an_alarm():
    sat = _visible_satellite()
    world = _world([Fault(kind="satellite_clock_step", at_s=FAULT_AT_S, satellite=sat, step_ns=30.0)], 50)
    log = {"excluded_at": None, "alarms": [], "false": 0}

    def on_epoch(t, ne, eps, rover, w):
        log["alarms"] += [(t, a) for a in ne.alarms]
        if sat in ne.excluded and log["excluded_at"] is None:
            log["excluded_at"] = t
        log["false"] += len(ne.excluded - {sat})
        if sat in ne.excluded:
            vrs = synthesize(ne, eps, w.receivers[w.receiver_ids.index("check1")].ecef[0][None], w.nav)
            assert sat not in set(vrs.sats)

    _run(world, on_epoch)
    assert log["excluded_at"] is not None and FAULT_AT_S <= log["excluded_at"] <= FAULT_AT_S + 2.0
    faults = [a for t, a in log["alarms"] if a.kind == "satellite-fault" and a.subject == sat]
    assert faults and faults[0].severity == "critical"
    assert log["false"] == 0  # no other satellite was ever excluded


def test_station_outage_is_reported_and_the_network_goes_on_without_it():
    world = _world([Fault(kind="station_outage", at_s=FAULT_AT_S, station="WEST")], 90)
    log = {"down": None, "present_after": [], "corrected_after": [], "baselines_after": []}

    def on_epoch(t, ne, eps, rover, w):
        for a in ne.alarms:
            if a.kind == "station-down" and a.subject == "WEST" and not a.cleared:
                log["down"] = t
        if t > FAULT_AT_S + 10:
            log["present_after"].append("WEST" in ne.present)
            vrs = synthesize(ne, eps, w.receivers[w.receiver_ids.index("check1")].ecef[0][None], w.nav)
            log["corrected_after"].append(int(vrs.corrected[0].sum()))
            log["baselines_after"].append(sorted(k for k, b in ne.baselines.items() if b is not None))

    _run(world, on_epoch)
    assert log["down"] is not None and log["down"] <= FAULT_AT_S + 7
    assert not any(log["present_after"])
    assert all("WEST" not in k for ks in log["baselines_after"] for k in ks)
    assert min(log["corrected_after"]) >= 3  # corrections carry on from the three remaining stations
