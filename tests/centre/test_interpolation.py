"""Interpolation of network residuals: exactness on fields each model represents, degeneracy detection,
missing data, leave-one-out."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.interpolation import (
    MAX_CROSS_LINE_DISTANCE_M,
    MODEL_CODES,
    InterpolationError,
    Model,
    distance_weights,
    interpolate,
    kriging_weights,
    leave_one_out,
    plane_weights,
    select_model,
    spread_ratio,
)
from tests.conftest import LONG_RUN_TIMEOUT_S

# A 210 km railway with stations every ~70 km, gently curving (a few km off a straight line), and two
# stations 25-30 km off the line.
LINE = np.array([[0.0, 0.0], [70e3, 3e3], [140e3, 4e3], [210e3, 1e3]])
OFF_LINE = np.array([[60e3, 28e3], [150e3, -25e3]])


def test_collinear_railway_is_detected_and_off_line_stations_restore_2d():
    assert spread_ratio(LINE) < 0.1
    assert select_model(LINE) is Model.ALONG_LINE
    assert select_model(np.vstack([LINE, OFF_LINE])) is Model.KRIGING
    assert select_model(LINE[:2]) is Model.ALONG_LINE
    assert select_model(LINE[:1]) is Model.DISTANCE


def test_plane_model_is_exact_for_a_planar_field():
    rng = np.random.default_rng(1)
    sta = np.vstack([LINE, OFF_LINE])
    grad = rng.normal(size=(2, 30)) * 1e-7  # 0.1 ppm-ish gradients per satellite, metres per metre
    V = (sta - sta[0]) @ grad
    rovers = rng.uniform([0, -20e3], [210e3, 20e3], size=(500, 2))
    corr, codes = interpolate(sta, rovers, V, Model.PLANE)
    np.testing.assert_allclose(corr, (rovers - sta[0]) @ grad, atol=1e-12)
    assert np.all(codes == 0)


def test_kriging_is_exact_for_a_planar_field_and_at_every_station():
    """Universal kriging with a linear drift: any plane is reproduced (with its offset), and a rover on a
    station gets that station's residual, whatever the field."""
    rng = np.random.default_rng(11)
    sta = np.vstack([LINE, OFF_LINE])
    grad = rng.normal(size=(2, 30)) * 1e-7
    V = (sta - sta[0]) @ grad
    rovers = rng.uniform([0, -20e3], [210e3, 20e3], size=(300, 2))
    corr, codes = interpolate(sta, rovers, V)
    np.testing.assert_allclose(corr, (rovers - sta[0]) @ grad, atol=1e-10)
    assert np.all(codes == MODEL_CODES[Model.KRIGING])
    W = kriging_weights(sta, sta)
    np.testing.assert_allclose(W, np.eye(len(sta)), atol=1e-8)
    rough = rng.normal(scale=0.05, size=(len(sta), 5))
    rough[0] = 0.0
    np.testing.assert_allclose(interpolate(sta, sta, rough)[0], rough, atol=1e-8)


def test_kriging_weighs_the_corners_of_a_square_equally_at_its_centre():
    """In the middle of a network the stations count alike (the plane through the master alone gives the
    master and its opposite station twice the weight of the other two)."""
    square = np.array([[0.0, 0.0], [35e3, -35e3], [0.0, -70e3], [-35e3, -35e3]])
    centre = np.array([[0.0, -35e3]])
    np.testing.assert_allclose(kriging_weights(square, centre), [[0.25] * 4], atol=1e-9)
    np.testing.assert_allclose(plane_weights(square, centre), [[0.0, 1 / 6, 1 / 3, 1 / 6]], atol=1e-9)


