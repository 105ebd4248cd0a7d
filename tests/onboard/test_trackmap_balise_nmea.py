"""Track map matching among parallel tracks, protection levels, virtual balise capture, NMEA output."""

from __future__ import annotations

import math

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_geodetic, enu_to_ecef, geodetic_deg_to_ecef
from augnet.onboard.balise import BaliseDetector, ListSink
from augnet.onboard.nmea import checksum, gga, rmc
from augnet.onboard.rtk import RtkSolution, Status
from augnet.onboard.trackmap import FORMAT, TrackDatabase, TrackMapError, gaussian_k

ORIGIN = geodetic_deg_to_ecef(34.5, 113.5, 120.0)
SEPARATION_M = 4.6
STEP_M = 10.0


def _centreline(n=600):
    """5 km+: 2 km straight heading east-north-east, then a 3 km radius curve, in local ENU."""
    s = np.arange(n) * STEP_M
    heading0 = math.radians(70.0)  # from north
    radius = 3000.0
    pts, tang = [], []
    for si in s:
        if si <= 2000.0:
            h = heading0
            e, nn = si * math.sin(h), si * math.cos(h)
        else:
            a = (si - 2000.0) / radius
            h = heading0 + a
            e0, n0 = 2000.0 * math.sin(heading0), 2000.0 * math.cos(heading0)
            # centre of the right-hand curve
            ce, cn = e0 + radius * math.cos(heading0), n0 - radius * math.sin(heading0)
            e = ce - radius * math.cos(h)
            nn = cn + radius * math.sin(h)
        pts.append((e, nn, 0.002 * si))  # a 2 per mille grade
        tang.append((math.sin(h), math.cos(h)))
    return np.array(pts), np.array(tang)


def _to_llh(enu):
    xyz = ORIGIN + enu_to_ecef(enu, ORIGIN)
    llh = ecef_to_geodetic(xyz)
    return np.column_stack((np.degrees(llh[:, 0]), np.degrees(llh[:, 1]), llh[:, 2]))


def make_db():
    c, t = _centreline()
    left = np.column_stack((-t[:, 1], t[:, 0], np.zeros(len(t))))  # left normal in ENU
    up = c + 0.5 * SEPARATION_M * left
    down = c - 0.5 * SEPARATION_M * left
    d = {
        "format": FORMAT, "name": "two-track test line",
        "tracks": [
            {"id": "UP", "line": "L1", "name": "up", "km_start": 10.0, "points": _to_llh(up).tolist()},
            {"id": "DN", "line": "L1", "name": "down", "km_start": 10.0, "points": _to_llh(down).tolist()},
        ],
        "km_posts": [{"track": "UP", "km": 11.0, "label": "K11"}],
        "balises": [
            {"id": "VB1", "track": "UP", "km": 10.5004, "telegram": "a1b2c3", "linked": True},
            {"id": "VB2", "track": "UP", "km": 12.7771, "telegram": "0102", "linked": True},
            {"id": "VB3", "track": "DN", "km": 11.2345, "telegram": "ff", "linked": False},
            {"id": "VB4", "track": "UP", "km": 14.9, "telegram": "", "linked": True},
        ],
    }
    return TrackDatabase.from_dict(d)


@pytest.fixture(scope="module")
def db():
    return make_db()


def test_file_round_trip_and_refusals(db, tmp_path):
    p = tmp_path / "line.json"
    db.save(p)
    db2 = TrackDatabase.load(p)
    assert set(db2.tracks) == {"UP", "DN"}
    assert [b.telegram for b in db2.balises] == [b.telegram for b in db.balises]
    assert db2.track_length_m["UP"] == pytest.approx(db.track_length_m["UP"])
    with pytest.raises(TrackMapError):
        TrackDatabase.from_dict({"format": "something else"})
    with pytest.raises(TrackMapError):
        TrackDatabase.from_dict({"format": FORMAT, "tracks": [{"id": "A", "points": [[1, 2, 3]]}]})
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(TrackMapError):
        TrackDatabase.load(bad)


@pytest.mark.parametrize("track,km", [("UP", 10.25), ("DN", 11.9), ("UP", 13.333), ("DN", 15.0)])
def test_points_on_a_track_match_it_with_the_right_chainage(db, track, km):
    p = db.position_at(track, km)
    m = db.match(p, np.eye(3) * 0.01**2)
    assert m.track == track
    assert m.km == pytest.approx(km, abs=1e-6)
    assert abs(m.cross_m) < 1e-3
    assert m.confirmed
    assert m.nearest_other_m == pytest.approx(SEPARATION_M, abs=0.05)


