"""Layout route kinematics: a train with a rear antenna stands with its rear at start_km, the rear follows one
length behind until a train_split, then slows to a stand; stops halt the head for their dwell; the scenario
refuses the new fields where they cannot apply."""

from __future__ import annotations

import numpy as np
import pytest

from stations.layout import Layout
from stations.scenario import Fault, ScenarioError, Stop, Train, load_scenario
from stations.world import rear_motion, route_motion

T = np.arange(0.0, 200.0)
ROUTE = ["t1c.0", "l3a", "l3b", "l3c", "t1c.2"]  # alpha-beta R2 through Beta's loop


@pytest.fixture(scope="module")
def layout():
    return Layout.load("alpha-beta")


def test_rear_one_length_behind_until_the_split_then_to_a_stand(layout):
    tr = Train(id="R", start_km=7.3, speed_kmh=100, start_speed_kmh=100, route=ROUTE, length_m=415.0,
               rear_antenna=True)
    _route, um, v = route_motion(layout, tr, T, 415.0)
    assert um[0] == pytest.approx(415.0)  # rear at start_km, route distance 0
    ur, _vr = rear_motion(T, um, v, 415.0)
    assert np.allclose(um - ur, 415.0)
    split = Fault(kind="train_split", train="R", at_s=20.0, rear_decel_m_s2=0.5)
    ur, vr = rear_motion(T, um, v, 415.0, split)
    before = T < 20.0
    assert np.allclose(um[before] - ur[before], 415.0)
    v0 = v[20]
    k = 20 + 4  # 4 s after the split
    assert ur[k] == pytest.approx(ur[20] + v0 * 4 - 0.25 * 16)
    stand = 20 + int(np.ceil(v0 / 0.5))
    assert vr[stand] == 0.0 and ur[-1] == pytest.approx(ur[20] + v0 ** 2 / (2 * 0.5))
    # the world's faults are on its own clock: a 60 s warm-up shifts the split back by 60 s
    shifted = split.model_copy(update={"at_s": 80.0})
    assert np.array_equal(rear_motion(T, um, v, 415.0, shifted, 60.0)[0], ur)


def test_a_stop_halts_the_head_for_its_dwell(layout):
    tr = Train(id="R", start_km=7.3, speed_kmh=100, start_speed_kmh=100, route=ROUTE,
               stops=[Stop(km=8.5, dwell_s=60.0)])
    route, um, v = route_motion(layout, tr, T)
    _xy, _z, km, _ei, _ = route.at(um)
    halted = np.flatnonzero(np.isclose(km, 8.5, atol=1e-4) & (v == 0.0))
    assert len(halted) >= 60 and np.all(np.diff(halted) == 1)  # one halt, the dwell long
    assert km[-1] > 8.6 and v[halted[-1] + 5] > 0.0  # and on again
    free = route_motion(layout, tr.model_copy(update={"stops": []}), T)[1]
    assert free[-1] > um[-1]


def test_the_scenario_refuses_misplaced_integrity_fields():
    sc = load_scenario("alpha-beta-integrity")
    assert all(t.rear_antenna for t in sc.trains) and [t.length_m for t in sc.trains] == [209.0, 415.0, 209.0]
    data = sc.model_dump(mode="json")
    with pytest.raises(ValueError, match="rear_decel_m_s2"):
        Fault(kind="train_split", train="R1", at_s=10.0)
    bad = dict(data, faults=[{"kind": "train_split", "train": "R9", "at_s": 10.0, "rear_decel_m_s2": 0.2}])
    with pytest.raises(ValueError, match="R9"):
        type(sc).model_validate(bad)
    plain = load_scenario("alpha-beta").model_dump(mode="json")
    no_rear = dict(plain, faults=[{"kind": "train_split", "train": "R1", "at_s": 10.0, "rear_decel_m_s2": 0.2}])
    with pytest.raises(ValueError, match="no rear antenna"):
        type(sc).model_validate(no_rear)
    demo = load_scenario("demo").model_dump(mode="json")
    demo["trains"][0]["rear_antenna"] = True
    with pytest.raises(ValueError, match="needs a route"):
        type(sc).model_validate(demo)


def test_a_stop_off_the_route_is_refused(layout):
    tr = Train(id="R", start_km=7.3, speed_kmh=100, route=ROUTE, stops=[Stop(km=3.0, dwell_s=10.0)])
    with pytest.raises(ScenarioError, match="not on its route"):
        route_motion(layout, tr, T)
