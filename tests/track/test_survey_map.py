"""The map built from a survey run (augnet/track/survey_map.py): a known curve recovered within the accuracy
the map states, outliers and gaps handled, the topology kept from the layout description."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation, geodetic_deg_to_ecef
from augnet.track.survey_map import MAX_GAP_M, build_map, map_error_m, verify
from augnet.track.topology import Edge, Node, Topology, TopologyError

LAT0, LON0, H0 = 45.0, 9.0, 100.0
RADIUS_M = 300.0  # a station curve: 300 m radius over 40 degrees after a 100 m straight
SIGMA_M = 0.01


def _truth_enu(s: np.ndarray) -> np.ndarray:
    """The known curve: 100 m straight east, then a left-hand arc of RADIUS_M; arc length s [m]."""
    s = np.asarray(s, float)
    arc = np.clip(s - 100.0, 0.0, None)
    th = arc / RADIUS_M
    x = np.where(s <= 100.0, s, 100.0 + RADIUS_M * np.sin(th))
    y = np.where(s <= 100.0, 0.0, RADIUS_M * (1.0 - np.cos(th)))
    return np.column_stack([x, y, np.zeros_like(x)])


LENGTH_M = 100.0 + RADIUS_M * math.radians(40.0)


def _llh(enu: np.ndarray) -> np.ndarray:
    origin = geodetic_deg_to_ecef(LAT0, LON0, H0)
    ecef = enu @ enu_rotation(math.radians(LAT0), math.radians(LON0)) + origin
    g = ecef_to_geodetic(ecef)
    return np.column_stack([np.degrees(g[:, 0]), np.degrees(g[:, 1]), g[:, 2]])


def _description() -> Topology:
    """The layout as designed: the topology right, its geometry a chord (the builder must not use it)."""
    ends = _llh(_truth_enu(np.array([0.0, LENGTH_M])))
    nodes = [Node("a", "open_end", tuple(ends[0])), Node("b", "open_end", tuple(ends[1]))]
    return Topology("known curve", nodes, [Edge("e1", "1", "main", "a", "b", ends, np.array([0.0, LENGTH_M / 1e3]))])


def _truth_map() -> Topology:
    s = np.linspace(0.0, LENGTH_M, 2001)
    pts = _llh(_truth_enu(s))
    nodes = [Node("a", "open_end", tuple(pts[0])), Node("b", "open_end", tuple(pts[-1]))]
    return Topology("truth", nodes, [Edge("e1", "1", "main", "a", "b", pts, s / 1e3)])


def _survey(seed: int, outliers=(), gap=None, direction="up") -> dict:
    rng = np.random.default_rng(seed)
    s = np.arange(0.0, LENGTH_M, 1.0)
    s = np.r_[s, LENGTH_M]
    enu = _truth_enu(s)
    # correlated survey errors (AR(1) over ~30 points) of SIGMA_M per horizontal axis, 2 SIGMA_M vertical
    e = np.zeros((len(s), 3))
    rho = math.exp(-1.0 / 30.0)
    e[0] = rng.normal(0, 1, 3)
    for i in range(1, len(s)):
        e[i] = rho * e[i - 1] + math.sqrt(1 - rho * rho) * rng.normal(0, 1, 3)
    enu = enu + e * np.array([SIGMA_M, SIGMA_M, 2 * SIGMA_M])
    for i, off in outliers:
        enu[i, :2] += off
    keep = np.ones(len(s), bool)
    if gap is not None:
        keep = ~((s >= gap[0]) & (s <= gap[1]))
    pts = _llh(enu[keep])
    if direction == "down":
        pts = pts[::-1]
    return {"format": "augnet-survey/1", "seed": seed,
            "runs": [{"id": "r1", "edge": "e1", "direction": direction, "t_s": list(range(len(pts))),
                      "points": pts.tolist(), "sigma_h_m": SIGMA_M, "sigma_v_m": 2 * SIGMA_M}]}


def test_known_curve_recovered_within_the_accuracy_the_map_states():
    built = build_map(_description(), _survey(1))
    acc = verify(built, _survey(2, direction="down"))
    err = map_error_m(built.topology, _truth_map(), step_m=0.5)
    # the design chord is metres off the curve; the built map follows it, and its verified accuracy figure
    # (against an independent run, whose own noise it includes) covers its true error
    assert map_error_m(_description(), _truth_map()).max() > 10.0
    assert np.percentile(err, 95) <= acc["horizontal_95_m"] and err.max() <= acc["horizontal_max_m"], (err.max(), acc)
    assert acc["horizontal_95_m"] < 4 * SIGMA_M
    # curvature-continuous fit reduced to chords: far fewer vertices than survey points, ends on the nodes
    e = built.topology.edges["e1"]
    assert 10 < len(e.points_llh) < 200 and built.fits["e1"].outliers == 0
    assert built.topology.accuracy == acc
    again = Topology.from_dict(built.topology.to_dict())
    assert again.accuracy == acc


def test_outliers_are_dropped_and_do_not_bend_the_map():
    outliers = [(150, np.array([2.0, -1.0])), (151, np.array([1.5, 0.5])), (300, np.array([-0.4, 0.3]))]
    built = build_map(_description(), _survey(3, outliers=outliers))
    assert built.fits["e1"].outliers >= 3
    err = map_error_m(built.topology, _truth_map(), step_m=0.5)
    assert err.max() < 4 * SIGMA_M, err.max()


def test_a_gap_is_bridged_along_the_curve_and_reported_a_long_one_refused():
    built = build_map(_description(), _survey(4, gap=(160.0, 190.0)))  # 30 m on the arc (sagitta 0.37 m)
    (a, b), = built.fits["e1"].gaps_m
    assert 29.0 < b - a < 33.0
    err = map_error_m(built.topology, _truth_map(), step_m=0.5)
    assert err.max() < 0.05, err.max()
    with pytest.raises(TopologyError, match="edge e1: survey gap of"):
        build_map(_description(), _survey(4, gap=(110.0, 110.0 + MAX_GAP_M + 20.0)))


def test_survey_must_cover_every_edge_and_name_known_edges():
    sv = _survey(5)
    sv["runs"][0]["edge"] = "zz"
    with pytest.raises(TopologyError, match="edge zz is not in the layout description"):
        build_map(_description(), sv)
    sv["runs"] = []
    with pytest.raises(TopologyError, match="edge e1: not in the survey"):
        build_map(_description(), sv)
    with pytest.raises(TopologyError, match="format"):
        build_map(_description(), {"format": "other"})


@pytest.mark.slow
def test_alpha_beta_built_from_a_simulated_survey_keeps_topology_and_is_centimetric():
    from augnet.track.topology_file import load_topology
    from stations.layout import Layout, layout_path
    from stations.survey import survey_run

    layout = Layout.load("alpha-beta")
    desc = load_topology(layout_path("alpha-beta"))
    truth = Topology.from_dict(layout.truth_topology_dict())
    s1, _ = survey_run(layout, 1, gaps=(("t1b", 1000.0, 1030.0),))
    s2, _ = survey_run(layout, 2)
    built = build_map(desc, s1)
    acc = verify(built, s2)
    err = map_error_m(built.topology, truth)
    assert set(built.topology.edges) == set(desc.edges) and set(built.topology.turnouts) == set(desc.turnouts)
    assert np.percentile(err, 95) <= acc["horizontal_95_m"] < 0.04 and err.max() < 0.06, (acc, err.max())
    # the design chords are decimetres off the as-built crossover: the reason the map is surveyed
    assert map_error_m(desc, truth).max() > 0.3


@pytest.mark.slow
def test_cli_survey_then_build_map_writes_the_map_with_its_accuracy(tmp_path):
    from typer.testing import CliRunner

    from augnet.track.cli import app as track_app
    from augnet.track.topology_file import load_topology
    from stations.cli import sim_app
    from stations.layout import layout_path

    runner = CliRunner()
    for seed in (1, 2):
        r = runner.invoke(sim_app, ["survey", "--seed", str(seed), "--out", str(tmp_path / f"s{seed}.json")])
        assert r.exit_code == 0, r.output
    r = runner.invoke(track_app, ["build-map", "--layout", str(layout_path("alpha-beta")), "--survey",
                                  str(tmp_path / "s1.json"), "--verify", str(tmp_path / "s2.json"),
                                  "--out", str(tmp_path / "map.json")])
    assert r.exit_code == 0, r.output
    built = load_topology(tmp_path / "map.json")
    assert built.accuracy["verified_against"] == "survey seed 2" and built.accuracy["horizontal_95_m"] < 0.04
    r = runner.invoke(sim_app, ["survey", "--gap", "t1b:100", "--out", str(tmp_path / "bad.json")])
    assert r.exit_code == 2 and "EDGE:FROM_M:TO_M" in r.output
