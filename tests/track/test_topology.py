"""Topology queries on the test line (crossover, loop), validation naming the element, adapter."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_geodetic, enu_to_ecef, geodetic_deg_to_ecef
from augnet.onboard.trackmap import TrackDatabase
from augnet.track.topology import Step, Topology, TopologyError
from augnet.track.topology_file import import_railml

LINE = Path(__file__).with_name("two_stations.railml")
ORIGIN = geodetic_deg_to_ecef(45.0, 9.0, 100.0)  # the test line's local origin: track 1 at km 0


def enu(x, y):
    """East/north offset [m] from the origin, at the line's height (100 m above the ellipsoid)."""
    lat, lon, _ = ecef_to_geodetic(ORIGIN + enu_to_ecef(np.array([x, y, 0.0]), ORIGIN))
    return geodetic_deg_to_ecef(np.degrees(lat), np.degrees(lon), 100.0)


@pytest.fixture(scope="module")
def topo() -> Topology:
    return import_railml(LINE)


@pytest.fixture()
def d(topo) -> dict:
    return copy.deepcopy(topo.to_dict())


def refused(d: dict) -> TopologyError:
    with pytest.raises(TopologyError) as exc:
        Topology.from_dict(d)
    return exc.value


def test_after_the_crossover_switch_track_1_or_2(topo):
    # facing the crossover from track 1: straight on (track 1) or over it onto track 2
    assert set(topo.next_steps(Step("t1a.0", "up"))) == {Step("t1a.1", "up"), Step("x12", "up")}
    assert topo.tracks_after_next_switch(Step("t1a.0", "up")) == {"1", "2", "X12"}
    assert topo.next_steps(Step("x12", "up")) == [Step("t2a.1", "up")]
    # trailing through the same switch on track 1 there is one way only
    assert topo.tracks_after_next_switch(Step("t1a.1", "down")) == {"1"}
    # track 2 at km 0.5 running up trails through A2: it stays on track 2
    assert topo.tracks_after_next_switch(Step("t2a.0", "up")) == {"2"}
    # on the open line, the next switch is at Beta: track 1 or the loop, whatever lies between
    assert topo.tracks_after_next_switch(Step("t1b", "up")) == {"1", "3"}


def test_edges_at_a_node(topo):
    assert sorted(topo.edges_at("swB1")) == [("l3a", "begin"), ("t1c.0", "end"), ("t1c.1", "begin")]
    assert topo.edges_at("bs1e") == [("t1c.2", "end")] and topo.nodes["bs1e"].kind == "buffer_stop"
    with pytest.raises(TopologyError, match="node nowhere"):
        topo.edges_at("nowhere")


def test_no_route_from_straight_to_diverging(topo):
    # arriving at switch B2 on its straight leg, the loop's leg is no way on
    assert topo.next_steps(Step("t1c.1", "up")) == [Step("t1c.2", "up")]
    with pytest.raises(TopologyError, match="does not follow t1c.1"):
        topo.check_route([Step("t1c.1", "up"), Step("l3c", "down")])


def test_loop_track_rejoins(topo):
    route = [Step("t1c.0", "up"), Step("l3a", "up"), Step("l3b", "up"), Step("l3c", "up"), Step("t1c.2", "up")]
    topo.check_route(route)
    ahead = topo.reachable(Step("l3a", "up"), 1100.0)
    assert Step("t1c.2", "up") in ahead and all(topo.edges[s.edge].track in ("1", "3") for s in ahead)
    # from km 7.9 on track 1, 150 m ahead: over switch B1 onto the loop's first piece or on along track 1;
    # 250 m ahead also the loop's platform road (100 m to the switch + the 100 m turnout road)
    near = topo.reachable(Step("t1c.0", "up"), 150.0, from_km=7.9)
    assert set(near) == {Step("t1c.0", "up"), Step("l3a", "up"), Step("t1c.1", "up")}
    assert Step("l3b", "up") in topo.reachable(Step("t1c.0", "up"), 250.0, from_km=7.9)
    assert set(topo.reachable(Step("t1c.0", "up"), 50.0, from_km=7.9)) == {Step("t1c.0", "up")}
    # distance along the loop from km 7.5 to km 9.5: 500 m + the loop's three pieces + 500 m
    loop_m = sum(topo.length_m(e) for e in ("l3a", "l3b", "l3c"))
    assert topo.route_distance_m(route, "t1c.2", 9.5, start_km=7.5) == pytest.approx(500 + loop_m + 500, abs=0.05)
    assert loop_m > 1000.0  # the loop is longer than the straight road it bypasses
    straight = [Step("t1c.0", "up"), Step("t1c.1", "up"), Step("t1c.2", "up")]
    assert topo.route_distance_m(straight, "t1c.2", 9.5, start_km=7.5) == pytest.approx(2000, abs=0.05)
    # down the line, from the loop's end through B1 back to track 1 only
    assert topo.next_steps(Step("l3a", "down")) == [Step("t1c.0", "down")]


def test_route_distance_refuses_an_edge_not_on_the_route(topo):
    with pytest.raises(TopologyError, match="does not pass edge t2b"):
        topo.route_distance_m([Step("t1b", "up")], "t2b", 5.0)


