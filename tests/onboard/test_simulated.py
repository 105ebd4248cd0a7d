"""Simulated must-show cases (the stations package records a scenario with its truth; the onboard core
only sees RINEX, broadcast ephemerides and, for the train, the track database exported from the
scenario's line): fix rate after the first fix, time to first fix, accuracy at 95 %, no wrong fix,
error within the protection level in every epoch, track identity in every epoch, virtual balise
captures (none missed or false) within 0.5 m.

Figures (2026-11-22, with the ionosphere-weighted filter: beyond ~7 km and against a VRS the SD
ionosphere is estimated and a fix is confirmed over 3 epochs): baseline-10km (120 s) fixed from 6 s and in
every epoch after, H95 ~1.1 cm, V95 ~1.1 cm (fixed epochs); demo train G101 (160 km/h, 8-11 km from STA2,
60 s, with baseline-10km's calm night atmosphere because this is single-base RTK, not the centre's VRS)
56/60 fixed, right track in every epoch, 5/5 balises captured within a centimetre.  network-70km: single-
base RTK over 35 km (ionosphere prior 7 cm) fixes rarely and never wrongly; with the centre's VRS see
`test_network_70km_with_the_centre_vrs`.
"""

from __future__ import annotations

import math
import re

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

pytestmark = pytest.mark.slow

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
    print(f"baseline-10km: {fixed.sum()}/{len(sols)} fixed, H95 {np.percentile(h[fixed], 95) * 100:.2f} cm, "
          f"V95 {np.percentile(v[fixed], 95) * 100:.2f} cm (fixed epochs)")


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
        assert abs(err) <= e.along_pl_m < 0.7  # the PL: 0.5 m satellite-fault bias + K_md sigma (decision 0253)
        errs.append(err)
    print(f"demo G101: {fixed.sum()}/{len(sols)} fixed, H95 {np.percentile(h[fixed], 95) * 100:.2f} cm (fixed); balise capture "
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


def _window(obs, t_from, t_to):
    """The epochs of an observation file in [t_from, t_to): a rover switched on at t_from."""
    from augnet.onboard.observations import ObsArrays

    m = (obs.times >= t_from) & (obs.times < t_to)
    return ObsArrays(obs.times[m], obs.sats, {k: v[m] for k, v in obs.obs.items()},
                     {k: v[m] for k, v in obs.lli.items()}, obs.approx_position_m, obs.marker_type)


def _errors_and_pl(sols, true_pos):
    """(fixed mask, horizontal error, vertical error, epochs whose error exceeds its protection level)."""
    fixed = np.array([s.status == Status.FIX for s in sols])
    enu = np.array([ecef_to_enu(s.position_m - p, p) for s, p in zip(sols, true_pos)])
    k = gaussian_k(INTEGRITY_RISK)
    over = []
    for s, e in zip(sols, enu):
        llh = ecef_to_geodetic(s.position_m)
        R = enu_rotation(llh[0], llh[1])
        C = R @ s.covariance_m2 @ R.T
        hpl = k * math.sqrt(max(np.linalg.eigvalsh(C[:2, :2])))
        vpl = k * math.sqrt(C[2, 2])
        if math.hypot(e[0], e[1]) > hpl or abs(e[2]) > vpl:
            over.append((s.time, s.status_name, e, hpl, vpl))
    return fixed, np.hypot(enu[:, 0], enu[:, 1]), np.abs(enu[:, 2]), over


def _wrong_dd_integers(sols, folder, rover, master, rover_shift=None):
    """(DD integers checked, the wrong ones) of every FIX against the simulator's ambiguities: a DD of
    rover minus base is the rover's minus the base's, and a VRS carries its master station's.
    `rover_shift`: (time, {(satellite, slot): cycles}) added to the rover's ambiguities from that time on."""
    from stations.recording import load_atmosphere

    atm = load_atmosphere(folder)
    keep = np.isin(atm["receiver"], [rover, master])
    N = {(int(round(t)), r, sat): (n1, n2) for t, r, sat, n1, n2 in zip(
        atm["gpst_s"][keep], atm["receiver"][keep], atm["sat"][keep], atm["N1_cyc"][keep], atm["N2_cyc"][keep])}
    checked, wrong = 0, []
    for s in sols:
        t = int(round(s.time))
        shift = rover_shift[1] if rover_shift is not None and s.time >= rover_shift[0] else {}
        for (sat, ref, f), value in s.fixed_dd.items():
            try:
                true = ((N[(t, rover, sat)][f] - N[(t, master, sat)][f])
                        - (N[(t, rover, ref)][f] - N[(t, master, ref)][f]))
            except KeyError:
                continue
            true += shift.get((sat, f), 0) - shift.get((ref, f), 0)
            checked += 1
            if value != round(true):
                wrong.append((s.time, sat, ref, f, value, true))
    return checked, wrong


@pytest.fixture(scope="module")
def network_70km_vrs(tmp_path_factory):
    """240 s of network-70km and the centre's VRS 28 m from check1 (from `augnet vrs` on the recording,
    check1 left out of the network): (folder, check1's truth, navigation, VRS, check1, VRS master)."""
    from typer.testing import CliRunner

    from augnet.cli import _mount, app

    folder = tmp_path_factory.mktemp("network70")
    _record("network-70km", 240, folder)
    truth = load_truth(folder)["check1"]
    llh = ecef_to_geodetic(truth.ecef_m[0] + np.array([15.0, -20.0, 5.0]))  # a VRS near, not at, the rover
    _mount()
    r = CliRunner().invoke(app, ["vrs", "--record", str(folder), "--at",
                                 f"{math.degrees(llh[0])},{math.degrees(llh[1])},{llh[2]}",
                                 "--out", str(folder / "VRS.obs"), "--exclude", "check1"])
    assert r.exit_code == 0, f"augnet vrs failed: {r.output[-2000:]}"
    m = re.search(r"VRS master station\(s\): (\w+) \(\d+ epochs\)\s*$", r.output, re.M)
    nav, _, _ = load_nav([folder / "nav.rnx"])
    vrs = load_obs(folder / "VRS.obs")
    assert vrs.non_physical
    return folder, truth, nav, vrs, load_obs(folder / "check1.obs"), m.group(1) if m else None


def _check_dd_integers(sols, folder, master, what, rover_shift=None):
    """No fixed DD integer unequal to the truth (when the VRS had one master throughout)."""
    if master is None:
        return 0
    checked, wrong = _wrong_dd_integers(sols, folder, "check1", master, rover_shift)
    assert not wrong, (what, wrong[:5])
    return checked


# Rover switch-on times [s after the recording starts] for the VRS test: once the centre's network
# has its first corrections (~20 s after it starts with the recording), as trains connect to a
# running service; each run lasts VRS_RUN_S.
VRS_STARTS_S = (30, 60, 90, 120, 150, 180)
VRS_RUN_S = 60


@pytest.fixture(scope="module")
def vrs_switch_ons(network_70km_vrs):
    """Rovers switched on at VRS_STARTS_S against the centre's VRS, as trains connecting to the running
    service: per start, (start, solutions, fixed mask, horizontal error, vertical error, PL exceedances)."""
    folder, truth, nav, vrs, rover, master = network_70km_vrs
    t0 = float(rover.times[0])
    runs = []
    for start in VRS_STARTS_S:
        sols = list(process(_window(rover, t0 + start, t0 + start + VRS_RUN_S), vrs, nav, vrs.approx_position_m,
                            RtkOptions()))
        runs.append((start, sols, *_errors_and_pl(sols, truth.at([round(s.time) for s in sols]))))
    return runs


def _time_to_first_fix_s(start, sols, fixed) -> float:
    assert fixed.any(), (start, sols[-1].message)
    return sols[int(np.argmax(fixed))].time - sols[0].time


def test_network_70km_with_the_centre_vrs(network_70km_vrs, vrs_switch_ons):
    """check1 (static, processed as a moving rover: kinematic, no dynamics) against the centre's VRS
    28 m away, the VRS synthesised from the four stations 35 km around it.  The rover knows the base is
    a VRS from its RINEX MARKER TYPE (NON_PHYSICAL) and estimates the residual ionosphere.

    Two views: one rover running from the recording's first epoch (the centre starting at the same
    time: for ~20 s its VRS is a plain geometric shift of a station 35 km away, then it carries only
    the network-corrected satellites, a handful at first, and every satellite continuing across the
    switch steps by the correction), for safety: no wrong fix, no epoch beyond its protection level;
    and rovers switched on at VRS_STARTS_S, as trains connecting to the running service, for the
    time to first fix (median over the starts) and the figures after it.

    Measured when written (240 s, quiet ionosphere as recalibrated in stations 5423242, kriging
    interpolation): from the first epoch 218/240 fixed (a first fix at 6 s on the single-base
    shift, right, lost when the VRS drops to 3 satellites at 21 s, fixed again from 37 s); switch-ons:
    time to first fix 9 s each, fixed in every epoch after the first fix, H95 1.2 cm, V95 1.9 cm;
    no wrong fix (every fixed DD integer equals the simulator's), no epoch beyond its protection level.

    Measured 2026-11-22 with the centre committed at 13c7b29 and validated partial fixes counting towards
    the confirmation: from the first epoch 199/240 fixed, first at 4 s, worst fixed error 2.8 cm;
    switch-ons 31, 11, 9, 9, 9, 9 s, 100 % fixed after the first fix, H95 0.98 cm, V95 2.64 cm, every
    fixed DD integer equal to the simulator's, no PL exceedance.  With the centre of 2ff8564: from the first
    epoch 228/240 fixed, first at 4 s; switch-ons 5 s each, H95 0.80 cm, V95 1.49 cm.
    """
    folder, truth, nav, vrs, rover, master = network_70km_vrs

    # one rover from the first epoch, through the centre's start-up (its VRS changes from a single-base
    # shift of all satellites to network-corrected ones, a handful at first): never a wrong fix, never
    # beyond the protection level, fixed at the end
    sols = list(process(rover, vrs, nav, vrs.approx_position_m, RtkOptions()))
    fixed, h, v, over = _errors_and_pl(sols, truth.at([round(s.time) for s in sols]))
    assert not np.any(fixed & (np.hypot(h, v) > WRONG_FIX_M))
    assert not over, over[:3]
    assert fixed[-VRS_RUN_S:].all()
    checked = _check_dd_integers(sols, folder, master, "from the first epoch")
    print(f"network-70km VRS from the first epoch: {fixed.sum()}/{len(sols)} fixed, first at "
          f"{np.argmax(fixed)} s, worst fixed error {np.hypot(h, v)[fixed].max() * 100:.1f} cm, "
          f"{checked} fixed DD integers checked against the truth")

    # rovers switched on while the service runs
    ttff, after, hs, vs = [], [], [], []
    for start, sols, fixed, h, v, over in vrs_switch_ons:
        ttff.append(_time_to_first_fix_s(start, sols, fixed))
        after.append(fixed[int(np.argmax(fixed)):].mean())
        assert not np.any(fixed & (np.hypot(h, v) > WRONG_FIX_M)), start
        assert not over, (start, over[:3])
        _check_dd_integers(sols, folder, master, start)
        hs.extend(h[fixed])
        vs.extend(v[fixed])
    h95, v95 = np.percentile(hs, 95), np.percentile(vs, 95)
    print(f"network-70km VRS: time to first fix {ttff} s (median {np.median(ttff):.1f}), fixed after the first fix "
          f"{min(after):.1%} at worst, H95 {h95 * 100:.2f} cm, V95 {v95 * 100:.2f} cm")
    assert min(after) >= 0.99
    assert h95 <= 0.02
    assert v95 <= 0.04


def test_network_70km_vrs_median_time_to_first_fix(vrs_switch_ons):
    """The median time to first fix of the rovers switched on at VRS_STARTS_S: at most 10 s.

    Measured 2026-11-22 with the centre as committed at 13c7b29: 31, 11, 9, 9, 9, 9 s (median 9 s; before
    validated partial fixes counted towards the 3-epoch confirmation: 33, 13, 11, 11, 11, 11, median 11).
    The first switch-on (30 s) waits for the centre: its VRS then carries 7 satellites.  With the centre of
    2ff8564 (its network fixes its satellites sooner): 5 s each (7 s each before)."""
    ttff = [_time_to_first_fix_s(start, sols, fixed) for start, sols, fixed, *_ in vrs_switch_ons]
    assert np.median(ttff) <= 10.0, ttff


def _with_outage(obs, t_from, t_to, seed):
    """The rover losing every signal over [t_from, t_to) (an overbridge, a tunnel): no observations, then
    every satellite re-acquired with new integer ambiguities and the loss-of-lock flag.  Returns the
    observations and the integers added per (satellite, slot)."""
    from augnet.onboard.observations import ObsArrays, choose_signals

    rng = np.random.default_rng(seed)
    obs_out = {k: v.copy() for k, v in obs.obs.items()}
    lli = {k: v.copy() for k, v in obs.lli.items()}
    gone = (obs.times >= t_from) & (obs.times < t_to)
    after = obs.times >= t_to
    first = int(np.argmax(after))
    for a in obs_out.values():
        a[gone] = np.nan
    shift = {}
    sats = list(obs.sats)
    for sat, signals in choose_signals(obs, 2).items():
        j = sats.index(sat)
        for f, sig in enumerate(signals):
            key = "L" + sig
            if not sig or key not in obs_out:
                continue
            k = int(rng.integers(-50, 51))
            shift[(sat, f)] = k
            obs_out[key][after, j] += k
            li = lli.setdefault(key, np.zeros(obs_out[key].shape, dtype=int))
            li[first, j] = int(li[first, j]) | 1
    return ObsArrays(obs.times, obs.sats, obs_out, lli, obs.approx_position_m, obs.marker_type), shift


@pytest.mark.parametrize("outage_s", [1, 20, 45])
def test_network_70km_vrs_refix_after_losing_every_signal(network_70km_vrs, outage_s):
    """A train under an overbridge (1 s) or through a tunnel (20 s, 45 s: demo's 2 km at 160 km/h): check1,
    switched on at 90 s and fixed, loses every signal 40 s later, then re-acquires every satellite with new
    integer ambiguities.  The SD ionosphere states (atmosphere, not tracking) are kept across the outage with
    the uncertainty their random walk gathers, so the new ambiguities fix against them: re-fixed within 5 s
    (at best 2 s: the 3-epoch confirmation), fixed in every epoch after, no wrong DD integer, no epoch
    beyond its protection level.

    Measured 2026-11-22 (centre committed at 13c7b29): re-fixed 2, 2 and 3 s after re-acquisition for 1, 20
    and 45 s outages (2 s each with the centre of 2ff8564); 11 s each when the ionosphere was dropped with
    the ambiguities (before ad0f254)."""
    folder, truth, nav, vrs, rover, master = network_70km_vrs
    t0 = float(rover.times[0])
    start, lost_after = 90, 40
    run = _window(rover, t0 + start, t0 + start + lost_after + outage_s + 30)
    back = t0 + start + lost_after + outage_s
    run, shift = _with_outage(run, back - outage_s, back, seed=outage_s)
    sols = list(process(run, vrs, nav, vrs.approx_position_m, RtkOptions()))
    fixed, h, v, over = _errors_and_pl(sols, truth.at([round(s.time) for s in sols]))
    times = np.array([s.time for s in sols])
    assert fixed[times < back - outage_s][-5:].all()  # fixed before the outage
    i_back = int(np.argmax(times >= back))
    refix = int(np.argmax(fixed[i_back:]))
    assert fixed[i_back:].any() and refix <= 5, [s.message for s in sols[i_back:i_back + 6]]
    assert fixed[i_back + refix:].all()
    assert not np.any(fixed & (np.hypot(h, v) > WRONG_FIX_M))
    assert not over, over[:3]
    checked = _check_dd_integers(sols, folder, master, outage_s, rover_shift=(back, shift))
    print(f"network-70km VRS, {outage_s} s without any signal: re-fixed {refix} s after re-acquisition, "
          f"{checked} fixed DD integers checked")


@pytest.mark.parametrize("which", ["reference", "other"])
def test_network_70km_vrs_a_slip_keeps_the_fix(network_70km_vrs, which):
    """A cycle slip on one satellite of a fixed rover (loss-of-lock flag, both frequencies jump): its
    ambiguities start afresh and are fixed against the held others; the fix confirmation is not restarted
    (the slipped satellite, like a rising one, is simply not compared with the previous epoch's integers),
    so the rover stays fixed in every epoch, with every fixed DD integer right and no PL exceedance.
    Before the serial numbers (ambiguity re-initialised under the same key) the confirmation restarted and
    cost two float epochs (the demo's trains lost 0.3-0.4 % of their fixed epochs that way)."""
    from augnet.onboard.observations import ObsArrays, choose_signals

    folder, truth, nav, vrs, rover, master = network_70km_vrs
    t0 = float(rover.times[0])
    run = _window(rover, t0 + 90, t0 + 150)
    sols = list(process(run, vrs, nav, vrs.approx_position_m, RtkOptions()))
    t_slip = t0 + 90 + 30
    before = next(s for s in sols if s.time == t_slip - 1)
    assert before.status == Status.FIX
    refs = sorted({ref for (_, ref, _) in before.fixed_dd})
    others = sorted({sat for (sat, _, _) in before.fixed_dd})
    sat = refs[0] if which == "reference" else others[0]
    obs_out = {k: v.copy() for k, v in run.obs.items()}
    lli = {k: v.copy() for k, v in run.lli.items()}
    j = list(run.sats).index(sat)
    after = run.times >= t_slip
    shift = {}
    for f, sig in enumerate(choose_signals(run, 2)[sat]):
        key = "L" + sig
        shift[(sat, f)] = 7 + 5 * f
        obs_out[key][after, j] += shift[(sat, f)]
        li = lli.setdefault(key, np.zeros(obs_out[key].shape, dtype=int))
        li[int(np.argmax(after)), j] = int(li[int(np.argmax(after)), j]) | 1
    run = ObsArrays(run.times, run.sats, obs_out, lli, run.approx_position_m, run.marker_type)
    sols = list(process(run, vrs, nav, vrs.approx_position_m, RtkOptions()))
    fixed, h, v, over = _errors_and_pl(sols, truth.at([round(s.time) for s in sols]))
    first = int(np.argmax(fixed))
    assert fixed[first:].all(), [(s.time - t_slip, s.message) for s in sols[first:] if s.status != Status.FIX][:5]
    assert not np.any(fixed & (np.hypot(h, v) > WRONG_FIX_M))
    assert not over, over[:3]
    slipped_fixed = sum(1 for s in sols if s.time >= t_slip for k in s.fixed_dd if sat in k[:2])
    assert slipped_fixed > 0  # the slipped satellite is fixed again
    _check_dd_integers(sols, folder, master, which, rover_shift=(t_slip, shift))
