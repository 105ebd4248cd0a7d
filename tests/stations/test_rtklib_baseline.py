"""Must-show: RTKLIB rnx2rtkp fixes the simulated 10 km baseline and lands on the true baseline.

Kinematic mode, L1+L2, station A as base (its truth position given), station B as rover, GPS +
Galileo + BeiDou, 15 degree mask, continuous ambiguity resolution, ratio 3: fixed in >= 95 % of the
epochs after the first minute, and within 1 cm horizontal / 2 cm vertical of the truth in >= 95 %
of the fixed epochs.  A tool nobody here wrote reads our RINEX observations and navigation file.
"""

from __future__ import annotations

import csv
import subprocess

import numpy as np
import pytest

from augnet.gnss.geometry import ecef_to_enu
from stations.record import record
from stations.scenario import load_scenario
from tests.conftest import require_tool
from tests.rtklib_pos import read_pos

pytestmark = pytest.mark.slow

DURATION_S = 360  # 6 minutes of 1 Hz data: the first minute is convergence, five are judged

CONFIG = """\
pos1-posmode       =kinematic
pos1-frequency     =l1+2
pos1-soltype       =forward
pos1-elmask        =15
pos1-navsys        =41
pos1-ionoopt       =brdc
pos1-tropopt       =saas
pos1-sateph        =brdc
pos2-armode        =continuous
pos2-arthres       =3
pos2-gloarmode     =off
pos2-bdsarmode     =on
out-solformat      =xyz
out-outhead        =on
ant2-postype       =xyz
ant2-pos1          ={x:.4f}
ant2-pos2          ={y:.4f}
ant2-pos3          ={z:.4f}
"""


def _truth(path, rx):
    for row in csv.DictReader(open(path)):
        if row["receiver"] == rx:
            return np.array([float(row["x_m"]), float(row["y_m"]), float(row["z_m"])])
    raise KeyError(rx)


def _judge_baseline(tmp_path, sc, nav_ephemerides=None, label="baseline-10km"):
    rnx2rtkp = require_tool("rnx2rtkp")
    record(sc, tmp_path, nav_ephemerides=nav_ephemerides, rtcm=False)
    base = _truth(tmp_path / "truth.csv", "A")
    rover = _truth(tmp_path / "truth.csv", "B")
    assert 9.9e3 < np.linalg.norm(rover - base) < 10.1e3
    conf = tmp_path / "rtk.conf"
    conf.write_text(CONFIG.format(x=base[0], y=base[1], z=base[2]))
    out = tmp_path / "B.pos"
    subprocess.run([rnx2rtkp, "-k", str(conf), "-o", str(out), str(tmp_path / "B.obs"),
                    str(tmp_path / "A.obs"), str(tmp_path / "nav.rnx")],
                   check=True, capture_output=True, timeout=120)
    t, xyz, q = read_pos(out)
    assert len(t) == sc.n_epochs
    after = (t - t[0]) >= 60.0
    fixed = (q == 1) & after
    fix_rate = fixed.sum() / after.sum()
    enu = ecef_to_enu(xyz - rover, rover)
    horiz = np.hypot(enu[:, 0], enu[:, 1])[fixed]
    vert = np.abs(enu[:, 2])[fixed]
    within = np.mean((horiz < 0.01) & (vert < 0.02))
    print(f"{label}: fixed {fix_rate:.1%} after 60 s; within 1 cm H / 2 cm V: {within:.1%}; "
          f"H rms {np.sqrt(np.mean(horiz ** 2)) * 1e3:.1f} mm, V rms {np.sqrt(np.mean(vert ** 2)) * 1e3:.1f} mm")
    assert fix_rate >= 0.95
    assert within >= 0.95


@pytest.mark.rtklib
def test_rnx2rtkp_fixes_baseline_10km(tmp_path):
    sc = load_scenario("baseline-10km").model_copy(update=dict(duration_s=DURATION_S))
    _judge_baseline(tmp_path, sc)