def test_along_line_gives_no_correction_far_across_the_line():
    """Two stations only (a satellite fixed on one baseline): the model knows nothing across their line."""
    sta = np.array([[0.0, 0.0], [50e3, 0.0]])
    V = np.array([[0.0], [0.03]])
    near = np.array([[25e3, 0.5 * MAX_CROSS_LINE_DISTANCE_M]])
    far = np.array([[25e3, 2.0 * MAX_CROSS_LINE_DISTANCE_M]])
    c_near, code = interpolate(sta, near, V)
    c_far, code_far = interpolate(sta, far, V)
    assert abs(c_near[0, 0] - 0.015) < 1e-12 and code[0] == MODEL_CODES[Model.ALONG_LINE]
    assert np.isnan(c_far[0, 0]) and code_far[0] == MODEL_CODES[Model.ALONG_LINE]


def test_plane_model_refuses_collinear_stations():
    with pytest.raises(InterpolationError):
        plane_weights(np.array([[0, 0], [1e3, 0], [2e3, 0]], float), np.zeros((1, 2)))


def test_along_line_model_is_exact_at_stations_and_linear_between():
    rng = np.random.default_rng(2)
    V = rng.normal(scale=0.05, size=(4, 12))
    V[0] = 0.0
    corr, codes = interpolate(LINE, LINE, V)
    assert np.all(codes == 1)
    np.testing.assert_allclose(corr, V, atol=1e-12)
    mid = 0.5 * (LINE[1] + LINE[2])
    corr_mid, _ = interpolate(LINE, mid, V)
    np.testing.assert_allclose(corr_mid[0], 0.5 * (V[1] + V[2]), atol=1e-9)


def _rms(errs):
    return float(np.sqrt(np.mean(np.square(errs))))


def test_along_line_follows_a_nonlinear_trend_that_a_single_plane_cannot():
    """Over 210 km the ionosphere is not one plane; the piecewise model follows it between stations."""
    rng = np.random.default_rng(3)
    truth_at = lambda p: 0.05 * np.sin(2 * np.pi * p[..., 0] / 300e3)  # noqa: E731  5 cm, 300 km wave
    rovers = np.column_stack([np.linspace(5e3, 205e3, 50), np.linspace(0, 3e3, 50)])
    errs = {Model.PLANE: [], Model.ALONG_LINE: []}
    for _ in range(20):
        V = (truth_at(LINE) - truth_at(LINE[0]) + rng.normal(scale=0.003, size=4))[:, None]
        V[0] = 0.0
        for model in errs:
            corr, _ = interpolate(LINE, rovers, V, model)
            errs[model].append(corr[:, 0] - (truth_at(rovers) - truth_at(LINE[0])))
    rms = {m: _rms(e) for m, e in errs.items()}
    assert rms[Model.ALONG_LINE] < 0.5 * rms[Model.PLANE], rms


def test_plane_on_nearly_collinear_stations_amplifies_noise_off_the_line():
    """200 m of cross-line spread: 3 mm of station noise becomes centimetres 3 km off the line."""
    rng = np.random.default_rng(5)
    sta = np.array([[0.0, 0.0], [70e3, 200.0], [140e3, -100.0], [210e3, 50.0]])
    assert select_model(sta) is Model.ALONG_LINE
    rover = np.array([[100e3, 3e3]])
    errs = {Model.PLANE: [], Model.ALONG_LINE: []}
    for _ in range(200):
        V = rng.normal(scale=0.003, size=(4, 1))
        V[0] = 0.0
        for model in errs:
            corr, _ = interpolate(sta, rover, V, model)
            errs[model].append(corr[0, 0])  # the truth is zero
    rms = {m: _rms(e) for m, e in errs.items()}
    assert rms[Model.PLANE] > 0.02 and rms[Model.ALONG_LINE] < 0.005, rms


def test_distance_weights_sum_to_one_and_honour_a_station():
    w = distance_weights(LINE, np.array([[35e3, 1e3], LINE[2]]))
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
    np.testing.assert_array_equal(w[1], np.eye(4)[2])


