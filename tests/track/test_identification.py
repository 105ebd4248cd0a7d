"""Track identification (augnet/track/identification.py) on the Alpha-Beta railML test line: tracks 1
and 2 4.6 m apart, crossover A1 -> A2 at km 1.5-1.56, loop 3 at Beta (km 8-9)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.onboard.integrity_allocation import DEFAULT_ALLOCATION
from augnet.track.campaign import run_campaign
from augnet.track.identification import (TrackIdentifier, fix_from_position, fix_from_solution,
                                         topology_transitions)
from augnet.track.topology_file import import_railml

LINE = Path(__file__).with_name("two_stations.railml")
FIXED_SIGMA_M = 0.015
FLOAT_SIGMA_M = 0.3


@pytest.fixture(scope="module")
def topo():
    return import_railml(LINE)


def fix_at(topo, edge, along_m, t, sigma=FIXED_SIGMA_M, offset_en=(0.0, 0.0)):
    """A fix at `along_m` on `edge`, moved by `offset_en` [m] east/north, with a horizontal sigma."""
    x = topo.point_at_m(edge, along_m)
    llh = ecef_to_geodetic(x)
    r = enu_rotation(llh[0], llh[1])
    cov = r.T @ np.diag([sigma ** 2, sigma ** 2, (2 * sigma) ** 2]) @ r
    return fix_from_position(t, x + r.T @ np.array([offset_en[0], offset_en[1], 0.0]), cov)


def everywhere(topology, edge, km, distance_m):
    """The topology constraint removed: any edge may follow any edge."""
    return set(topology.edges)


def feed_on_track_2_from_track_1(topo, transitions):
    """A train known on track 1 (edge t1b, km 5, far from any switch); the fixes then say track 2
    (a 4.6 m jump north: a wrong fix, not a move the line allows)."""
    ident = TrackIdentifier(topo, transitions=transitions)
    ident.start("t1b", 5.0, 0.0)
    along0 = topo.along_m("t2b", 5.0)
    return [ident.update(fix_at(topo, "t2b", along0 + 20.0 * k, float(k))) for k in range(1, 31)]


def test_never_decides_a_track_not_connected_to_the_one_it_was_on(topo):
    out = feed_on_track_2_from_track_1(topo, topology_transitions)
    assert not any(d.track == "2" for d in out)
    # the fixes fit no track the train may be on: no decision at all, rather than a guess
    assert all(d.status == "inconsistent" for d in out)


def test_without_the_topology_constraint_the_same_fixes_decide_track_2(topo):
    # the test above fails if the identifier's transitions ignore the topology
    out = feed_on_track_2_from_track_1(topo, everywhere)
    assert sum(d.track == "2" for d in out) >= 25


def test_through_the_crossover_track_2_is_reached_and_decided(topo):
    ident = TrackIdentifier(topo)
    L = topo.length_m("t1a.0")
    ident.start("t1a.0", topo.km_at("t1a.0", L - 100.0), 0.0)
    t, out = 0.0, []
    for s in np.arange(L - 80.0, L, 20.0):
        t += 1.0
        out.append(ident.update(fix_at(topo, "t1a.0", s, t)))
    for s in np.arange(2.0, topo.length_m("x12"), 2.0):
        t += 0.2
        out.append(ident.update(fix_at(topo, "x12", s, t)))
    for s in np.arange(10.0, 200.0, 20.0):
        t += 1.0
        out.append(ident.update(fix_at(topo, "t2a.1", s, t)))
    assert [d.track for d in out[:4]] == ["1"] * 4
    assert "X12" in [d.track for d in out]
    assert out[-1].track == "2" and out[-1].edge == "t2a.1"
    assert not any(d.track == "1" for d in out[5:])  # once past the switch never back on track 1


def test_ambiguous_just_past_the_switch_is_unknown(topo):
    ident = TrackIdentifier(topo)
    L = topo.length_m("t1a.0")
    ident.start("t1a.0", topo.km_at("t1a.0", L - 20.0), 0.0)
    # 4 m into the crossover the legs are 0.3 m apart: one float sigma
    d = ident.update(fix_at(topo, "x12", 4.0, 1.0, sigma=FLOAT_SIGMA_M))
    assert d.status == "unknown" and d.track is None
    assert d.other_mass > ident.decision_risk
    assert set(d.tracks) >= {"1", "X12"}


def test_cold_start_between_parallel_tracks_is_unknown(topo):
    ident = TrackIdentifier(topo)
    along = topo.along_m("t1b", 5.0)
    # halfway between track 1 and track 2 (north of track 1), a poor float fix (sigma 1 m)
    d = ident.update(fix_at(topo, "t1b", along, 0.0, sigma=1.0, offset_en=(0.0, 2.3)))
    assert d.status == "unknown" and set(d.tracks) == {"1", "2"}
    assert abs(d.tracks["1"] - d.tracks["2"]) < 0.2


def test_fix_beyond_its_protection_level_from_every_track_is_inconsistent(topo):
    ident = TrackIdentifier(topo)
    along = topo.along_m("t1b", 5.0)
    # halfway again, but a float fix claiming 0.3 m: 2.3 m is beyond its PL from both tracks
    d = ident.update(fix_at(topo, "t1b", along, 0.0, sigma=FLOAT_SIGMA_M, offset_en=(0.0, 2.3)))
    assert d.status == "inconsistent" and d.track is None


def test_cold_start_on_a_fixed_fix_decides_its_track(topo):
    ident = TrackIdentifier(topo)
    d = ident.update(fix_at(topo, "t2b", topo.along_m("t2b", 5.0), 0.0))
    assert d.status == "decided" and d.track == "2" and d.other_mass <= ident.decision_risk


def test_decision_risk_is_the_allocated_per_decision_risk(topo):
    ident = TrackIdentifier(topo)
    assert ident.decision_risk == DEFAULT_ALLOCATION.per_decision_risk
    assert 1e-14 < ident.decision_risk < 1e-12  # 1e-9 /h x 0.5 / 3600 (decision 0250)


def test_fix_sigma_is_widened_to_the_protection_level(topo):
    f = fix_at(topo, "t1b", 100.0, 0.0)
    sigma_eff = math.sqrt(float(np.linalg.eigvalsh(f.cov_en_m2)[-1]))
    pl = DEFAULT_ALLOCATION.protection_level(FIXED_SIGMA_M, "cross")
    assert sigma_eff * DEFAULT_ALLOCATION.k_fault_free == pytest.approx(pl, rel=0.02)
    assert sigma_eff > 2 * FIXED_SIGMA_M  # the 0.5 m fault bias dominates a fixed solution's PL


def test_fix_from_solution_and_bad_input(topo):
    x = topo.point_at_m("t1b", 100.0)
    sol = SimpleNamespace(time=3.0, position_m=x, covariance_m2=np.eye(3) * 1e-4)
    f = fix_from_solution(sol)
    assert f is not None and f.time_s == 3.0
    assert fix_from_solution(SimpleNamespace(time=3.0, position_m=np.full(3, np.nan),
                                             covariance_m2=np.eye(3))) is None
    with pytest.raises(ValueError, match="finite"):
        fix_from_position(0.0, x, np.full((3, 3), np.nan))
    ident = TrackIdentifier(topo)
    ident.update(f)
    with pytest.raises(ValueError, match="older"):
        ident.update(fix_from_solution(SimpleNamespace(time=2.0, position_m=x, covariance_m2=np.eye(3) * 1e-4)))
    assert ident.update(None, 4.0).status == "no fix"


def test_an_onboard_rtk_solution_is_a_fix_the_identifier_decides_on(topo):
    from augnet.onboard.rtk import RtkSolution, Status

    x = topo.point_at_m("t2b", 1000.0)
    sol = RtkSolution(time=10.0, status=Status.FIX, position_m=x, covariance_m2=np.eye(3) * FIXED_SIGMA_M ** 2)
    d = TrackIdentifier(topo).update(fix_from_solution(sol))
    assert d.status == "decided" and d.track == "2" and d.edge == "t2b"


def test_campaign_smoke_crossover_and_loop_no_wrong_decision(topo):
    # seed 4: track 1 over the crossover to track 2 (up); seed 5: down track 1 through loop 3
    rep = run_campaign(topo, seeds=(4, 5))
    t = rep.totals()
    assert t["wrong"] == 0
    assert t["switches"] == 2 and t["switches_correct"] == 2
    assert t["decided"] >= 0.9 * t["epochs"]
    assert any("x12+" in r.route for r in rep.runs) and any("l3b-" in r.route for r in rep.runs)


def test_cli_campaign_prints_the_report_and_refuses_a_bad_line(tmp_path):
    from typer.testing import CliRunner

    from augnet.cli import _mount, app

    _mount()
    out = tmp_path / "totals.json"
    r = CliRunner().invoke(app, ["track", "campaign", "--line", str(LINE), "--runs", "1", "--json", str(out)])
    assert r.exit_code == 0, r.output
    assert "wrong 0" in r.output and "facing switches passed" in r.output
    assert '"epochs"' in out.read_text()
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "something else"}')
    r = CliRunner().invoke(app, ["track", "campaign", "--line", str(bad)])
    assert r.exit_code == 2 and "format" in r.output


@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_campaign_error_model_reports_its_sigma_honestly_unless_stressed(scale):
    from augnet.track.campaign import SolutionErrorModel

    m = SolutionErrorModel(np.random.default_rng(7), error_scale=scale)
    z, states = [], []
    for _ in range(20000):
        st, err, sig = m.step()
        states.append(st)
        if err is not None:
            z.append(err[:2] / sig[:2])
    z = np.array(z)
    assert np.std(z) == pytest.approx(scale, rel=0.15)  # AR(1), ~400 independent samples
    assert 0.6 < states.count("fixed") / len(states) < 0.9  # the stated fixed/float mixture
    with pytest.raises(ValueError):
        SolutionErrorModel(np.random.default_rng(0), error_scale=0.0)


def test_a_maps_stated_accuracy_widens_the_likelihood(topo):
    """A fix 0.7 m off track 1 far from any switch: beyond the fixed solution's PL (0.57 m) on an exact map
    (inconsistent), within it on a map whose verified accuracy is 0.4 m (95 %)."""
    from augnet.track.topology import Topology

    d = topo.to_dict()
    coarse = Topology.from_dict({**d, "accuracy": {"horizontal_95_m": 0.4}})
    out = {}
    for name, t in (("exact", topo), ("coarse", coarse)):
        ident = TrackIdentifier(t)
        ident.start("t1b", 5.0, 0.0)
        along = t.along_m("t1b", 5.0)
        out[name] = ident.update(fix_at(t, "t1b", along + 10.0, 1.0, offset_en=(0.0, -0.7)))
    assert out["exact"].status == "inconsistent"
    assert out["coarse"].status != "inconsistent" and out["coarse"].best_track == "1"
    assert TrackIdentifier(coarse).map_sigma_m == pytest.approx(0.4 / 1.96)
