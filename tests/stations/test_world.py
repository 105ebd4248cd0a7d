"""Each error term is real: switched off, the matching combination goes flat; switched on, it has
the size the scenario states.  Trains follow the track; tunnels break lock; same seed, same data."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from stations.diagnostics import dd_ionosphere_ppm, dd_truth
from stations.scenario import load_scenario
from stations.world import World

C = SPEED_OF_LIGHT_M_S


def _scenario(name="baseline-10km", duration=120.0, **errors):
    sc = load_scenario(name)
    e = sc.errors
    parts = {}
    for key, val in errors.items():
        if isinstance(val, dict):
            parts[key] = getattr(e, key).model_copy(update=val)
        else:
            parts[key] = val
    return sc.model_copy(update=dict(duration_s=duration, errors=e.model_copy(update=parts)))


OFF = dict(ionosphere={"level": "off"}, troposphere={"enabled": False}, orbit_clock={"enabled": False},
           noise={"enabled": False}, receiver_clock=False)


def _run(sc, block=60):
    w = World(sc)
    return w, w.run(block)


def _cat(blocks, name):
    return np.concatenate([getattr(b, name) for b in blocks])


def _model_range(blocks):
    """rho + c (dt_r - dt^s) per (E, R, N): the non-dispersive part without troposphere."""
    rng = _cat(blocks, "range_m")
    return rng + C * (_cat(blocks, "rx_clock_s")[:, :, None] - _cat(blocks, "sat_clock_s"))


def test_all_errors_off_is_exact():
    w, bl = _run(_scenario(**OFF))
    P, L, obs = _cat(bl, "pseudorange_m"), _cat(bl, "phase_cyc"), _cat(bl, "observed")
    model = _model_range(bl)[..., None]
    assert obs.sum() > 1000
    assert np.nanmax(np.abs(P - model)) < 1e-6
    amb = _cat(bl, "ambiguity_cyc")
    resid = L - model / w.wavelength_m[None, None] - amb
    assert np.nanmax(np.abs(resid)) < 1e-6
    assert np.all(np.isnan(amb[~obs]))


def test_geometry_free_phase_flat_without_ionosphere():
    # ionosphere off, everything else on: L1 - L2 geometry-free (metres) constant per arc up to noise
    sc = _scenario(ionosphere={"level": "off"}, noise={"multipath": False})
    w, bl = _run(sc)
    L = _cat(bl, "phase_cyc") * w.wavelength_m[None, None]
    gf = L[..., 0] - L[..., 1]
    seen = ~np.isnan(gf).all(axis=0)
    gf = gf[:, seen]
    dev = gf - np.nanmean(gf, axis=0, keepdims=True)  # no slips in this scenario: one arc each
    assert np.nanstd(dev) < 0.006  # ~sqrt(2) x phase noise, metres
    # and with the ionosphere on the same combination moves by centimetres over two minutes
    w2, bl2 = _run(_scenario(noise={"multipath": False}))
    L2 = _cat(bl2, "phase_cyc") * w2.wavelength_m[None, None]
    gf2 = L2[..., 0] - L2[..., 1]
    gf2 = gf2[:, ~np.isnan(gf2).all(axis=0)]
    span = np.nanmax(gf2, axis=0) - np.nanmin(gf2, axis=0)
    assert np.nanmedian(span) > 0.01


def test_code_and_phase_diverge_by_twice_the_ionosphere():
    sc = _scenario(troposphere={"enabled": False}, orbit_clock={"enabled": False}, noise={"enabled": False},
                   receiver_clock=False)
    w, bl = _run(sc)
    P = _cat(bl, "pseudorange_m")
    L = _cat(bl, "phase_cyc") * w.wavelength_m[None, None]
    amb = _cat(bl, "ambiguity_cyc") * w.wavelength_m[None, None]
    iono = 40.3e16 * _cat(bl, "stec_tecu")[..., None] / w.freq_hz[None, None] ** 2
    assert np.nanmax(np.abs((P - (L - amb)) - 2 * iono)) < 1e-5
    # dispersive: the L2 delay is (f1/f2)^2 times the L1 delay
    g = _cat(bl, "observed")[..., 0] & (w.sat_system == "G")[None, None]
    ratio = (P[..., 1] - _model_range(bl))[g] / (P[..., 0] - _model_range(bl))[g]
    assert np.allclose(ratio, (1575.42 / 1227.60) ** 2, rtol=1e-6)


def test_troposphere_is_non_dispersive_and_only_when_on():
    base = dict(ionosphere={"level": "off"}, orbit_clock={"enabled": False}, noise={"enabled": False},
                receiver_clock=False)
    w, bl = _run(_scenario(**base))
    P = _cat(bl, "pseudorange_m")
    tropo = _cat(bl, "tropo_m")
    resid = P - _model_range(bl)[..., None]
    assert np.nanmax(np.abs(resid[..., 0] - tropo)) < 1e-6
    assert np.nanmax(np.abs(resid[..., 0] - resid[..., 1])) < 1e-6  # same on both frequencies
    el = _cat(bl, "elevation_rad")
    obs = _cat(bl, "observed")[..., 0]
    # 2.3-2.5 m at zenith near sea level, ~7-9 m at 15 deg
    hi = obs & (el > np.radians(75))
    assert np.all((tropo[hi] > 2.3) & (tropo[hi] < 2.6))
    low = obs & (el > np.radians(14)) & (el < np.radians(16))
    assert np.all((tropo[low] > 8.0) & (tropo[low] < 10.5))
    w2, bl2 = _run(_scenario(troposphere={"enabled": False}, **base))
    resid2 = _cat(bl2, "pseudorange_m") - _model_range(bl2)[..., None]
    assert np.nanmax(np.abs(resid2)) < 1e-6


def test_noise_and_multipath_levels():
    w, bl = _run(_scenario(ionosphere={"level": "off"}, troposphere={"enabled": False},
                           orbit_clock={"enabled": False}, receiver_clock=False, duration=300))
    el = _cat(bl, "elevation_rad")
    P = _cat(bl, "pseudorange_m")
    err = P - _model_range(bl)[..., None]
    hi = _cat(bl, "observed")[..., 0] & (el > np.radians(60))
    sd = np.std(err[..., 0][hi])
    assert 0.2 < sd < 0.5  # code ~0.3 m near zenith (geodetic grade)
    # multipath is correlated in time (AR(1), minutes for a static antenna); white noise is not
    mp = _cat(bl, "multipath_code_m")[..., 0]
    a, b = mp[1:][hi[1:] & hi[:-1]], mp[:-1][hi[1:] & hi[:-1]]
    assert np.corrcoef(a, b)[0, 1] > 0.95
    w0, bl0 = _run(_scenario(ionosphere={"level": "off"}, troposphere={"enabled": False},
                             orbit_clock={"enabled": False}, receiver_clock=False,
                             noise={"multipath": False}, duration=60))
    assert np.all(_cat(bl0, "multipath_code_m") == 0.0)


def test_orbit_and_clock_errors_have_stated_size():
    w, bl = _run(_scenario(duration=60))
    orb = _cat(bl, "orbit_error_range_m")[_cat(bl, "observed")[..., 0]]
    clk = _cat(bl, "sat_clock_error_s")[_cat(bl, "observed")[..., 0]]
    assert 0.05 < np.std(orb) < 1.0  # decimetres along the line of sight
    assert 0.2e-9 < np.std(clk) < 3e-9  # about a nanosecond
    w0, bl0 = _run(_scenario(orbit_clock={"enabled": False}, duration=30))
    # left: only the rounding of the broadcast parameters to their ICD resolution
    obs0 = _cat(bl0, "observed")[..., 0]
    assert np.max(np.abs(_cat(bl0, "orbit_error_range_m")[obs0])) < 0.05
    assert np.max(np.abs(_cat(bl0, "sat_clock_error_s")[obs0])) < 0.3e-9


@pytest.mark.slow
@pytest.mark.parametrize("name,level,a,b,lo,hi", [("network-70km", None, "NORTH", "SOUTH", 1.0, 4.0),
                                                   ("network-70km", "moderate", "NORTH", "SOUTH", 1.0, 4.0),
                                                   ("iono-storm", None, "ST1", "ST2", 10.0, 20.0)])
def test_dd_ionosphere_level(name, level, a, b, lo, hi):
    """DD L1 ionosphere over 70 km, RMS in ppm of the baseline: 1-4 quiet (and moderate), 10-20 in a storm
    (network-rtk.md). Measured over 180 s: quiet 1.24 (95 % 2.34), moderate 2.18 (95 % 3.89), storm 13.9."""
    sc = load_scenario(name).model_copy(update=dict(duration_s=180.0, trains=[]))
    if level is not None:
        iono = sc.errors.ionosphere.model_copy(update={"level": level})
        sc = sc.model_copy(update={"errors": sc.errors.model_copy(update={"ionosphere": iono})})
    w = World(sc)
    stats = dd_ionosphere_ppm(w, w.run(), a, b)
    print(f"{name} ({level or 'as written'}) {a}-{b}: DD L1 ionosphere {stats}")
    assert lo <= stats["rms"] <= hi


def test_dd_ionosphere_grows_with_baseline():
    sc = load_scenario("network-70km").model_copy(update=dict(duration_s=60.0))
    w = World(sc)
    bl = w.run()
    short = np.sqrt(np.mean(dd_truth(w, bl, "check1", "NORTH", "iono_l1_m") ** 2))
    long = np.sqrt(np.mean(dd_truth(w, bl, "SOUTH", "NORTH", "iono_l1_m") ** 2))
    assert long > 1.5 * short


def test_same_seed_same_data_any_block_size():
    sc = _scenario(duration=40, cycle_slips_per_hour=200.0)
    _, a = _run(sc, block=60)
    _, b = _run(sc, block=7)
    for name in ("pseudorange_m", "phase_cyc", "doppler_hz", "lli", "ambiguity_cyc"):
        assert np.array_equal(_cat(a, name), _cat(b, name), equal_nan=True)
    _, c = _run(sc.model_copy(update=dict(seed=sc.seed + 1)), block=60)
    assert not np.array_equal(_cat(a, "pseudorange_m"), _cat(c, "pseudorange_m"), equal_nan=True)


def test_cycle_slips_change_ambiguity_and_are_flagged():
    w, bl = _run(_scenario(duration=120, cycle_slips_per_hour=120.0))
    amb, lli, lock = _cat(bl, "ambiguity_cyc"), _cat(bl, "lli"), _cat(bl, "lock_time_s")
    jumped = (amb[1:] != amb[:-1]) & ~np.isnan(amb[1:]) & ~np.isnan(amb[:-1])
    assert jumped.sum() > 5
    assert np.all(lli[1:][jumped] & 1)
    assert np.all(lock[1:][jumped] == 0.0)
    # without a flag, the ambiguity never changes
    steady = ~np.isnan(amb[1:]) & ~np.isnan(amb[:-1]) & ((lli[1:] & 1) == 0)
    assert np.all(amb[1:][steady] == amb[:-1][steady])


def test_half_cycle_flag_only_when_enabled():
    w, bl = _run(_scenario(duration=20))
    assert not np.any(_cat(bl, "lli") & 2)
    w, bl = _run(_scenario(duration=20, half_cycle=True))
    lli = _cat(bl, "lli")
    assert np.any(lli[:5] & 2) and not np.any(lli[10:] & 2)


@pytest.mark.slow
def test_trains_follow_the_track_and_lose_lock_in_the_tunnel():
    sc = load_scenario("demo")
    w = World(sc)
    bl = w.run()
    tl = w.track
    ecef = _cat(bl, "rx_ecef")
    for i, rx in enumerate(w.receivers):
        if rx.kind != "train":
            continue
        tr = next(t for t in sc.trains if t.id == rx.id)
        # back from ECEF to the plane, independently of how the points were made
        from augnet.gnss.geometry import ecef_to_geodetic
        llh = ecef_to_geodetic(ecef[:, i])
        enu = np.column_stack([tl.geodetic_to_plane(np.degrees(llh[:, 0]), np.degrees(llh[:, 1])), llh[:, 2]])
        sel = slice(None, None, 25)
        ids, s, dist = tl.nearest_track(enu[sel])
        assert set(ids) == {rx.track_id}
        assert np.max(dist) < 0.005  # on the polyline (mm: projection round trip)
        assert np.allclose(s / 1e3, rx.km[sel], atol=1e-4)
        rail = tl.point(s)[:, 2]
        assert np.allclose(enu[sel, 2] - rail, tr.antenna_height_m, atol=0.005)
    # G101 runs through the 2 km tunnel at km 100-102: no observations inside, new arcs after
    i = w.receiver_ids.index("G101")
    rx = w.receivers[i]
    km = rx.km
    inside = (km >= 100.0) & (km <= 102.0)
    assert inside.any() and (km > 102.1).any()
    obs = _cat(bl, "observed")[:, i]
    assert not obs[inside].any()
    before = np.flatnonzero(km < 100.0)[-1]
    # first epoch after the exit with signals again (the epoch whose interval spans the portal
    # is still blocked: the receiver was in the tunnel for part of it)
    after = np.flatnonzero((km > 102.0) & obs.any(axis=(1, 2)))[0]
    assert km[after] - 102.0 < 0.1
    amb = _cat(bl, "ambiguity_cyc")[:, i]
    lli = _cat(bl, "lli")[:, i]
    both = obs[before] & obs[after]
    assert both.sum() >= 8
    assert np.all(lli[after][obs[after]] & 1)  # every signal re-acquired with loss of lock
    assert np.mean(amb[after][both] != amb[before][both]) > 0.9  # new integer ambiguities
    assert np.all(_cat(bl, "lock_time_s")[after, i][obs[after]] == 0.0)


def test_faults_clock_step_and_station_outage():
    from stations.scenario import Fault
    sc = _scenario(duration=40, **OFF)
    sat = "G05"
    sc = sc.model_copy(update=dict(faults=[
        Fault(kind="satellite_clock_step", at_s=20, satellite=sat, step_ns=30.0),
        Fault(kind="station_outage", at_s=10, until_s=15, station="B")]))
    w, bl = _run(sc)
    j = w.sats.index(sat)
    err = _cat(bl, "sat_clock_error_s")[:, 0, j]
    # the step happens at 20 s satellite time; the signal sent just before arrives at epoch 20, so
    # receivers see it from epoch 21 (transit ~0.07 s)
    # (err also holds the broadcast af0 rounding, a constant fraction of a ns: look at the step)
    step = err - err[0]
    assert np.allclose(step[:21], 0.0, atol=1e-12) and np.allclose(step[21:], 30e-9, atol=1e-11)
    # the step is in the observations: the code jumps by 30 ns of light (~9 m)
    P = _cat(bl, "pseudorange_m")
    if not np.isnan(P[19, 0, j, 0]):
        jump = (P[21, 0, j, 0] - P[20, 0, j, 0]) - (P[20, 0, j, 0] - P[19, 0, j, 0])
        assert jump == pytest.approx(-C * 30e-9, abs=0.15)  # less the range acceleration
    obs = _cat(bl, "observed")
    ib = w.receiver_ids.index("B")
    assert not obs[10:15, ib].any() and obs[9, ib].any() and obs[15, ib].any()
    lli = _cat(bl, "lli")
    assert np.all(lli[15, ib][obs[15, ib]] & 1)  # lock lost across the outage


def test_triple_frequency_observables():
    sc = load_scenario("baseline-10km")
    sc = sc.model_copy(update=dict(duration_s=30, signals={"G": ["1C", "2W", "5Q"], "E": ["1C", "5Q", "7Q"],
                                                           "C": ["2I", "6I", "7I"]},
                                   errors=sc.errors.model_copy(update=dict(
                                       ionosphere=sc.errors.ionosphere.model_copy(update={"level": "off"}),
                                       noise=sc.errors.noise.model_copy(update={"multipath": False})))))
    w, bl = _run(sc)
    assert w.K == 3
    obs = _cat(bl, "observed")
    assert obs[..., 2].sum() > 100
    L = _cat(bl, "phase_cyc") * w.wavelength_m[None, None]
    gf15 = L[..., 0] - L[..., 2]
    gf15 = gf15[:, ~np.isnan(gf15).all(axis=0)]
    assert np.nanstd(gf15 - np.nanmean(gf15, axis=0)) < 0.006


def test_doppler_matches_the_phase_rate():
    # static stations and moving trains alike: -D = dL/dt (central difference) with the noise off;
    # the Doppler carries the whole phase rate, ionosphere and troposphere included
    sc = load_scenario("demo").model_copy(update=dict(duration_s=20.0))
    sc = sc.model_copy(update=dict(errors=sc.errors.model_copy(update=dict(
        noise=sc.errors.noise.model_copy(update={"enabled": False}), cycle_slips_per_hour=0.0,
        phase_resets_per_hour=0.0, unflagged_slips_per_hour=0.0, data_gaps_per_hour=0.0,  # unflagged jumps
        receiver_clock=False))))
    # (a receiver clock's random-walk frequency would be in the Doppler at the epoch but averaged
    # in the phase difference: 0.1-0.2 Hz for a train TCXO, as in real receivers)
    w, bl = _run(sc)
    L, D = _cat(bl, "phase_cyc"), _cat(bl, "doppler_hz")
    rate = (L[2:] - L[:-2]) / 2.0
    lli = _cat(bl, "lli")
    ok = ~np.isnan(rate) & ~np.isnan(D[1:-1]) & (((lli[1:-1] | lli[2:]) & 1) == 0)
    diff = (rate + D[1:-1])[ok]
    assert ok.sum() > 1000
    assert np.max(np.abs(diff)) < 0.01  # Hz: 2 mm/s, the central difference's own error
    # the train's own motion: 300 km/h is up to 438 Hz on L1 against a station nearby; two static
    # stations 70 km apart differ only by the satellites' motion seen from 70 km apart (< 100 Hz)
    ids = w.receiver_ids
    train = D[:, ids.index("G303"), :, 0] - D[:, ids.index("STA3"), :, 0]
    static = D[:, ids.index("STA2"), :, 0] - D[:, ids.index("STA3"), :, 0]
    assert 250 < np.nanmax(np.abs(train)) < 440
    assert np.nanmax(np.abs(static)) < 100


def test_cutting_hides_low_satellites_across_the_track():
    sc = load_scenario("demo")
    train = sc.trains[0].model_copy(update=dict(start_km=29.0))  # the cutting is at km 30-31.5
    sc = sc.model_copy(update=dict(duration_s=60.0, trains=[train],
                                   stations=[s for s in sc.stations if s.id == "STA1"]))
    w, bl = _run(sc)
    i = w.receiver_ids.index("G101")
    rx = w.receivers[i]
    inside = (rx.km > 30.05) & (rx.km < 31.45)
    assert inside.sum() > 20
    el = _cat(bl, "elevation_rad")[:, i]
    az = _cat(bl, "azimuth_rad")[:, i]
    seen = _cat(bl, "observed")[:, i].any(-1)
    across = np.abs(np.sin(az - rx.heading_rad[:, None])) > 0.9
    low = (el > np.radians(12)) & (el < np.radians(30))
    assert (low & across)[inside].any()
    assert not seen[inside][(low & across)[inside]].any()  # hidden by the walls
    high = el > np.radians(40)
    assert seen[inside][high[inside]].all()  # the sky overhead stays open
    assert seen[~inside][(low & across)[~inside]].any()  # outside the cutting they are seen


def test_unflagged_resets_slips_and_gaps():
    """Phase resets move every signal by the same distance (geometry-free jump < 0.25 m, code minus phase by
    metres to kilometres), unflagged slips jump by whole cycles, gaps drop epochs; none carries a flag."""
    sc = _scenario(duration=200, phase_resets_per_hour=90.0, unflagged_slips_per_hour=30.0,
                   data_gaps_per_hour=90.0)
    w, bl = _run(sc)
    amb, lli, obs = _cat(bl, "ambiguity_cyc"), _cat(bl, "lli"), _cat(bl, "observed")
    both = ~np.isnan(amb[1:]) & ~np.isnan(amb[:-1])
    jumped = both & (amb[1:] != amb[:-1])
    assert jumped.sum() > 20
    assert not np.any(lli[1:][jumped] & 1)
    lam = w.wavelength_m
    d_m = (amb[1:] - amb[:-1]) * lam[None, None]  # (E-1, R, N, K) phase jump [m]
    sat_jump = jumped.any(-1)
    gf = np.abs(d_m[..., 0] - d_m[..., 1])[sat_jump]
    big = np.abs(d_m[..., 0])[sat_jump] >= 19.0  # the resets (20 m to 5 km)
    assert big.sum() > 10 and np.all(gf[big] < 0.25)
    # gaps: a satellite missing for 1-3 epochs inside its arc, back without a flag
    seen = obs[..., 0]
    back = seen[2:] & ~seen[1:-1] & seen[:-2]
    assert back.sum() > 3
    assert not np.any(lli[2:, ..., 0][back] & 1)


def test_unflagged_events_draw_apart_from_everything_else():
    """Their own random stream: switched on, the code (noise, multipath) is what it was; only the phase moves."""
    plain = _run(_scenario(duration=60))[1]
    resets = _run(_scenario(duration=60, phase_resets_per_hour=120.0))[1]
    assert np.array_equal(_cat(plain, "pseudorange_m"), _cat(resets, "pseudorange_m"), equal_nan=True)
    assert not np.array_equal(_cat(plain, "phase_cyc"), _cat(resets, "phase_cyc"), equal_nan=True)


def _by_receiver(sc, *entries):
    """The scenario with errors.by_receiver entries (validated as a scenario file would be)."""
    from stations.scenario import parse_scenario

    data = sc.model_dump(mode="json")
    data["errors"]["by_receiver"] = list(entries)
    return parse_scenario(data)


def _last_seen_changes(amb, obs):
    """(E, R, N, K) bool: the ambiguity differs from the one of the signal's previous observed epoch, same arc or
    not (a gap in between included)."""
    last = np.full(amb.shape[1:], np.nan)
    out = np.zeros(amb.shape, bool)
    for e in range(len(amb)):
        out[e] = obs[e] & ~np.isnan(last) & (amb[e] != last)
        last = np.where(obs[e], amb[e], last)
    return out


EVENTS = dict(duration=240, phase_resets_per_hour=60.0, unflagged_slips_per_hour=30.0, data_gaps_per_hour=120.0)


def test_a_receiver_that_announces_its_events():
    """errors.by_receiver (decision 0273): B announces its resets and slips (LLI, lock time restarted), drawn at the
    moments they came unannounced; A, keeping errors' events, is byte for byte what it was."""
    plain = _scenario(**EVENTS)
    w0, b0 = _run(plain)
    w1, b1 = _run(_by_receiver(plain, {"receivers": ["B"], "announced": True}))
    a, b = w0.receiver_ids.index("A"), w0.receiver_ids.index("B")
    for name in ("pseudorange_m", "phase_cyc", "lli", "lock_time_s", "ambiguity_cyc"):
        assert np.array_equal(_cat(b0, name)[:, a], _cat(b1, name)[:, a], equal_nan=True), name
    assert np.array_equal(_cat(b0, "ambiguity_cyc"), _cat(b1, "ambiguity_cyc"), equal_nan=True)  # same moments
    obs = _cat(b1, "observed")
    moved = _last_seen_changes(_cat(b1, "ambiguity_cyc"), obs)
    lli0, lli1, lock1 = _cat(b0, "lli"), _cat(b1, "lli"), _cat(b1, "lock_time_s")
    assert moved[:, b].sum() > 20 and moved[:, a].sum() > 20
    assert np.all(lli1[:, b][moved[:, b]] & 1)  # every event B's data show is flagged, after a gap too
    assert not np.any(lli0[:, b][moved[:, b]] & 1)  # the same events unannounced
    assert not np.any(lli1[:, a][moved[:, a]] & 1)
    back = moved[:, b] & ~np.roll(obs[:, b], 1, axis=0)  # an event inside a gap: flagged when the data return
    assert back.any()
    within = moved[:, b] & ~back
    assert np.all(lock1[:, b][within] == 0.0)  # seen at once: its lock time restarts at the event


def test_a_receiver_with_its_own_rates():
    """A class entry gives the stations no events, a named entry (taking precedence) gives B flagged slips."""
    plain = _scenario(**EVENTS)
    sc = _by_receiver(plain, {"receivers": ["stations"], "phase_resets_per_hour": 0, "unflagged_slips_per_hour": 0,
                              "data_gaps_per_hour": 0},
                      {"receivers": ["B"], "cycle_slips_per_hour": 60.0})
    w, bl = _run(sc)
    a, b = w.receiver_ids.index("A"), w.receiver_ids.index("B")
    obs, lli = _cat(bl, "observed"), _cat(bl, "lli")
    moved = _last_seen_changes(_cat(bl, "ambiguity_cyc"), obs)
    assert not moved[:, a].any()  # no events at all
    assert moved[:, b].sum() > 10 and np.all(lli[:, b][moved[:, b]] & 1)  # only flagged slips
    seen = obs[..., 0]
    assert not (seen[2:] & ~seen[1:-1] & seen[:-2])[:, b].any()  # its gaps are the class's: none
