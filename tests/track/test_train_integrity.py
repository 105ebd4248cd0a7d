"""The two-antenna train-integrity monitor on the alpha-beta as-built topology: the head-tail distance over
the map (through a switch included), the bound from the two PLs, loss after LOSS_EPOCHS and its latch."""

from __future__ import annotations

import math

import pytest

from augnet.track.topology import Step, Topology
from augnet.track.train_integrity import (COUPLER_PLAY_M, INTEGRITY_ALERT_LIMIT_M, LOSS_EPOCHS, AntennaFix,
                                          IntegrityMonitor)
from stations.layout import Layout

SPACING_M = 209.0


@pytest.fixture(scope="module")
def topo() -> Topology:
    return Topology.from_dict(Layout.load("alpha-beta").truth_topology_dict())


def at(topo: Topology, edge: str, along_m: float, pl_m: float = 0.3) -> AntennaFix:
    return AntennaFix(edge, topo.km_at(edge, along_m), pl_m)


def test_complete_train_on_one_edge_is_confirmed(topo):
    mon = IntegrityMonitor(topo, SPACING_M, "up")
    s = mon.update(0.0, at(topo, "t1b", 1500.0), at(topo, "t1b", 1500.0 - SPACING_M))
    assert s.status == "confirmed" and s.error_m == pytest.approx(0.0, abs=1e-6)
    assert s.bound_m == pytest.approx(0.3 + 0.3 + COUPLER_PLAY_M)


def test_distance_through_the_crossover_is_the_route_distance(topo):
    """Tail on t1a.0 before switch A1, head on the crossover: the distance is the path's, not the chainage's."""
    route = [Step("t1a.0", "up"), Step("x12", "up"), Step("t2a.1", "up")]
    tail = at(topo, "t1a.0", topo.length_m("t1a.0") - 150.0)
    for head_edge, head_along in (("x12", 30.0), ("t2a.1", 100.0)):
        head = at(topo, head_edge, head_along)
        truth = (topo.route_distance_m(route, head.edge, head.km, start_km=tail.km))
        mon = IntegrityMonitor(topo, truth, "up")
        d = mon.distance_m(tail, head, 1000.0)
        assert d == pytest.approx(truth, abs=1e-6)
        chainage_d = (head.km - tail.km) * 1e3
        assert mon.update(0.0, head, tail).status == "confirmed"
    assert abs(chainage_d - truth) > 0.05  # the chainage difference would be off by more than a fixed fix's PL


def test_down_direction_and_a_leg_not_on_the_route(topo):
    """Down through switch A2 from t2a.1: the straight leg t2a.0 is reachable as well as the crossover."""
    mon = IntegrityMonitor(topo, SPACING_M, "down")
    tail = at(topo, "t2a.1", 100.0)
    head = AntennaFix("t2a.0", topo.km_at("t2a.0", topo.length_m("t2a.0") - (SPACING_M - 100.0)), 0.3)
    assert mon.update(0.0, head, tail).error_m == pytest.approx(0.0, abs=1e-6)
    # the head on track 1 beyond the crossover, one spacing from the tail: reachable only through x12
    rest = SPACING_M - 100.0 - topo.length_m("x12")
    assert rest > 0
    far = at(topo, "t1a.0", topo.length_m("t1a.0") - rest)
    assert mon.update(1.0, far, tail).error_m == pytest.approx(0.0, abs=1e-6)
    # a head not reachable from the tail (the other main track, no route there): not measured, not confirmed
    other = at(topo, "t1b", 100.0)
    s = mon.update(2.0, other, tail)
    assert s.status == "unknown" and math.isnan(s.distance_m)


def test_split_is_lost_after_the_persistence_and_latched(topo):
    mon = IntegrityMonitor(topo, SPACING_M, "up")
    head_s, tail_s = 1000.0, 1000.0 - SPACING_M
    states = []
    for k in range(12):  # the rear part falls back 0.25 k^2 m (0.5 m/s^2 from k = 0)
        gap = 0.25 * k * k
        states.append(mon.update(float(k), at(topo, "t1b", head_s + 20.0 * k),
                                 at(topo, "t1b", tail_s + 20.0 * k - gap)))
    bound = 0.3 + 0.3 + COUPLER_PLAY_M
    first_over = next(k for k in range(12) if 0.25 * k * k > bound)
    assert all(s.status == "confirmed" for s in states[:first_over])
    assert all(s.status == "unknown" for s in states[first_over:first_over + LOSS_EPOCHS - 1])
    assert states[first_over + LOSS_EPOCHS - 1].status == "lost"
    assert mon.lost_at_s == float(first_over + LOSS_EPOCHS - 1)
    # the gap closing again (the rear re-measured at its place) does not clear a latched loss
    s = mon.update(20.0, at(topo, "t1b", 2000.0), at(topo, "t1b", 2000.0 - SPACING_M))
    assert s.status == "lost"
    mon.reset()
    assert mon.update(21.0, at(topo, "t1b", 2000.0), at(topo, "t1b", 2000.0 - SPACING_M)).status == "confirmed"


def test_one_outlying_epoch_does_not_alarm(topo):
    mon = IntegrityMonitor(topo, SPACING_M, "up")
    for k in range(10):
        off = 5.0 if k == 4 else 0.0
        s = mon.update(float(k), at(topo, "t1b", 1000.0 + k + off), at(topo, "t1b", 1000.0 + k - SPACING_M))
        assert s.status == ("unknown" if k == 4 else "confirmed")
    assert mon.lost_at_s is None


def test_large_protection_levels_or_no_fix_cannot_confirm(topo):
    mon = IntegrityMonitor(topo, SPACING_M, "up")
    pl = INTEGRITY_ALERT_LIMIT_M / 2.0
    s = mon.update(0.0, at(topo, "t1b", 1000.0, pl), at(topo, "t1b", 1000.0 - SPACING_M, pl))
    assert s.status == "unknown" and "alert limit" in s.reason
    assert mon.update(1.0, None, at(topo, "t1b", 800.0)).status == "unknown"
    assert mon.update(2.0, at(topo, "t1b", 1000.0, math.inf), at(topo, "t1b", 800.0)).status == "unknown"
    assert mon.lost_at_s is None


def test_bad_arguments_refused(topo):
    with pytest.raises(ValueError):
        IntegrityMonitor(topo, 0.0, "up")
    with pytest.raises(ValueError):
        IntegrityMonitor(topo, SPACING_M, "sideways")
