"""The four along-track methods side by side over every epoch of a short demo-line run, tunnel included.

The demo scenario (line, stations, sky) with 60 s of warm-up and 120 s of two trains at
160 km/h on wet rail: G101 (track 1, +km) runs clean through the tunnel; G102 (track 2, -km) runs through it
the other way and has its wheels slide (30 % of the speed lost) for 3 s in open sky afterwards. The centre's
network of six stations is the run's cost (~2 min CPU on the shared machine).
"""

from __future__ import annotations

import pytest

from augnet.onboard.along_track_fusion import METHODS
from augnet.scenario import report as R
from augnet.scenario.runner import load, simulate
from stations.scenario import Fault, Train
from tests.conftest import LONG_RUN_TIMEOUT_S

pytestmark = [pytest.mark.slow, pytest.mark.timeout(LONG_RUN_TIMEOUT_S)]

SLIDE_AT_S, SLIDE_UNTIL_S = 100.0, 103.0


def fusion_scenario():
    sc = load("demo")
    trains = [Train(id="G101", track=1, start_km=99.0, direction=1, start_speed_kmh=160, speed_kmh=160,
                    wheel_radius_error_pct=0.05),
              Train(id="G102", track=2, start_km=103.5, direction=-1, start_speed_kmh=160, speed_kmh=160,
                    wheel_radius_error_pct=-0.08)]
    slide = Fault(kind="odometer_slide", at_s=SLIDE_AT_S, until_s=SLIDE_UNTIL_S, train="G102", slide_fraction=0.3)
    return sc.model_copy(update={"name": "demo-fusion", "duration_s": 120.0,
                                 "trains": trains, "faults": [slide], "rail": "wet"})


@pytest.fixture(scope="module")
def fused():
    log = simulate(fusion_scenario(), warm_up_s=60)
    rep = R.build(log)
    return log, {tid: rep.trains[tid]["along_track_fusion"] for tid in log.trains}


def test_weighted_median_is_the_most_available_and_never_misleads(fused):
    _, figs = fused
    g = figs["G101"]
    assert set(g) == set(METHODS)
    assert g["gnss_raim"]["epochs"] == 120 and g["gnss_raim"]["epochs_without_sky"] > 30  # the tunnel
    for m in METHODS:
        assert g["weighted_median"]["available"] >= g[m]["available"], (m, g)
    for tid in ("G101", "G102"):
        assert figs[tid]["weighted_median"]["hmi"] == 0, figs[tid]
        assert figs[tid]["residual_weighted_median"]["hmi"] == 0, figs[tid]


def test_gnss_alone_is_unavailable_in_the_tunnel_and_the_fusion_carries_on(fused):
    log, figs = fused
    for tid, tl in log.trains.items():
        assert figs[tid]["gnss_raim"]["available_without_sky"] == 0
        inside = [f for f, n in zip(tl.fused["weighted_median"], tl.n_tracked) if n == 0]
        assert inside and all(f.odometry_only for f in inside)
        assert inside[-1].pl_m > inside[0].pl_m  # the protection level grows on odometry


def test_injected_slide_is_caught_at_its_first_epoch(fused):
    log, figs = fused
    tl = log.trains["G102"]
    for m in METHODS[1:]:
        f = figs["G102"][m]
        assert f["rejected_fixes"] >= 1 and f["alarms"] >= 1 and f["hmi"] == 0, (m, f)
        during = [x for x, t in zip(tl.fused[m], tl.t_s) if SLIDE_AT_S <= t < SLIDE_UNTIL_S]
        assert during and not any(x.available for x in during), m  # withdrawn from the first sliding epoch
    assert figs["G102"]["gnss_raim"]["rejected_fixes"] == 0  # GNSS alone does not read the odometer
