"""RTK on synthetic base/rover observations (truth known): fixing, accuracy, slips, and bad input.

Every bad-input case asserts a clear status and message and that no exception leaves the loop.
"""

from __future__ import annotations


import numpy as np
import pytest

from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import ecef_to_enu, enu_to_ecef, geodetic_deg_to_ecef
from augnet.onboard.observations import ObsArrays
from augnet.onboard.postprocess import process
from augnet.onboard.rtk import RtkOptions, Status
from tests.onboard.synth import simulate, visible_sats

BASE = geodetic_deg_to_ecef(35.1347, 136.9776, 105.0)
T0 = 1403252400.0
N_EPOCHS = 20


@pytest.fixture(scope="module")
def nav(shared_data):
    from augnet.gnss.rinex import read_nav

    return NavigationData(read_nav(shared_data / "rinex/static-1m-2024/base.nav").ephemerides)


@pytest.fixture(scope="module")
def sats(nav):
    return visible_sats(nav, BASE, T0)


def _rover_at(east, north, up=0.0):
    return BASE + enu_to_ecef(np.array([east, north, up]), BASE)


def _pair(nav, sats, rover_pos, n=N_EPOCHS, rover_kw=None, base_kw=None):
    t = T0 + np.arange(float(n))
    base, _ = simulate(nav, sats, t, BASE, clock_s=1e-4 + 1e-9 * np.arange(n), seed=11, **(base_kw or {}))
    rover, truth = simulate(nav, sats, t, rover_pos, clock_s=-2e-4 + 3e-9 * np.arange(n), seed=12, **(rover_kw or {}))
    return rover, base, truth


def _errors(sols, truth_pos):
    tp = np.broadcast_to(truth_pos, (len(sols), 3))
    return np.array([np.linalg.norm(ecef_to_enu(s.position_m - p, p)) for s, p in zip(sols, tp)])


def test_static_2km_baseline_fixes_and_is_accurate(nav, sats):
    rov_pos = _rover_at(1500.0, -1200.0, 8.0)
    rover, base, truth = _pair(nav, sats, rov_pos)
    sols = list(process(rover, base, nav, BASE, RtkOptions(systems=("G", "E"))))
    status = np.array([s.status for s in sols])
    assert status[0] == Status.FIX, sols[0].message
    assert np.all(status == Status.FIX)
    err = _errors(sols, rov_pos)
    assert np.max(err) < 0.01  # 2 mm phase noise: fixed error at the millimetre level
    assert all(s.ratio >= 3.0 for s in sols)
    assert all(len(sats) - 2 <= s.n_sats <= len(sats) for s in sols)  # a satellite may cross the mask


@pytest.mark.parametrize("dynamics", [False, True])
def test_moving_rover_fixed_with_and_without_dynamics(nav, sats, dynamics):
    t = T0 + np.arange(float(N_EPOCHS))
    # 25 m/s north-east with a gentle acceleration, a train leaving a station
    d = 25.0 * (t - T0)[:, None] * np.array([0.6, 0.8, 0.0]) + 0.25 * (t - T0)[:, None] ** 2 * np.array([0.6, 0.8, 0.0])
    path = BASE + enu_to_ecef(d + np.array([300.0, 200.0, 0.0]), BASE)
    base, _ = simulate(nav, sats, t, BASE, seed=21)
    rover, _ = simulate(nav, sats, t, path, clock_s=1e-5 * np.ones(N_EPOCHS), seed=22)
    sols = list(process(rover, base, nav, BASE, RtkOptions(systems=("G", "E"), dynamics=dynamics)))
    assert [s.status for s in sols].count(Status.FIX) == N_EPOCHS
    assert np.max(_errors(sols, path)) < 0.02


