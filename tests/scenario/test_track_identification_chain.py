"""Track identification in the full simulated chain (issue 16): the onboard RTK solutions of trains taking the
Alpha crossover, through `augnet.track.identification` on the as-built map; truth only judges."""

from __future__ import annotations

import pytest

from augnet.scenario.runner import load, simulate
from augnet.scenario.track_identification import identify
from augnet.track.survey_map import build_map
from augnet.track.topology import Topology
from augnet.track.topology_file import load_topology
from stations.layout import Layout, layout_path
from stations.survey import survey_run
from tests.conftest import LONG_RUN_TIMEOUT_S

pytestmark = [pytest.mark.slow, pytest.mark.timeout(LONG_RUN_TIMEOUT_S)]


def test_crossover_both_ways_right_track_in_every_decided_epoch():
    sc = load("alpha-beta")
    sc = sc.model_copy(update={"duration_s": 60.0, "trains": [t for t in sc.trains if t.id in ("R1", "R3")]})
    log = simulate(sc, warm_up_s=60)
    layout = Layout.load(sc.layout.file)
    res = identify(log, Topology.from_dict(layout.truth_topology_dict()), layout)
    print(res.text())
    t = res.totals()
    # the first ~12 of the 60 s are before the first fix (float, metre-level errors): "unknown" there
    assert t["wrong"] == 0 and t["decided"] > 0.6 * t["epochs"], t
    facing = [p for p in res.passages if p.facing]
    # R1 up and R3 down each take the crossover from its toe: the leg is decided, and before the train is
    # a crossover's length past the frog (60 m)
    assert sorted(p.switch for p in facing) == ["swA1", "swA2"] and all(p.leg_track == "X12" for p in facing)
    assert all(p.decided_after_frog_m < 60.0 for p in facing), [p.decided_after_frog_m for p in facing]
    assert len(res.passages) == 4 and all(p.wrong == 0 for p in res.passages)
    # the same solutions on the map built from a survey run (the estimator's map, not the truth's)
    built = build_map(load_topology(layout_path(sc.layout.file)), survey_run(layout, 1)[0])
    on_built = identify(log, built.topology, layout).totals()
    assert on_built["wrong"] == 0 and on_built["facing_decided"] == 2, on_built