def test_nearest_point_between_the_main_tracks(topo):
    p = enu(5000.0, 2.3)  # halfway between tracks 1 and 2 at km 5
    n1, n2 = topo.nearest_point("t1b", p), topo.nearest_point("t2b", p)
    assert n1.km == pytest.approx(5.0, abs=0.01) and n2.km == pytest.approx(5.0, abs=0.01)
    # 2.3 m across; the 4 km chords sag 0.31 m below the ellipsoid height at mid-span (L^2 / 8R)
    assert n1.distance_m == pytest.approx(np.hypot(2.3, 0.31), abs=0.05)
    assert n2.distance_m == pytest.approx(n1.distance_m, abs=0.02)
    near = topo.nearest_edges(enu(8500.0, -4.0), radius_m=5.0)  # 0.6 m from the loop, 4 m from track 1
    assert [h.edge for h in near] == ["l3b", "t1c.1"]
    assert near[0].distance_m == pytest.approx(0.6, abs=0.05) and near[0].km == pytest.approx(8.5, abs=0.01)
    assert topo.nearest_edges(enu(5000.0, 30.0), radius_m=10.0) == []
    mid = topo.nearest_edges(enu(1530.0, 2.3), radius_m=3.0)  # on the crossover, 2.3 m from either main track
    assert mid[0].edge == "x12" and mid[0].distance_m < 0.05 and {h.edge for h in mid[1:]} == {"t1a.1", "t2a.0"}


def test_adapter_to_the_track_database(topo):
    db = TrackDatabase.from_dict(topo.to_track_database_dict())
    assert set(db.tracks) == set(topo.edges) and {b.id for b in db.balises} == {"bg1", "bg2", "bg3", "bg4"}
    m = db.match(enu(8500.0, -4.6))
    assert m.track == "l3b" and m.km == pytest.approx(8.5, abs=0.01)


def test_dangling_connection_is_refused(d):
    d["edges"][0]["begin"] = "nowhere"
    e = refused(d)
    assert e.element == f"edge {d['edges'][0]['id']}" and "dangling connection" in e.reason


def test_node_missing_an_edge_is_refused(d):
    d["edges"] = [e for e in d["edges"] if e["id"] != "t1b"]
    e = refused(d)
    assert e.element == "node c1a_e" and "dangling connection" in e.reason and "this one 1" in e.reason


def test_switch_leg_that_does_not_exist_is_refused(d):
    t = next(t for t in d["turnouts"] if t["id"] == "swA1")
    t["diverging"] = "x99"
    e = refused(d)
    assert e.element == "turnout swA1" and "diverging leg 'x99' does not exist" in e.reason
    t["diverging"] = "t2b"
    assert "does not end at this switch" in refused(d).reason


def test_chainage_not_increasing_is_refused(d):
    edge = next(e for e in d["edges"] if e["id"] == "x12")
    edge["km"] = [1.56, 1.5]
    e = refused(d)
    assert e.element == "edge x12" and "chainage not increasing" in e.reason


def test_geometry_gap_is_refused(d):
    edge = next(e for e in d["edges"] if e["id"] == "l3b")
    edge["points"][0][1] += 1e-5  # 0.8 m east at 45 N
    e = refused(d)
    assert e.element == "edge l3b" and "geometry gap" in e.reason and "cl1_e" in e.reason


def test_bad_file_fields_are_refused(d):
    assert refused({"format": "augnet-trackmap/1"}).element == "file"
    del d["nodes"][3]["position"]
    e = refused(d)
    assert e.element.startswith("node ") and "missing field" in e.reason


def test_point_of_interest_off_its_edge_is_refused(d):
    p = next(p for p in d["points_of_interest"] if p["id"] == "bg1")
    p["km"] = 2.0  # bg1 sits on t1a.0, km 0-1.5
    e = refused(d)
    assert e.element == "point of interest bg1" and "outside edge t1a.0" in e.reason


def test_repeated_point_is_refused(d):
    edge = next(e for e in d["edges"] if e["id"] == "t1b")
    edge["points"].insert(1, list(edge["points"][0]))
    edge["km"].insert(1, edge["km"][0] + 1e-4)
    e = refused(d)
    assert e.element == "edge t1b" and "points 0 and 1 coincide" in e.reason


def test_adapter_matches_the_edge_under_the_train_not_a_collinear_one_ahead(topo):
    """One track per edge: collinear edges (t1a.0 ... t1c.2 on track 1) lie on each other's straight
    extension; a roof antenna 5 cm off the centre line is ~5 cm from every one of them across the track but
    kilometres along it: only the edge under the train is a candidate."""
    from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation

    db = TrackDatabase.from_dict(topo.to_track_database_dict())
    for e in topo.edges.values():
        for km in np.linspace(e.km_begin, e.km_end, 7)[1:-1]:
            p = topo.position_ecef(e.id, km)
            llh = ecef_to_geodetic(p)
            r = enu_rotation(llh[0], llh[1])
            for north in (-0.05, 0.05):
                m = db.match(p + r.T @ np.array([0.0, north, 4.2]))
                assert m.track == e.id, (e.id, km, north, m.track, m.candidates)
