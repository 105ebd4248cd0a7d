"""The centre's 4001 bound in the train's protection levels, in the simulated chain (issue 15, decision 0281).

One short demo-line run twice, the centre sending the bound (`correction_bound=True`) and not: the RTK
solutions are the same (a 4001 is not an observation), so every difference in the PLs is the bound's. On:
each float / fixed epoch's along- and cross-track PL is K x hypot(its receiver sigma, the bound carried to
the axis), larger than off, and no epoch is misleading (error beyond its PL while available). Off: no bound
term anywhere, the PLs as K x the receiver sigma."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_enu
from augnet.onboard.integrity_allocation import ALONG_TRACK_ALERT_LIMIT_M, CROSS_TRACK_ALERT_LIMIT_M
from augnet.onboard.rtk import Status
from augnet.onboard.trackmap import gaussian_k
from augnet.scenario import report as R
from augnet.scenario.runner import load, simulate
from stations.scenario import Train
from tests.conftest import LONG_RUN_TIMEOUT_S

pytestmark = [pytest.mark.slow, pytest.mark.timeout(LONG_RUN_TIMEOUT_S)]

DURATION_S = 60.0
WARM_UP_S = 60.0  # the centre's bound needs a 30-epoch window before it is finite (decision 0280)


def _scenario():
    sc = load("demo")
    trains = [Train(id="G101", track=1, start_km=80.0, direction=1, start_speed_kmh=160, speed_kmh=160)]
    return sc.model_copy(update={"name": "demo-bound", "duration_s": DURATION_S, "trains": trains, "faults": []})


@pytest.fixture(scope="module")
def runs():
    return {on: simulate(_scenario(), warm_up_s=WARM_UP_S, correction_bound=on) for on in (False, True)}


from augnet.onboard.integrity_allocation import DEFAULT_ALLOCATION, GNSS_FAULT_MODES  # noqa: E402


def _arrays(log):
    tl = log.trains["G101"]
    return {k: np.array(getattr(tl, k), float) for k in
            ("status", "along_pl_m", "cross_pl_m", "correction_along_m", "correction_cross_m", "along_sigma_m",
             "cross_sigma_m")}, tl


def test_with_the_bound_on_the_pls_grow_by_it_and_without_it_they_are_unchanged(runs):
    off, tl_off = _arrays(runs[False])
    on, tl_on = _arrays(runs[True])
    assert np.array_equal(off["status"], on["status"])  # the 4001 changes no solution
    assert np.array_equal(np.array(tl_off.position), np.array(tl_on.position))
    assert np.all(off["correction_along_m"] == 0) and np.all(off["correction_cross_m"] == 0)
    rtk = np.isin(on["status"], [Status.FIX, Status.FLOAT]) & np.isfinite(off["along_pl_m"])
    assert rtk.sum() >= DURATION_S / 2
    k = gaussian_k(runs[True].integrity_risk)
    for axis in ("along", "cross"):
        corr = on[f"correction_{axis}_m"][rtk]
        assert np.all(np.isfinite(corr)) and np.all(corr > 0)  # every RTK epoch bounded, none unbounded
        # the bound inflates the receiver sigma in quadrature; the PL is then max(K sigma, fault bounds) (0253)
        sig = np.hypot(off[f"{axis}_sigma_m"][rtk], corr)
        assert on[f"{axis}_sigma_m"][rtk] == pytest.approx(sig, rel=1e-9)
        grown = np.array([max(k * s, DEFAULT_ALLOCATION.fault_bound(s, axis, GNSS_FAULT_MODES)) for s in sig])
        assert on[f"{axis}_pl_m"][rtk] == pytest.approx(grown, rel=1e-9)
        assert np.all(on[f"{axis}_pl_m"][rtk] > off[f"{axis}_pl_m"][rtk])
    # outside the RTK epochs (no corrections used) nothing changes
    assert on["along_pl_m"][~rtk] == pytest.approx(off["along_pl_m"][~rtk])
    print("bound on the along-track axis [m] p50/max:", np.median(on["correction_along_m"][rtk]),
          on["correction_along_m"][rtk].max(), "PL on/off p50 [m]:", np.median(on["along_pl_m"][rtk]),
          np.median(off["along_pl_m"][rtk]))


def test_with_the_bound_on_nothing_is_misleading(runs):
    log = runs[True]
    arr, tl = _arrays(log)
    truth_km = np.array(tl.truth_km, float)
    # the matched chainage against the truth's (along-track error) and the horizontal error (an upper bound
    # of the cross-track one)
    km = []
    for pos in tl.position:
        m = log.track_db.match(pos) if np.all(np.isfinite(pos)) else None
        km.append(m.km if m is not None and m.track else math.nan)
    along_err = np.abs(np.array(km) - truth_km) * 1000.0
    truth = np.array(tl.truth_position)
    est = np.array(tl.position)
    h_err = np.array([np.linalg.norm(ecef_to_enu(e - t, t)[:2]) if np.all(np.isfinite(e)) else math.nan
                      for e, t in zip(est, truth)])
    along_avail = arr["along_pl_m"] <= ALONG_TRACK_ALERT_LIMIT_M
    cross_avail = arr["cross_pl_m"] <= CROSS_TRACK_ALERT_LIMIT_M
    assert along_avail.sum() > 0 and cross_avail.sum() > 0
    assert not np.any(along_avail & (along_err > arr["along_pl_m"]))
    assert not np.any(cross_avail & (h_err > arr["cross_pl_m"]))
    fusion = R.build(log).trains["G101"]["along_track_fusion"]
    assert all(v["hmi"] == 0 for v in fusion.values()), fusion