def test_cross_track_offset_sign_and_confirmation_against_the_protection_level(db):
    T, N, U = db.tangent_at("UP", 12.0)
    base = db.position_at("UP", 12.0)
    # 1 m to the left (away from DN): confirmed with a cm-level covariance
    m = db.match(base + 1.0 * N, np.eye(3) * 0.02**2)
    assert m.track == "UP" and m.cross_m == pytest.approx(1.0, abs=1e-3) and m.confirmed
    # 2.2 m towards DN (0.1 m from the midline): the nearest is still UP but not confirmed
    m = db.match(base - 2.2 * N, np.eye(3) * 0.02**2)
    assert m.track == "UP" and not m.confirmed
    # 2.5 m towards DN: DN is the nearer track
    assert db.match(base - 2.5 * N, np.eye(3) * 0.02**2).track == "DN"
    # on the track but with a metre-level (SPP) covariance: never confirmed
    m = db.match(base, np.eye(3) * 1.0)
    assert m.track == "UP" and not m.confirmed
    # the default K is the allocated per-decision one (1e-9/h over 3600 decisions/h, half fault-free)
    assert m.cross_pl_m == pytest.approx(gaussian_k(1e-9 * 0.5 / 3600.0) * 1.0, rel=1e-6)


def test_protection_levels_project_the_covariance_on_the_track(db):
    T, N, U = db.tangent_at("UP", 11.0)
    # 0.3 m sigma along the track, 0.01 m across, 0.05 m up
    C = 0.3**2 * np.outer(T, T) + 0.01**2 * np.outer(N, N) + 0.05**2 * np.outer(U, U)
    m = db.match(db.position_at("UP", 11.0), C, integrity_risk=1e-9, allocation=None)  # fault-free term alone
    k = gaussian_k(1e-9)
    assert k == pytest.approx(6.109, abs=0.01)  # two-sided Gaussian quantile for 1e-9
    assert m.along_pl_m == pytest.approx(k * 0.3, rel=1e-3)
    assert m.cross_pl_m == pytest.approx(k * 0.01, rel=1e-2)
    assert (m.along_sigma_m, m.cross_sigma_m) == pytest.approx((0.3, 0.01), rel=1e-2)
    assert m.confirmed


def test_protection_levels_bound_the_satellite_and_correction_faults(db):
    # decision 0253: a satellite fault or a wrong correction the checks let through biases the fix by up to
    # b_i; the PL is max(K sigma, b_i + K_md sigma) (decision 0250), so a fixed 2 cm sigma no longer gives 0.15 m
    from augnet.onboard.integrity_allocation import DEFAULT_ALLOCATION, DEFAULT_FAULT_MODES

    T, N, U = db.tangent_at("UP", 11.0)
    C = 0.02**2 * np.outer(T, T) + 0.01**2 * np.outer(N, N) + 0.05**2 * np.outer(U, U)
    m = db.match(db.position_at("UP", 11.0), C)
    sat = DEFAULT_FAULT_MODES[0]
    k_md = DEFAULT_ALLOCATION.k_missed_detection(sat)
    assert m.along_pl_m == pytest.approx(sat.bias_along_m + k_md * 0.02, rel=1e-3)
    assert m.cross_pl_m == pytest.approx(sat.bias_cross_m + k_md * 0.01, rel=1e-2)
    assert m.along_pl_m > DEFAULT_ALLOCATION.k_fault_free * 0.02
    # a wide sigma: the fault-free term dominates again
    wide = db.match(db.position_at("UP", 11.0), C * 100.0)
    assert wide.along_pl_m == pytest.approx(DEFAULT_ALLOCATION.k_fault_free * 0.2, rel=1e-3)


def test_off_the_map_and_no_position(db):
    T, N, U = db.tangent_at("UP", 12.0)
    m = db.match(db.position_at("UP", 12.0) + 60.0 * N, np.eye(3) * 1e-4)
    assert m.track is None and not m.confirmed and "gate" in m.message
    assert db.match(np.full(3, np.nan)).track is None


def _drive(db, track, km_from, km_to, speed_m_s, t0=1000.0, sigma=0.01, rng=None, skip=()):
    """Positions of an antenna moving along a track at constant speed, one per second."""
    n = int(abs(km_to - km_from) * 1000.0 / speed_m_s) + 1
    sign = 1.0 if km_to > km_from else -1.0
    out = []
    for i in range(n):
        km = km_from + sign * i * speed_m_s / 1000.0
        p = db.position_at(track, km)
        if rng is not None:
            p = p + rng.normal(0.0, sigma, 3)
        out.append((t0 + i, km, p, i in skip))
    return out


def test_virtual_balises_captured_once_each_on_the_right_track_with_small_error(db):
    rng = np.random.default_rng(4)
    sink = ListSink()
    det = BaliseDetector(db, sink)
    speed = 55.0  # 200 km/h
    for t, km, p, _ in _drive(db, "UP", 10.1, 14.8, speed, rng=rng, sigma=0.02):
        det.update(t, db.match(p, np.eye(3) * 0.02**2))
    ids = [e.balise_id for e in sink.events]
    assert ids == ["VB1", "VB2"]  # VB3 is on the other track, VB4 beyond the run
    for e in sink.events:
        true_t = 1000.0 + (e.km - 10.1) * 1000.0 / speed
        assert abs(e.time - true_t) * speed < 0.5  # capture position error under 0.5 m
        assert e.direction == 1 and e.along_pl_m < 0.7 and not e.late  # 0.5 m satellite-fault bias + K_md sigma
    assert sink.events[0].telegram == bytes.fromhex("a1b2c3")