def test_cycle_slip_without_lli_is_detected_and_the_fix_stays_right(nav, sats):
    rov_pos = _rover_at(800.0, 300.0)
    slip_sat = sats[2]
    rover, base, _ = _pair(nav, sats, rov_pos, rover_kw={"slips": [(10, slip_sat, 0, 7)]})
    # hide the slip from the loss-of-lock indicator: geometry-free / innovation tests must catch it
    for k in rover.lli:
        rover.lli[k][:] = 0
    sols = list(process(rover, base, nav, BASE, RtkOptions(systems=("G", "E"))))
    err = _errors(sols, rov_pos)
    fixed = np.array([s.status == Status.FIX for s in sols])
    assert fixed[10:].sum() >= 9
    assert np.max(err[fixed]) < 0.01  # no wrong fix after the slip


def test_code_blunder_on_one_satellite_does_not_spoil_the_fix(nav, sats):
    rov_pos = _rover_at(-400.0, 900.0)
    rover, base, _ = _pair(nav, sats, rov_pos)
    rover.obs["C1C"][5, list(rover.sats).index(sats[4])] += 80.0
    sols = list(process(rover, base, nav, BASE, RtkOptions(systems=("G", "E"))))
    assert all(s.status == Status.FIX for s in sols)
    assert np.max(_errors(sols, rov_pos)) < 0.01


def test_missing_base_epochs_age_the_corrections_and_degrade_to_single(nav, sats):
    rov_pos = _rover_at(500.0, 500.0)
    rover, base, _ = _pair(nav, sats, rov_pos, n=30)
    keep = np.ones(30, bool)
    keep[8:20] = False  # a 12 s outage of the correction link
    base = ObsArrays(base.times[keep], base.sats, {k: v[keep] for k, v in base.obs.items()},
                     {k: v[keep] for k, v in base.lli.items()})
    sols = list(process(rover, base, nav, BASE, RtkOptions(systems=("G", "E"), max_age_s=5.0)))
    st = [s.status for s in sols]
    ages = [s.age_s for s in sols]
    assert all(x == Status.FIX for x in st[:8])
    # ages 1..5 s: still RTK (ambiguities carried by the last base epoch are still valid)
    assert ages[8:13] == pytest.approx([1, 2, 3, 4, 5], abs=0.01)  # time tags carry receiver clocks
    for s in sols[13:20]:
        assert s.status == Status.SINGLE
        assert "stale" in s.message
        assert s.age_s > 5.0
    assert st[-1] == Status.FIX
    assert np.linalg.norm(sols[-1].position_m - rov_pos) < 0.01


def test_wrong_base_coordinates_are_refused_not_fixed_to(nav, sats):
    rov_pos = _rover_at(100.0, 100.0)
    rover, base, _ = _pair(nav, sats, rov_pos, n=5)
    wrong = BASE + enu_to_ecef(np.array([3000.0, 0.0, 0.0]), BASE)
    sols = list(process(rover, base, nav, wrong, RtkOptions(systems=("G", "E"))))
    assert all(s.status == Status.SINGLE for s in sols)
    assert all("base position inconsistent" in s.message for s in sols)


def test_base_too_far_from_rover_is_single_with_a_reason(nav, sats):
    far_base = geodetic_deg_to_ecef(36.5, 138.5, 300.0)  # ~200 km away
    t = T0 + np.arange(4.0)
    base, _ = simulate(nav, sats, t, far_base, seed=5)
    rover, _ = simulate(nav, sats, t, BASE, seed=6)
    sols = list(process(rover, base, nav, far_base, RtkOptions(systems=("G", "E"))))
    assert all(s.status == Status.SINGLE for s in sols)
    assert all("baseline" in s.message for s in sols)