@pytest.mark.rtklib
@pytest.mark.shared_data
def test_rnx2rtkp_fixes_baseline_10km_on_a_real_broadcast_file(shared_data, tmp_path):
    """The same with the real 2023-07-11 GPS/Galileo/BeiDou broadcast ephemerides (`--nav`)."""
    from stations.cli import nav_ephemerides_for

    sc = load_scenario("baseline-10km").model_copy(update=dict(duration_s=DURATION_S))
    sc, ephs = nav_ephemerides_for(sc, shared_data / "nav" / "brdm-2023-07-11.nav")
    _judge_baseline(tmp_path, sc, ephs, "baseline-10km, real nav")


@pytest.mark.rtklib
def test_rnx2rtkp_follows_the_moving_train(tmp_path):
    """A 160 km/h train against station STA2 (8-16 km away): RTKLIB's kinematic solution, epoch by
    epoch, lies on our truth (ionosphere and residual wet delay off, so only the motion is judged)."""
    rnx2rtkp = require_tool("rnx2rtkp")
    sc = load_scenario("demo")
    e = sc.errors
    e = e.model_copy(update=dict(ionosphere=e.ionosphere.model_copy(update={"level": "off"}),
                                 troposphere=e.troposphere.model_copy(update={"wet_residual_m": 0.0}),
                                 cycle_slips_per_hour=0.0))
    record(sc.model_copy(update=dict(duration_s=120.0, errors=e)), tmp_path, rtcm=False)
    base = _truth(tmp_path / "truth.csv", "STA2")
    conf = tmp_path / "rtk.conf"
    conf.write_text(CONFIG.format(x=base[0], y=base[1], z=base[2]))
    out = tmp_path / "G101.pos"
    subprocess.run([rnx2rtkp, "-k", str(conf), "-o", str(out), str(tmp_path / "G101.obs"),
                    str(tmp_path / "STA2.obs"), str(tmp_path / "nav.rnx")],
                   check=True, capture_output=True, timeout=120)
    t, xyz, q = read_pos(out)
    truth = {}
    for row in csv.DictReader(open(tmp_path / "truth.csv")):
        if row["receiver"] == "G101":
            h, m, s = row["gpst_calendar"][11:].split(":")
            truth[int(h) * 3600 + int(m) * 60 + round(float(s))] = [float(row[k]) for k in ("x_m", "y_m", "z_m")]
    ref = np.array([truth[int(round(v))] for v in t])
    moved = np.linalg.norm(ref[-1] - ref[0])
    assert moved > 5000.0  # it really is moving: 160 km/h for two minutes
    fixed = q == 1
    assert fixed.mean() >= 0.9
    err = np.linalg.norm(xyz[fixed] - ref[fixed], axis=1)
    print(f"train G101: fixed {fixed.mean():.1%}, 3-D error RMS {np.sqrt(np.mean(err ** 2)) * 1e3:.1f} mm")
    assert np.percentile(err, 95) < 0.02