def test_missing_residuals_use_the_stations_that_have_them():
    sta = np.vstack([LINE, OFF_LINE])
    grad = np.array([[1e-7], [-2e-7]])
    V = np.repeat((sta - sta[0]) @ grad, 3, axis=1)
    V[4, 1] = np.nan  # one off-line station lacks satellite 1: still 2-D with the other
    V[4:, 2] = np.nan  # both off-line stations lack satellite 2: falls back to the line
    V[0, 0] = np.nan  # the master's own residual is zero by definition, NaN or not
    rover = np.array([[100e3, 2e3]])
    corr, codes = interpolate(sta, rover, V)
    exact = float(((rover - sta[0]) @ grad)[0, 0])
    np.testing.assert_allclose(corr[0, :2], exact, atol=1e-12)
    assert list(codes) == [MODEL_CODES[Model.KRIGING]] * 2 + [MODEL_CODES[Model.ALONG_LINE]]
    assert abs(corr[0, 2] - exact) < 0.01


def test_leave_one_out_is_zero_on_a_planar_field_and_reports_curvature():
    sta = np.vstack([LINE, OFF_LINE])
    V = (sta - sta[0]) @ np.array([[1e-7], [3e-7]])
    err = leave_one_out(sta, V, Model.PLANE)
    assert np.isnan(err[0]).all()
    np.testing.assert_allclose(err[1:], 0.0, atol=1e-12)
    curved = V + 1e-12 * ((sta - sta[0]) ** 2).sum(axis=1, keepdims=True)
    assert np.nanmax(np.abs(leave_one_out(sta, curved, Model.PLANE))) > 1e-3


def test_many_rovers_and_satellites_in_one_product():
    rng = np.random.default_rng(4)
    sta = np.vstack([LINE, OFF_LINE])
    V = rng.normal(scale=0.02, size=(6, 40))
    V[0] = 0
    rovers = np.column_stack([rng.uniform(0, 210e3, 2000), rng.uniform(-2e3, 5e3, 2000)])
    corr, codes = interpolate(sta, rovers, V)
    assert corr.shape == (2000, 40) and np.isfinite(corr).all()


# --- the figure on the simulated network, against the simulator's truth --------------------------------
#
# Issue 5: "interpolated DD ionosphere at a point ~35 km from the nearest station: RMS <= 1 cm quiet (report the
# storm figure); leave-one-station-out prediction error reported". network-70km: check1 sits 35 km from each of
# four stations (opposite ones 70 km apart). The network engine solves the four stations (NetworkSolver, the
# simulator's observables, never its truth); its DD ionosphere residuals are interpolated to check1 exactly as
# the VRS does (interpolate() on the network's station coordinates, residuals and master); the result is
# compared with the simulator's true DD ionosphere between check1 and the master. DDs are re-referenced to the
# highest corrected satellite at check1 per system, as a rover forms them.

NETWORK_RATE_HZ = 0.5
NETWORK_DURATION_S = {"quiet": 1200.0, "moderate": 600.0, "storm": 600.0}
TARGET_QUIET_RMS_M = 0.01


