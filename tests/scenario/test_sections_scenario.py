"""The section register through the simulated chain: three trains' estimated positions as position reports,
through two stations; the register's order matches the truth at every epoch and every boundary crossing
is a station's insert or remove (truth read only here, to judge)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.scenario.runner import load, simulate
from augnet.scenario.sections import replay
from augnet.system.section_register import BOUNDARY_ZONE_M
from stations.scenario import Train
from tests.conftest import LONG_RUN_TIMEOUT_S

pytestmark = [pytest.mark.slow, pytest.mark.timeout(LONG_RUN_TIMEOUT_S)]


def station_scenario():
    """demo's line: G1 and G2 up on track 1 through Langfang East (km 68.5-70.5), G1 ahead; G3 down on
    track 2 through Tianjin South (km 138.5-140.5)."""
    sc = load("demo")
    trains = [Train(id="G1", track=1, start_km=67.0, direction=1, start_speed_kmh=300, speed_kmh=300),
              Train(id="G2", track=1, start_km=65.5, direction=1, start_speed_kmh=250, speed_kmh=250),
              Train(id="G3", track=2, start_km=142.0, direction=-1, start_speed_kmh=300, speed_kmh=300)]
    return sc.model_copy(update={"name": "demo-sections", "duration_s": 100.0, "trains": trains, "faults": []})


@pytest.fixture(scope="module")
def run():
    log = simulate(station_scenario(), warm_up_s=60)
    return log, replay(log)


def test_order_preserved_and_every_crossing_through_a_station(run):
    log, rep = run
    svc = rep.service
    print("epochs", rep.epochs, "queues checked", rep.queues_checked, "stats", dict(svc.stats))
    for ev, past in rep.transitions:
        print(ev, "past boundary m", None if math.isnan(past) else round(past, 1))
    assert rep.epochs >= 90 and rep.queues_checked >= 30  # G1 and G2 share a queue most of the run
    assert rep.order_mismatches == []
    actions = [(e.train_id, e.action, e.section_id, e.direction, e.by) for e, _ in rep.transitions]
    assert ("G1", "admit", 1, "up", "start-of-mission") in actions
    assert ("G1", "remove", 1, "up", "Langfang East") in actions
    assert ("G1", "insert", 2, "up", "Langfang East") in actions
    assert ("G2", "remove", 1, "up", "Langfang East") in actions
    assert ("G2", "insert", 2, "up", "Langfang East") in actions
    assert ("G3", "remove", 3, "down", "Tianjin South") in actions
    assert ("G3", "insert", 2, "down", "Tianjin South") in actions
    # G1 left section 1 and entered section 2 before G2: the same order in both
    left = [a[0] for a in actions if a[1:] == ("remove", 1, "up", "Langfang East")]
    assert left == ["G1", "G2"]
    assert [r.train_id for r in svc.register.trains(2, "up")] == ["G1", "G2"]
    assert [r.train_id for r in svc.register.trains(2, "down")] == ["G3"]
    # each crossing happened after the true boundary and within the zone the register allows
    past = np.array([p for _e, p in rep.transitions if not math.isnan(p)])
    assert len(past) == 6 and np.all(past > -5.0) and np.all(past < BOUNDARY_ZONE_M), past
    assert not any(k.startswith("refused_") for k in svc.stats), dict(svc.stats)


def test_rbc_telegrams_carry_the_order(run):
    _log, rep = run
    svc = rep.service
    msg = svc.telegram(2, "up", 1000)
    assert [t.train_id for t in msg.trains] == ["G1", "G2"] and msg.direction == 0
    assert msg.trains[0].chainage_mm > msg.trains[1].chainage_mm
    assert all(t.length_dm == 2090 and t.correction_age_ms < 5000 for t in msg.trains)