@pytest.mark.rtklib
def test_rnx2rtkp_refixes_after_the_tunnel(tmp_path):
    """G101 enters the 2 km tunnel (km 100-102) 45 s in: RTKLIB loses the train, then fixes the new
    ambiguity arcs after the exit and lands on the truth again (no stale ambiguities carried over)."""
    rnx2rtkp = require_tool("rnx2rtkp")
    sc = load_scenario("demo")
    e = sc.errors
    e = e.model_copy(update=dict(ionosphere=e.ionosphere.model_copy(update={"level": "off"}),
                                 troposphere=e.troposphere.model_copy(update={"wet_residual_m": 0.0}),
                                 cycle_slips_per_hour=0.0))
    train = sc.trains[0].model_copy(update=dict(start_km=98.0))
    sc = sc.model_copy(update=dict(duration_s=200.0, errors=e, trains=[train],
                                   stations=[s for s in sc.stations if s.id == "STA2"]))
    record(sc, tmp_path, rtcm=False)
    base = _truth(tmp_path / "truth.csv", "STA2")
    conf = tmp_path / "rtk.conf"
    conf.write_text(CONFIG.format(x=base[0], y=base[1], z=base[2]))
    out = tmp_path / "G101.pos"
    subprocess.run([rnx2rtkp, "-k", str(conf), "-o", str(out), str(tmp_path / "G101.obs"),
                    str(tmp_path / "STA2.obs"), str(tmp_path / "nav.rnx")],
                   check=True, capture_output=True, timeout=120)
    t, xyz, q = read_pos(out)
    rows = [r for r in csv.DictReader(open(tmp_path / "truth.csv")) if r["receiver"] == "G101"]
    km = np.array([float(r["km"]) for r in rows])
    t_truth = np.array([float(r["gpst_s"]) for r in rows]) % 86400.0
    ecef = np.array([[float(r[k]) for k in ("x_m", "y_m", "z_m")] for r in rows])
    idx = np.searchsorted(t_truth, t)
    in_tunnel = (km[idx] > 100.0) & (km[idx] < 102.0)
    assert not in_tunnel.any()  # no solution while the sky is hidden
    before = km[idx] < 100.0
    after = km[idx] > 102.0
    assert np.mean(q[before] == 1) > 0.8 and after.sum() > 60
    exit_t = t[after][0]
    refixed = after & (q == 1)
    assert refixed.any()
    time_to_fix = t[refixed][0] - exit_t
    err = np.linalg.norm(xyz[refixed] - ecef[idx[refixed]], axis=1)
    print(f"tunnel: re-fixed {time_to_fix:.0f} s after the first epoch out, "
          f"{np.mean(q[after] == 1):.0%} fixed after, 3-D error p95 {np.percentile(err, 95) * 1e3:.1f} mm")
    assert time_to_fix < 60.0
    assert np.percentile(err, 95) < 0.03


@pytest.mark.rtklib
@pytest.mark.shared_data
def test_rnx2rtkp_single_point_exact_with_real_group_delays(shared_data, tmp_path):
    """Errors off, real 2023 broadcast file (non-zero TGDs): RTKLIB's single-point solution, which
    applies the broadcast clocks and group delays, lands on the truth to millimetres per system."""
    rnx2rtkp = require_tool("rnx2rtkp")
    from stations.cli import nav_ephemerides_for

    sc = load_scenario("baseline-10km")
    e = sc.errors
    e = e.model_copy(update=dict(ionosphere=e.ionosphere.model_copy(update={"level": "off"}),
                                 troposphere=e.troposphere.model_copy(update={"enabled": False}),
                                 orbit_clock=e.orbit_clock.model_copy(update={"enabled": False}),
                                 noise=e.noise.model_copy(update={"enabled": False}), receiver_clock=False))
    sc, ephs = nav_ephemerides_for(sc.model_copy(update=dict(duration_s=3.0, errors=e)),
                                   shared_data / "nav" / "brdm-2023-07-11.nav")
    assert any(abs(x.tgd) > 1e-9 for x in ephs if x.system == "G")
    record(sc, tmp_path, nav_ephemerides=ephs, rtcm=False)
    truth = _truth(tmp_path / "truth.csv", "A")
    for navsys in (1, 32):  # GPS L1 C/A with TGD; BeiDou B1I with TGD1 (incl. GEO)
        conf = tmp_path / f"spp{navsys}.conf"
        conf.write_text(f"pos1-posmode =single\npos1-navsys ={navsys}\npos1-ionoopt =off\n"
                        "pos1-tropopt =off\npos1-elmask =10\nout-solformat =xyz\n")
        out = tmp_path / f"spp{navsys}.pos"
        subprocess.run([rnx2rtkp, "-k", str(conf), "-o", str(out), str(tmp_path / "A.obs"),
                        str(tmp_path / "nav.rnx")], check=True, capture_output=True, timeout=60)
        _, xyz, q = read_pos(out)
        assert len(xyz) == 3
        assert np.max(np.linalg.norm(xyz - truth, axis=1)) < 0.005, navsys