def _network_figures(level: str) -> dict:
    from augnet.centre.network import NetworkSolver
    from augnet.gnss.geometry import ecef_to_enu
    from stations.ionosphere import delay_m
    from stations.scenario import load_scenario
    from stations.world import World
    from tests.centre.simdata import station_epochs

    sc = load_scenario("network-70km").model_copy(update={"duration_s": NETWORK_DURATION_S[level],
                                                          "rate_hz": NETWORK_RATE_HZ})
    iono = sc.errors.ionosphere.model_copy(update={"level": level})
    sc = sc.model_copy(update={"errors": sc.errors.model_copy(update={"ionosphere": iono})})
    world = World(sc)
    ids = world.receiver_ids
    rover = ids.index("check1")
    col = {s: j for j, s in enumerate(world.sats)}
    stations = {r.id: r.ecef[0] for r in world.receivers if r.id != "check1"}
    net = NetworkSolver(stations)
    est, floor, loo_est, loo_true = [], [], [], []
    for block in world.epochs():
        per = {r: station_epochs(world, block, i) for i, r in enumerate(ids) if r in stations}
        i1 = delay_m(block.stec_tecu, world.freq_hz[None, None, :, 0])  # truth, each system's first signal
        for e in range(len(block.t_gpst)):
            ne = net.update({r: per[r][e] for r in stations}, world.nav)
            if not len(ne.sats):
                continue
            rows = [ids.index(s) for s in ne.stations]
            m = rows[0]
            cols = np.array([col[s] for s in ne.sats])
            refs = np.array([col.get(ne.refs.get(s[0], ""), -1) for s in ne.sats])
            ok_ref = refs >= 0
            sd = i1[e][:, cols] - i1[e][:, np.maximum(refs, 0)]  # (receivers, sats): sat minus network ref
            truth = np.where(ok_ref, sd - sd[m], np.nan)  # DD against the master
            V = ne.dd_iono_m
            supported = np.isfinite(V[1:]).any(axis=0) & ok_ref  # some baseline fixed it
            V_true = np.where(np.isfinite(V), truth[rows], np.nan)
            rov_en = ecef_to_enu(world.receivers[rover].ecef[0] - ne.station_xyz_m[0], ne.station_xyz_m[0])[None, :2]
            c_est, _ = interpolate(ne.station_en_m, rov_en, V)
            c_true, _ = interpolate(ne.station_en_m, rov_en, V_true)
            err_est = c_est[0] - truth[rover]
            err_true = c_true[0] - truth[rover]
            el = block.elevation_rad[e, rover, cols]
            use = supported & np.isfinite(err_est)
            for system in {s[0] for s in ne.sats}:
                k = np.flatnonzero(use & np.array([s[0] == system for s in ne.sats]))
                if len(k) < 2:
                    continue
                r = k[np.argmax(el[k])]
                est.extend(err_est[k[k != r]] - err_est[r])
                floor.extend(err_true[k[k != r]] - err_true[r])
            # leave one station out: each non-master station predicted from the others, against its own
            # residual (what the network can see) and against the truth
            lo = leave_one_out(ne.station_en_m, V)
            fin = np.isfinite(lo)
            loo_est.extend(lo[fin])
            loo_true.extend((lo + V - truth[rows])[fin])
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    return {"level": level, "n": len(est), "rms_m": rms(est), "p95_m": float(np.percentile(np.abs(est), 95)),
            "floor_rms_m": rms(floor), "loo_rms_m": rms(loo_est), "loo_true_rms_m": rms(loo_true)}


@pytest.fixture(scope="module")
def network_figures():
    out = {level: _network_figures(level) for level in NETWORK_DURATION_S}
    for f in out.values():
        print(f"\nnetwork-70km {f['level']}: interpolated DD ionosphere at check1 (35 km from every station) "
              f"{f['rms_m'] * 100:.2f} cm RMS, 95 % {f['p95_m'] * 100:.2f} cm (n={f['n']}); from the true station "
              f"residuals {f['floor_rms_m'] * 100:.2f} cm; leave-one-station-out {f['loo_rms_m'] * 100:.2f} cm "
              f"against the station's residual, {f['loo_true_rms_m'] * 100:.2f} cm against the truth")
    return out


@pytest.mark.slow
@pytest.mark.timeout(LONG_RUN_TIMEOUT_S)
def test_interpolated_dd_ionosphere_at_35_km_quiet(network_figures):
    """Measured when written (20 min at 0.5 Hz): 0.87-0.95 cm RMS (95 % 1.6-1.8 cm) as the network engine changed
    under it; 0.62-0.64 cm from the true station residuals (what the non-linear field leaves); the rest is the station residuals' own error (~0.8 cm per
    station and DD: the phase multipath the 30 s smoothing on each baseline leaves, and that smoothing's
    30 s lag behind a DD ionosphere moving ~0.1 mm/s). The margin to the 1 cm target is thin."""
    f = network_figures["quiet"]
    assert f["n"] > 3000
    assert f["rms_m"] <= TARGET_QUIET_RMS_M
    assert f["floor_rms_m"] < f["rms_m"]