def test_corrupt_observations_never_raise(nav, sats):
    rov_pos = _rover_at(200.0, -300.0)
    rover, base, _ = _pair(nav, sats, rov_pos, n=12)
    rng = np.random.default_rng(3)
    for k in rover.obs:
        a = rover.obs[k]
        mask = rng.random(a.shape) < 0.1
        a[mask] = rng.choice([np.nan, np.inf, -1e15, 0.0, 1e20], size=mask.sum())
    base.obs["L1C"][4:6] = np.nan  # base phases lost for two epochs
    rover.obs["C1C"][7] = np.nan  # no L1 code at all in one epoch
    sols = list(process(rover, base, nav, BASE, RtkOptions(systems=("G", "E"))))
    assert len(sols) == 12
    for s in sols:
        assert s.status in (Status.FIX, Status.FLOAT, Status.SINGLE, Status.NONE)
        assert s.message
        if s.status != Status.NONE:
            assert np.all(np.isfinite(s.position_m))
    fixed = [s for s in sols if s.status == Status.FIX]
    assert fixed and max(np.linalg.norm(s.position_m - rov_pos) for s in fixed) < 0.05


def test_no_base_at_all_gives_single(nav, sats):
    rov_pos = _rover_at(10.0, 10.0)
    rover, base, _ = _pair(nav, sats, rov_pos, n=3)
    empty = ObsArrays(np.zeros(0), base.sats, {k: v[:0] for k, v in base.obs.items()}, {})
    sols = list(process(rover, empty, nav, BASE, RtkOptions(systems=("G", "E"))))
    assert [s.status for s in sols] == [Status.SINGLE] * 3
    assert all("no base" in s.message for s in sols)


def test_reset_starts_the_filter_afresh(nav, sats):
    from augnet.onboard.observations import choose_signals, epochs
    from augnet.onboard.rtk import RtkFilter

    rover, base, _ = _pair(nav, sats, _rover_at(1500.0, -1200.0, 8.0), n=6)
    opt = RtkOptions(systems=("G", "E"))
    r_ep = epochs(rover, opt.n_slots, opt.systems, choose_signals(rover, opt.n_slots, opt.systems))
    b_ep = epochs(base, opt.n_slots, opt.systems, choose_signals(base, opt.n_slots, opt.systems))
    used = RtkFilter(nav, BASE, opt)
    for r, b in zip(r_ep, b_ep):
        used.step(r, b)
    assert len(used.layout) > 0 and used.consecutive_fixes > 0
    used.reset()
    assert len(used.layout) == 0 and not used.initialised and used.confirmation.decision is None
    fresh = RtkFilter(nav, BASE, opt)
    for r, b in zip(r_ep[:3], b_ep[:3]):
        a, f = used.step(r, b), fresh.step(r, b)
        assert (a.status, a.message, dict(a.fixed_dd)) == (f.status, f.message, dict(f.fixed_dd))
        np.testing.assert_array_equal(a.position_m, f.position_m)


def _clock_step(obs: ObsArrays, sat: str, from_epoch: int, step_m: float) -> None:
    """A satellite clock step as the receiver sees it: code and phase of every slot longer by step_m."""
    from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
    from augnet.onboard.observations import BAND_FREQ_HZ

    j = list(obs.sats).index(sat)
    for key in obs.obs:
        if key[0] == "C":
            obs.obs[key][from_epoch:, j] += step_m
        elif key[0] == "L":
            obs.obs[key][from_epoch:, j] += step_m * BAND_FREQ_HZ[(sat[0], key[1])] / SPEED_OF_LIGHT_M_S


