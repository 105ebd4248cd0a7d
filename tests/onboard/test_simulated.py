"""Simulated must-show cases (the stations package records a scenario with its truth; the onboard core
only sees RINEX, broadcast ephemerides and, for the train, the track database exported from the
scenario's line): fix rate after the first fix, time to first fix, accuracy at 95 %, no wrong fix,
error within the protection level in every epoch, track identity in every epoch, virtual balise
captures (none missed or false) within 0.5 m.

Figures when written: baseline-10km (120 s) 120/120 fixed from the first epoch, H95 ~0.8 cm,
V95 ~0.8 cm; demo train G101 (160 km/h, 8-11 km from STA2, 60 s, with baseline-10km's calm night
atmosphere because this is single-base RTK, not the centre's VRS) fixed throughout, right track in
every epoch, 5/5 balises captured within a few centimetres.  network-70km needs the centre's VRS
(single-base RTK over 35 km stays float: no fix, and no wrong fix).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_enu, ecef_to_geodetic, enu_rotation
from augnet.onboard.balise import BaliseDetector, ListSink
from augnet.onboard.inputs import load_nav, load_obs
from augnet.onboard.postprocess import process
from augnet.onboard.rtk import RtkOptions, Status
from augnet.onboard.trackmap import FORMAT, TrackDatabase, gaussian_k

stations_record = pytest.importorskip("stations.record")
from stations.recording import load_truth  # noqa: E402
from stations.scenario import load_scenario  # noqa: E402

INTEGRITY_RISK = 1e-7
WRONG_FIX_M = 0.10


def _record(name, duration, out, calm_atmosphere_from=None):
    sc = load_scenario(name).model_copy(update={"duration_s": duration})
    if calm_atmosphere_from:
        # single-base RTK over ~10 km without the centre's VRS needs a calm ionosphere (the daytime
        # quiet preset gives ~2 cm of DD ionosphere at 10 km, which no short-baseline engine fixes)
        calm = load_scenario(calm_atmosphere_from).errors
        sc = sc.model_copy(update={"errors": sc.errors.model_copy(
            update={"ionosphere": calm.ionosphere, "troposphere": calm.troposphere})})
    stations_record.record(sc, out, rtcm=False)
    return sc


def _run(folder, base, rover, opt=None):
    nav, alpha, beta = load_nav([folder / "nav.rnx"])
    truth = load_truth(folder)
    sols = list(process(load_obs(folder / f"{rover}.obs"), load_obs(folder / f"{base}.obs"), nav,
                        truth[base].ecef_m[0], opt or RtkOptions()))
    true_pos = truth[rover].at([round(s.time) for s in sols])
    return sols, true_pos, truth[rover]


def _check_rtk_figures(sols, true_pos):
    status = np.array([s.status for s in sols])
    fixed = status == Status.FIX
    assert fixed.any(), sols[0].message
    first = int(np.argmax(fixed))
    assert first <= 10  # time to first fix <= 10 s at 1 Hz
    assert fixed[first:].mean() >= 0.99
    enu = np.array([ecef_to_enu(s.position_m - p, p) for s, p in zip(sols, true_pos)])
    h = np.hypot(enu[:, 0], enu[:, 1])
    v = np.abs(enu[:, 2])
    assert np.percentile(h[fixed], 95) <= 0.02
    assert np.percentile(v[fixed], 95) <= 0.04
    assert not np.any(np.linalg.norm(enu[fixed], axis=1) > WRONG_FIX_M)  # no wrong fix
    # protection levels from the filter covariance: no epoch whose error exceeds them
    k = gaussian_k(INTEGRITY_RISK)
    for s, e in zip(sols, enu):
        llh = ecef_to_geodetic(s.position_m)
        R = enu_rotation(llh[0], llh[1])
        C = R @ s.covariance_m2 @ R.T
        hpl = k * math.sqrt(max(np.linalg.eigvalsh(C[:2, :2])))
        vpl = k * math.sqrt(C[2, 2])
        assert math.hypot(e[0], e[1]) <= hpl and abs(e[2]) <= vpl, (s.time, s.status_name, e, hpl, vpl)
    return fixed, h, v


def test_baseline_10km_static(tmp_path):
    _record("baseline-10km", 120, tmp_path)
    sols, true_pos, _ = _run(tmp_path, "A", "B")
    fixed, h, v = _check_rtk_figures(sols, true_pos)
    print(f"baseline-10km: {fixed.sum()}/{len(sols)} fixed, H95 {np.percentile(h, 95) * 100:.2f} cm, "
          f"V95 {np.percentile(v, 95) * 100:.2f} cm")


def _export_track_db(sc, km_from, km_to, balise_kms) -> TrackDatabase:
    """The scenario's main-line tracks as an augnet-trackmap/1 database (what the simulator should export),
    a virtual balise on track 1 at each km, and decoys at the same km on track 2."""
    from stations.track import TrackLine

    line = TrackLine(sc.line)
    s = np.arange(km_from * 1000.0, km_to * 1000.0 + 1.0, 20.0)
    tracks = []
    for k in range(1, sc.line.tracks + 1):
        llh = line.plane_to_geodetic(line.point(s, line.track_offset_m(k)))
        tracks.append({"id": line.track_id(k), "line": sc.line.id, "points": llh.tolist(), "km": (s / 1000.0).tolist()})
    balises = [{"id": f"VB{i}", "track": line.track_id(1), "km": km, "telegram": f"{i:04x}"} for i, km in enumerate(balise_kms)]
    balises += [{"id": f"DECOY{i}", "track": line.track_id(2), "km": km, "telegram": "00"} for i, km in enumerate(balise_kms)]
    return TrackDatabase.from_dict({"format": FORMAT, "name": sc.name, "tracks": tracks, "balises": balises})


def test_demo_train_track_identity_and_virtual_balises(tmp_path):
    sc = _record("demo", 60, tmp_path, calm_atmosphere_from="baseline-10km")
    sols, true_pos, truth = _run(tmp_path, "STA2", "G101")
    fixed, h, v = _check_rtk_figures(sols, true_pos)
    balise_kms = [80.5, 81.0, 81.5, 82.0, 82.5]
    db = _export_track_db(sc, 79.5, 83.5, balise_kms)
    sink = ListSink()
    det = BaliseDetector(db, sink)
    for s in sols:
        m = db.match(s.position_m, s.covariance_m2, integrity_risk=INTEGRITY_RISK)
        t_idx = int(np.flatnonzero(np.isclose(truth.t_gpst, round(s.time)))[0])
        assert m.track == truth.track[t_idx]  # the right track in every epoch
        if s.status == Status.FIX:
            assert m.confirmed
        det.update(s.time, m)
    assert [e.balise_id for e in sink.events] == [f"VB{i}" for i in range(len(balise_kms))]  # none missed/false
    # capture error: where the true antenna was (on the map) at the capture time, against the balise
    errs = []
    for e in sink.events:
        i = int(np.searchsorted(truth.t_gpst, e.time))
        w = (e.time - truth.t_gpst[i - 1]) / (truth.t_gpst[i] - truth.t_gpst[i - 1])
        p = truth.ecef_m[i - 1] * (1 - w) + truth.ecef_m[i] * w
        true_along = db.match(p).along_m
        err = true_along - db.along_m(e.track, e.km)
        assert abs(err) <= 0.5, (e, err)
        assert e.along_pl_m < 0.5
        errs.append(err)
    print(f"demo G101: {fixed.sum()}/{len(sols)} fixed, H95 {np.percentile(h, 95) * 100:.2f} cm; balise capture "
          f"errors {', '.join(f'{x * 100:.1f}' for x in errs)} cm")


def test_35km_single_base_without_vrs_never_reports_a_wrong_fix(tmp_path):
    """Beyond the short-baseline model (DD ionosphere of several cm unmodelled) the filter must stay
    float rather than fix wrongly; fixing there is the centre's VRS's job."""
    _record("network-70km", 60, tmp_path)
    sols, true_pos, _ = _run(tmp_path, "NORTH", "check1")
    err = np.array([np.linalg.norm(s.position_m - p) for s, p in zip(sols, true_pos)])
    fixed = np.array([s.status == Status.FIX for s in sols])
    assert not np.any(fixed & (err > WRONG_FIX_M))
    assert all(s.status in (Status.FIX, Status.FLOAT) for s in sols)
    assert np.all(err < 2.0)  # float, but a sound float


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "not met yet (measured 2026-11-22, 120 s): network-70km, check1 (static, treated as a moving rover) "
    "against the centre's VRS 28 m away: kinematic 35/120 fixed from 27 s, H95 7.5 cm, worst 16.5 cm "
    "(wrong fixes: the float is 30-70 cm off, DD code residuals ~1 m, and fix-and-hold keeps the first "
    "wrong set); static mode 89/120 fixed, H95 2.8 cm, worst 5.1 cm. Needs: ionosphere-weighted float "
    "(or estimated DD ionosphere), a VRS with cm-level DD errors, and fix validation over time."))
def test_network_70km_with_the_centre_vrs(tmp_path):
    from typer.testing import CliRunner

    from augnet.cli import _mount, app

    _record("network-70km", 120, tmp_path)
    truth = load_truth(tmp_path)["check1"]
    llh = ecef_to_geodetic(truth.ecef_m[0] + np.array([15.0, -20.0, 5.0]))  # a VRS near, not at, the rover
    _mount()
    r = CliRunner().invoke(app, ["vrs", "--record", str(tmp_path), "--at",
                                 f"{math.degrees(llh[0])},{math.degrees(llh[1])},{llh[2]}",
                                 "--out", str(tmp_path / "VRS.obs"), "--exclude", "check1"])
    if r.exit_code != 0:
        pytest.skip(f"augnet vrs unavailable: {r.output[-200:]}")
    nav, _, _ = load_nav([tmp_path / "nav.rnx"])
    vrs = load_obs(tmp_path / "VRS.obs")
    sols = list(process(load_obs(tmp_path / "check1.obs"), vrs, nav, vrs.approx_position_m, RtkOptions()))
    true_pos = truth.at([round(s.time) for s in sols])
    _check_rtk_figures(sols, true_pos)