@pytest.mark.slow
@pytest.mark.timeout(LONG_RUN_TIMEOUT_S)
def test_moderate_and_storm_and_leave_one_out_are_reported(network_figures):
    """Loose bounds only: the figures are printed. Measured when written (10 min each): moderate 1.6 cm
    (floor 1.4-1.5), storm 32-43 cm (floor 29-30; the storm's station residuals themselves are off by more as
    the engine changed). Leave-one-out (DDs against the network's reference satellites; a corner of the square
    predicted from the other three, i.e. extrapolated 50-70 km): 3.0-3.1 cm quiet, 5.5-6.0 cm moderate,
    17-32 cm storm."""
    q, mod, storm = network_figures["quiet"], network_figures["moderate"], network_figures["storm"]
    assert mod["n"] > 1000 and storm["n"] > 1000
    assert q["rms_m"] < mod["rms_m"] < 0.03
    assert 0.05 < storm["rms_m"] < 0.6
    assert q["loo_rms_m"] < 0.05 and q["loo_rms_m"] > q["rms_m"]


def _floor_from_truth(level: str, duration_s: float = 3600.0, rate_hz: float = 0.05) -> float:
    """RMS error at check1 of the kriging of the four stations' TRUE DD ionosphere (no estimation error at
    all): what the non-linear field between stations 70 km apart leaves. Satellites above 15 degrees at every
    receiver; reference the highest at the master; master NORTH."""
    from augnet.gnss.geometry import ecef_to_enu
    from stations.ionosphere import delay_m
    from stations.scenario import load_scenario
    from stations.world import World

    sc = load_scenario("network-70km").model_copy(update={"duration_s": duration_s, "rate_hz": rate_hz})
    iono = sc.errors.ionosphere.model_copy(update={"level": level})
    sc = sc.model_copy(update={"errors": sc.errors.model_copy(update={"ionosphere": iono})})
    world = World(sc)
    ids = world.receiver_ids
    sta = [ids.index(s) for s in ("NORTH", "EAST", "SOUTH", "WEST")]
    rover = ids.index("check1")
    xyz = np.array([r.ecef[0] for r in world.receivers])
    en = ecef_to_enu(xyz - xyz[sta[0]], xyz[sta[0]])[:, :2]
    errs = []
    for block in world.epochs():
        i1 = delay_m(block.stec_tecu, world.freq_hz[None, None, :, 0])
        for e in range(len(block.t_gpst)):
            el = block.elevation_rad[e]
            for system in np.unique(world.sat_system):
                cols = np.flatnonzero((world.sat_system == system) & (el[sta + [rover]] > np.radians(15)).all(axis=0))
                if len(cols) < 2:
                    continue
                ref = cols[np.argmax(el[sta[0], cols])]
                sd = i1[e][:, cols] - i1[e][:, [ref]]
                dd = sd - sd[sta[0]]
                corr, _ = interpolate(en[sta], en[rover], dd[sta])
                errs.extend(corr[0] - dd[rover])
    return float(np.sqrt(np.mean(np.square(errs))))


@pytest.mark.slow
def test_interpolation_floor_of_each_ionosphere_level():
    """The floor in stations/README.md: quiet 0.63 cm, moderate 1.35 cm, active 5.8 cm, storm 18 cm (an hour at
    20 s); quiet leaves room under the 1 cm target for the station residuals' own error, moderate does not."""
    floors = {level: _floor_from_truth(level) for level in ("quiet", "moderate", "active", "storm")}
    print("\nkriging floor at check1 from true station residuals: "
          + ", ".join(f"{k} {v * 100:.2f} cm" for k, v in floors.items()))
    assert floors["quiet"] < 0.008
    assert 0.01 < floors["moderate"] < 0.02
    assert floors["quiet"] < floors["moderate"] < floors["active"] < floors["storm"]