@pytest.mark.parametrize("step_m", [100e-9 * 299_792_458.0, 3.0])
def test_satellite_clock_step_between_base_and_rover_epoch_is_left_out_not_taken_in(nav, sats, step_m):
    # issue 15 (decision 0253): the VRS epoch a rover uses is ~1 s older; a clock step in that second is in
    # the rover's data and not yet in the base's, in code and phase alike. Taken as a slip (ambiguity
    # restarted from code, which carries the step too) the filter absorbed it: 100 ns (29.98 m) left a float
    # ~1 m off in the campaign (10 m here); 3 m, within the code's noise, left 1.4-2.9 m. The code-and-phase
    # test catches the first, the Doppler-without-GF range jump (cycleslip.py) the second.
    n = 30
    t = T0 + np.arange(float(n))
    d = 60.0 * (t - T0)[:, None] * np.array([0.6, 0.8, 0.0])  # 216 km/h, white-noise position (no dynamics)
    path = BASE + enu_to_ecef(d + np.array([300.0, 200.0, 0.0]), BASE)
    base, _ = simulate(nav, sats, t - 1.0, BASE, seed=31)  # every base epoch 1 s older than the rover's
    rover, _ = simulate(nav, sats, t, path, clock_s=1e-5 * np.ones(n), seed=32)
    for key in [k for k in rover.obs if k[0] == "L"]:  # Dopplers (range rate = -lambda D), before the step
        rover.obs["D" + key[1:]] = -np.gradient(rover.obs[key], axis=0)
    gps = [s for s in sats if s.startswith("G")]
    sat = gps[0]
    _clock_step(rover, sat, 15, step_m)  # the rover sees it at its epoch 15 (t = T0 + 15)
    _clock_step(base, sat, 16, step_m)  # the base at its epoch tagged T0 + 15, used with rover epoch 16
    flt = None
    sols = []
    from augnet.onboard.observations import epochs as obs_epochs
    from augnet.onboard.rtk import RtkFilter

    opt = RtkOptions(systems=("G", "E"))
    rov_eps, base_eps = obs_epochs(rover, opt.n_slots, opt.systems), obs_epochs(base, opt.n_slots, opt.systems)
    flt = RtkFilter(nav, BASE, opt)
    held = []
    for r, b in zip(rov_eps, base_eps):
        sols.append(flt.step(r, b))
        held.append(sat in flt.range_faults)
    err = _errors(sols, path)
    fixed = np.array([s.status == Status.FIX for s in sols])
    assert fixed[5:15].all()  # fixed before the step
    assert held[15] and not any(held[:15])  # the jump is seen at the epoch it reaches the rover
    assert fixed[15:].all(), [s.message for s in sols[15:]]
    assert np.max(err[5:]) < 0.02  # nothing of the 30 m reached the position


def test_range_jump_is_told_from_a_slip():
    """cycleslip.SlipDetector.range_jump: the same metres on both slots against the Dopplers (GF steady) is a
    range jump; a slip on one slot (GF jumps) is not, nor is a steady epoch."""
    from augnet.onboard.cycleslip import SlipDetector
    from augnet.onboard.observations import EpochObs

    wl = np.array([0.1903, 0.2442])
    sats = np.array(["G01", "G02", "G03", "G04"])

    def epoch(t, extra_m):
        rng = 2e7 + 100.0 * t + np.arange(4) * 1e5  # ranges growing 100 m/s
        ph = (rng[:, None] + extra_m) / wl[None, :]
        dop = -100.0 / wl[None, :] * np.ones((4, 1))
        return EpochObs(t, sats, rng[:, None] * np.ones((1, 2)), ph, dop, np.full((4, 2), 45.0),
                        np.zeros((4, 2), np.int16), np.tile(wl, (4, 1)), np.full((4, 2), "1C"))

    det = SlipDetector()
    det.detect(epoch(0.0, np.zeros((4, 2))))
    assert not det.detect(epoch(1.0, np.zeros((4, 2)))).any() and not det.range_jump.any()
    step = np.zeros((4, 2))
    step[1, :] = 3.0  # 3 m on both slots of G02: a clock step
    slip = det.detect(epoch(2.0, step))
    assert det.range_jump.tolist() == [False, True, False, False] and slip[1].all()
    cyc = step.copy()
    cyc[2, 0] = 7 * wl[0]  # and a 7-cycle slip on slot 0 of G03
    slip = det.detect(epoch(3.0, cyc))
    assert slip[2, 0] and not det.range_jump[2]