def test_reverse_direction_lever_arm_and_late_capture(db):
    sink = ListSink()
    det = BaliseDetector(db, sink, lever_arm_m=10.0)  # reference point 10 m ahead of the antenna
    speed = 20.0
    run = _drive(db, "DN", 11.5, 11.0, speed, skip=range(10, 14))
    for t, km, p, skip in run:
        cov = np.eye(3) * (4.0 if skip else 0.01**2)  # an SPP stretch: matches not confirmed
        det.update(t, db.match(p, cov))
    assert [e.balise_id for e in sink.events] == ["VB3"]
    e = sink.events[0]
    assert e.direction == -1
    # the reference point reaches the balise 10 m (0.5 s) before the antenna does
    true_t = 1000.0 + ((11.5 - 11.2345) * 1000.0 - 10.0) / speed
    assert abs(e.time - true_t) * speed < 0.5
    assert not e.linked
    assert e.late  # decided across the unconfirmed stretch, interpolated over it


def _solution(status=Status.FIX, velocity=(np.nan, np.nan, np.nan)):
    p = geodetic_deg_to_ecef(35.134699012, 136.977575471, 104.8596)
    return RtkSolution(1403252400.0, status, np.asarray(p), np.eye(3) * 1e-6, n_sats=21, ratio=12.0, age_s=1.2,
                       velocity_m_s=np.asarray(velocity, float))


def test_gga_round_trips_through_pynmeagps_with_rtk_precision():
    from pynmeagps import NMEAReader

    s = gga(_solution())
    assert s.endswith("\r\n") and s.startswith("$GNGGA,")
    body, cs = s.strip()[1:].split("*")
    assert checksum(body) == cs
    msg = NMEAReader.parse(s.encode())
    assert msg.quality == 4
    assert msg.lat == pytest.approx(35.134699012, abs=2e-9)
    assert msg.lon == pytest.approx(136.977575471, abs=2e-9)
    assert msg.alt == pytest.approx(104.8596, abs=1e-3)
    assert msg.numSV == 21
    assert msg.diffAge == pytest.approx(1.2)
    # 2024-06-24 08:20:00 GPST is 08:19:42 UTC (18 leap seconds)
    assert s.split(",")[1] == "081942.00"
    assert NMEAReader.parse(gga(_solution(Status.FLOAT)).encode()).quality == 5
    assert NMEAReader.parse(gga(_solution(Status.SINGLE)).encode()).quality == 1
    none = gga(RtkSolution(1403252400.0, Status.NONE, np.full(3, np.nan), np.full((3, 3), np.nan)))
    assert NMEAReader.parse(none.encode()).quality == 0


def test_rmc_speed_and_course_from_velocity():
    from pynmeagps import NMEAReader
    from augnet.gnss.geometry import enu_to_ecef as e2e

    p = _solution().position_m
    v = e2e(np.array([10.0, 10.0, 0.0]), p)  # north-east at 14.14 m/s
    msg = NMEAReader.parse(rmc(_solution(velocity=v)).encode())
    assert msg.status == "A" and msg.posMode == "R"
    assert msg.spd == pytest.approx(14.142 * 3600 / 1852, abs=0.01)
    assert msg.cog == pytest.approx(45.0, abs=0.01)


def test_onboard_unit_ties_rtk_map_balises_and_nmea(shared_data):
    """One step through the whole unit on a synthetic rover placed on the test line's track."""
    from augnet.gnss.ephemeris import NavigationData
    from augnet.gnss.rinex import read_nav
    from augnet.onboard.observations import epochs
    from augnet.onboard.rtk import RtkOptions
    from augnet.onboard.unit import OnboardUnit
    from tests.onboard.synth import simulate, visible_sats

    nav = NavigationData(read_nav(shared_data / "rinex/static-1m-2024/base.nav").ephemerides)
    db = make_db()
    t = 1403252400.0 + np.arange(6.0)
    speed = 30.0
    path = np.array([db.position_at("UP", 10.49 + speed * k / 1000.0) for k in range(6)])
    base_pos = db.position_at("DN", 10.0)
    sats = visible_sats(nav, base_pos, t[0])
    base, _ = simulate(nav, sats, t, base_pos, seed=1)
    rover, _ = simulate(nav, sats, t, path, seed=2)
    unit = OnboardUnit(nav, base_pos, db, options=RtkOptions(systems=("G", "E")))
    outs = [unit.step(r, b) for r, b in zip(epochs(rover), epochs(base))]
    assert all(o.solution.status == Status.FIX for o in outs)
    assert all(o.match.track == "UP" and o.match.confirmed for o in outs)
    assert [e.balise_id for e in unit.sink.events] == ["VB1"]
    assert outs[0].gga.startswith("$GNGGA") and ",4," in outs[0].gga
    rec = outs[-1].record()
    assert rec["track"] == "UP" and rec["status"] == "fix" and rec["track_confirmed"]
    assert rec["km"] == pytest.approx(10.49 + 5 * speed / 1000.0, abs=0.001)
