"""Track geometry and train kinematics: curves, grades, parallel tracks, blockages, speed profile."""

from __future__ import annotations

import numpy as np
import pytest

from stations.kinematics import train_motion
from stations.scenario import load_scenario
from stations.track import TrackLine


@pytest.fixture(scope="module")
def demo():
    sc = load_scenario("demo")
    return sc, TrackLine(sc.line)


def test_line_length_and_curves(demo):
    sc, tl = demo
    assert 205e3 < tl.length_m < 230e3
    # curvature: heading changes only on arcs, and never sharper than the radius allows
    h = tl.tangent_xy
    dpsi = np.abs(np.angle(np.exp(1j * np.diff(np.arctan2(h[:, 1], h[:, 0])))))
    ds = np.diff(tl.s_m)
    curvature = dpsi[1:] / np.maximum(ds[1:], 1e-9)
    assert curvature.max() <= 1.0 / sc.line.curve_radius_m * 1.05
    assert (dpsi > 1e-4).sum() > 50  # there are curves


def test_grades_follow_waypoints(demo):
    sc, tl = demo
    p0 = tl.point(0.0)
    assert p0[2] == pytest.approx(sc.line.waypoints[0].h_m)
    assert tl.point(tl.length_m)[2] == pytest.approx(sc.line.waypoints[-1].h_m)
    g = tl.grade(np.array([1e3, 100e3]))
    assert np.all(np.abs(g) < 0.01)  # under 10 per mille: a plain line
    s = np.array([1e3, 1.1e3])
    dh = np.diff(tl.point(s)[:, 2])[0]
    assert dh / 100.0 == pytest.approx(g[0], rel=1e-6)


def test_parallel_tracks_are_spaced(demo):
    sc, tl = demo
    s = np.linspace(0, tl.length_m, 777)
    a = tl.point(s, tl.track_offset_m(1))[:, :2]
    b = tl.point(s, tl.track_offset_m(2))[:, :2]
    sep = np.linalg.norm(a - b, axis=1)
    assert np.allclose(sep, sc.line.track_spacing_m, atol=0.01)
    # loop tracks exist only inside station areas, a further 4.6 m out
    loop = tl.tracks["L1-S1-1"]
    assert loop.s_m.min() >= 68.5e3 - 1 and loop.s_m.max() <= 70.5e3 + 1


def test_nearest_track_recovers_track_and_km(demo):
    sc, tl = demo
    s = np.array([5e3, 69.3e3, 150.7e3])
    pts = tl.point(s, tl.track_offset_m(2))
    ids, km, dist = tl.nearest_track(pts)
    assert ids[0] == "L1-2" and ids[2] == "L1-2"
    assert np.allclose(km, s, atol=0.05)
    assert np.all(dist < 1e-3)


def test_blockage_touch_between_epochs(demo):
    sc, tl = demo
    # a 15 m overbridge at km 120 passed between two epochs 83 m apart still breaks lock
    full, wall = tl.blockage_mask_deg(np.array([119.95e3, 125e3, 30.5e3]),
                                      np.array([120.033e3, 125.08e3, 30.6e3]))
    assert list(full) == [90.0, 0.0, 0.0] and list(wall) == [0.0, 0.0, 35.0]


def test_cutting_hides_across_not_along():
    from stations.track import cutting_mask_rad
    m = np.degrees(cutting_mask_rad(35.0, np.radians([0.0, 90.0, 180.0, 270.0, 45.0]), 0.0))
    assert np.allclose(m[[0, 2]], 0.0) and np.allclose(m[[1, 3]], 35.0)
    assert 0.0 < m[4] < 35.0


def test_speed_profile_accelerates_brakes_and_stops():
    sc = load_scenario("demo")
    tl = TrackLine(sc.line)
    train = sc.trains[0].model_copy(update=dict(start_speed_kmh=0.0, start_km=200.0, speed_kmh=160.0,
                                                accel_m_s2=0.5, decel_m_s2=0.7))
    t = np.arange(0.0, 600.0)
    m = train_motion(train, tl.length_m, t)
    assert m.speed_m_s[0] == 0.0
    assert np.max(m.accel_m_s2) == pytest.approx(0.5, abs=1e-6)
    assert np.max(m.speed_m_s) == pytest.approx(160 / 3.6, rel=1e-3)
    assert m.s_m[-1] == pytest.approx(tl.length_m, abs=1.0)  # stopped at the buffer
    assert m.speed_m_s[-1] == 0.0
    assert np.min(m.accel_m_s2) >= -0.7 * 1.5 - 1e-9
    assert np.all(np.diff(m.s_m) >= -1e-9)


def test_restriction_respected_and_direction():
    sc = load_scenario("demo")
    tl = TrackLine(sc.line)
    from stations.scenario import SpeedChange
    train = sc.trains[1].model_copy(update=dict(speed_profile=[SpeedChange(from_km=0, speed_kmh=300),
                                                               SpeedChange(from_km=140, speed_kmh=160),
                                                               SpeedChange(from_km=145, speed_kmh=300)]))
    t = np.arange(0.0, 400.0, 0.5)
    m = train_motion(train, tl.length_m, t)
    inside = (m.s_m >= 140e3) & (m.s_m < 145e3)
    assert inside.any()
    assert m.speed_m_s[inside].max() <= 160 / 3.6 + 0.05
    assert np.all(np.diff(m.s_m) <= 1e-9)  # direction -1: km decreasing
