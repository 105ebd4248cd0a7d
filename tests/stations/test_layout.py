"""Simulated trains follow a track layout (stations/layout.py): as-built geometry, routes, truth per epoch."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from stations.layout import LATERAL_ACCEL_M_S2, Layout, LayoutError
from stations.scenario import ScenarioError, load_scenario, parse_scenario
from stations.world import World

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def layout():
    return Layout.load("alpha-beta")


def test_layout_module_imports_nothing_of_the_estimator():
    tree = ast.parse((ROOT / "stations" / "layout.py").read_text())
    mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    mods |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not any(m and m.startswith("augnet") for m in mods), mods


def test_diverging_leg_leaves_tangentially_and_curvature_is_continuous(layout):
    r = layout.route(["t1a.0", "x12", "t2a.1"], 1, 1.4)
    k = r.curvature_1_m()
    on_x = r.edge_index == 1
    # a 1:13 crossover over 60 m is a reverse curve, not a chord: its radius is finite, its curvature starts
    # and ends at zero and ramps between consecutive 1 m vertices by at most a fifth of its peak (a straight
    # meeting an arc would jump by all of it)
    assert 100.0 < 1.0 / k[on_x].max() < 200.0
    assert np.max(np.abs(np.diff(k))) < 0.2 * k.max()
    i0 = int(np.flatnonzero(on_x)[0])
    assert k[i0 - 1] < 0.05 * k.max() and k[i0 - 5] < 1e-6  # ~0 at the switch node, 0 on the straight before
    # the tracks either side are 4.6 m apart (the design), the train ends up on track 2
    xy_end = r.xy[-1]
    t2 = layout.edges["t2a.1"]
    assert np.min(np.linalg.norm(t2.xy - xy_end, axis=1)) < 1e-6
    t1 = layout.edges["t1a.1"].xy
    d = np.min(np.linalg.norm(t1 - t2.xy[700], axis=1))
    assert abs(d - 4.6) < 0.01


def test_route_must_keep_the_switch_rule_and_the_direction(layout):
    with pytest.raises(LayoutError, match="does not follow"):
        layout.route(["t1a.1", "x12"], -1, 2.0)  # straight leg -> diverging leg: no route through swA1
    with pytest.raises(LayoutError, match="does not follow"):
        layout.route(["t1a.0", "t2a.1"], 1, 1.0)
    with pytest.raises(LayoutError, match="outside edge"):
        layout.route(["t1a.0", "x12"], 1, 2.5)
    with pytest.raises(LayoutError, match="not in layout"):
        layout.route(["t9"], 1, 1.0)


def test_scenario_refuses_a_train_without_route_on_a_layout():
    d = load_scenario("alpha-beta").model_dump(mode="json")
    d["trains"][0]["route"] = []
    with pytest.raises(ScenarioError, match="give the train's route"):
        parse_scenario(d)


def test_trains_run_their_routes_with_the_truth_edge_and_chainage_per_epoch(layout):
    sc = load_scenario("alpha-beta")
    w = World(sc)
    trains = [r for r in w.receivers if r.kind == "train"]
    assert len(trains) == 3
    for rx, cfg in zip(trains, sc.trains):
        seq = [rx.edge[0]] + [rx.edge[i] for i in range(1, len(rx.edge)) if rx.edge[i] != rx.edge[i - 1]]
        assert seq == cfg.route[:len(seq)] and len(seq) >= 3, (rx.id, seq)
        route = w.routes[rx.id]
        xy, z, km, ei, along = route.at(rx.route_m)
        assert np.array_equal(np.array(route.edges, dtype=object)[ei], rx.edge)
        assert np.allclose(km, rx.km)
        # the antenna is 4.2 m above the rail on the truth polyline of its edge (horizontal distance < 1 mm)
        llh = np.degrees(np.array([_lat_lon(p) for p in rx.ecef]))
        p = layout.geodetic_to_plane(llh[:, 0], llh[:, 1])
        for j in range(0, len(p), 7):
            e = layout.edges[rx.edge[j]]
            assert np.min(np.linalg.norm(e.xy - p[j], axis=1)) < SAMPLE_HALF_M + 1e-3
        # on the diverging legs the speed keeps to the curve's limit
        k = route.curvature_1_m()
        lim = np.sqrt(LATERAL_ACCEL_M_S2 / np.maximum(np.interp(rx.route_m, route.u_m, k), 1e-12))
        assert np.all(rx.speed_m_s <= lim * 1.02 + 0.05), rx.id
        assert rx.speed_m_s.max() > 25.0  # the line speed (100 km/h) elsewhere


SAMPLE_HALF_M = 0.5  # a point is within half a 1 m truth sample of a vertex


def _lat_lon(p):
    from augnet.gnss.geometry import ecef_to_geodetic
    llh = ecef_to_geodetic(p)
    return llh[0], llh[1]


def test_a_bad_route_or_layout_file_is_a_scenario_error_naming_it():
    d = load_scenario("alpha-beta").model_dump(mode="json")
    d["trains"][0]["route"] = ["t1a.0", "t2a.1"]
    with pytest.raises(ScenarioError, match="t2a.1 does not follow t1a.0"):
        World(parse_scenario(d))
    d = load_scenario("alpha-beta").model_dump(mode="json")
    d["layout"]["file"] = "/nonexistent/layout.json"
    with pytest.raises(ScenarioError, match="cannot read"):
        World(parse_scenario(d))
