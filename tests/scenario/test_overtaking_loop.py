"""Overtaking on a loop track through the section register: on the alpha-beta layout a slow train S enters
Beta's loop and waits at the platform; a fast train F, which left Alpha after it, runs through Beta on the main
track and leaves first. The simulator's route kinematics (stations.world.route_motion: the trains follow the
topology, halt at their stops) give each train's chainage every second; the reports go as datagrams into the
centre's SectionService. The register's order must match the true order in every section at every epoch, the
arrival order (S, F) and the departure order (F, S) must come from Beta's removes and inserts, and nothing is
refused. (The GNSS chain's position errors are centimetres on fixed solutions (decision 0291); the register's
rules are what this test judges, so it feeds the route's chainage.)"""

from __future__ import annotations

import numpy as np
import pytest

from augnet.onboard.position_report import ReportBuilder, encode
from augnet.system.section_service import SectionService, StationArea
from stations.layout import Layout
from stations.scenario import Stop, Train
from stations.world import route_motion

# Alpha's area from the layout (line start to its exit boundary sb1 at km 3.0); Beta's from its entry boundary
# (km 7.0) to km 9.5, 500 m past switch B2 (the layout's Beta runs to the buffer stops at km 10.0, which would
# leave no section after Beta to check the departure order in).
AREAS = [StationArea("Alpha", 0.0, 3.0), StationArea("Beta", 7.0, 9.5)]
LINE_KM = 10.0
PL_M = 0.05  # a fixed solution's along-track PL order (decision 0291), reported with every position
SLOW = Train(id="S", start_km=2.0, direction=1, speed_kmh=80, length_m=209.0,
             route=["t1a.1", "t1b", "t1c.0", "l3a", "l3b", "l3c", "t1c.2"],
             stops=[Stop(km=8.5, dwell_s=240.0), Stop(km=9.7, dwell_s=1000.0)])  # platform; then behind F
FAST = Train(id="F", start_km=0.5, direction=1, speed_kmh=160, length_m=209.0,
             route=["t1a.0", "t1a.1", "t1b", "t1c.0", "t1c.1", "t1c.2"], stops=[Stop(km=1.0, dwell_s=60.0)])


@pytest.fixture(scope="module")
def run():
    layout = Layout.load("alpha-beta")
    t = np.arange(0.0, 700.0)
    paths = {}
    for tr in (SLOW, FAST):
        route, um, _v = route_motion(layout, tr, t)
        _xy, _z, km, ei, _ = route.at(um)
        paths[tr.id] = (km, np.array(route.edges, dtype=object)[ei], tr.length_m)
    svc = SectionService(AREAS, LINE_KM)
    builders = {tid: ReportBuilder(tid, p[2], integrity="confirmed") for tid, p in paths.items()}
    mismatches, checked, where = [], {}, {tid: [] for tid in paths}
    for k, tk in enumerate(t):
        for tid, (km, edges, _l) in paths.items():
            r = builders[tid].build(1e6 + tk, edges[k], float(km[k]), correction_age_s=1.0, along_pl_m=PL_M,
                                    cross_pl_m=PL_M, hpl_m=None, vpl_m=None, track_confirmed=True)
            svc.on_datagram(encode(r))
            where[tid].append((svc.register.where(tid), svc.in_station.get(tid)))
        for (sid, d), q in svc.register.queues.items():
            ids = q.ids()
            if len(ids) >= 2:
                checked[sid] = checked.get(sid, 0) + 1
                truth = tuple(sorted(ids, key=lambda x: -paths[x][0][k]))
                if truth != ids:
                    mismatches.append((tk, sid, d, ids, truth))
    return svc, paths, mismatches, checked, where


def test_order_preserved_and_the_overtaking_is_the_stations(run):
    svc, paths, mismatches, checked, where = run
    assert mismatches == []
    # both trains in section 1 (Alpha - Beta) for ~30 s and in section 2 (Beta - line end) for ~55 s
    assert checked.get(1, 0) >= 20 and checked.get(2, 0) >= 20, checked
    ev = [(e.train_id, e.action, e.section_id, e.by) for e in svc.events]
    print(ev, dict(svc.stats))
    assert ev == [("S", "insert", 1, "Alpha"), ("F", "insert", 1, "Alpha"),
                  ("S", "remove", 1, "Beta"), ("F", "remove", 1, "Beta"),
                  ("F", "insert", 2, "Beta"), ("S", "insert", 2, "Beta")]
    assert not any(k.startswith("refused_") for k in svc.stats), dict(svc.stats)
    assert [r.train_id for r in svc.register.trains(2, "up")] == ["F", "S"]
    # F truly passed S, and while it did S stood in Beta on the loop track (edge l3b), in no section
    s_km, f_km = paths["S"][0], paths["F"][0]
    passed = int(np.argmax(f_km > s_km))
    assert passed > 0 and s_km[0] > f_km[0]
    assert s_km[passed] == pytest.approx(8.5) and s_km[passed - 5] == pytest.approx(8.5)  # S waiting
    assert where["S"][passed] == (None, ("Beta", "l3b")) and paths["S"][1][passed] == "l3b"


def test_section_behind_released_once_the_confirmed_rears_are_out(run):
    svc, *_ = run
    q1 = svc.register.queue(1, "up")
    assert len(q1) == 0 and q1.left_behind == {} and q1.occupied_from_km() is None
    q2 = svc.register.queue(2, "up")
    assert q2.occupied_from_km() == pytest.approx(9.7 - 0.209, abs=1e-6)  # S's confirmed rear, at its stop
