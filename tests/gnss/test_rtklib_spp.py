"""Our broadcast ephemeris against RTKLIB's: error-free pseudoranges -> rnx2rtkp single point.

We compute pseudoranges for a known receiver with our satellite positions and clocks (transit
time iterated, Earth rotation during transit, satellite clock with the relativistic term, the
signal's group delay), write them as RINEX 3.04 with our writer, and let RTKLIB 2.4.3 solve a
single-point position with ionosphere and troposphere corrections off and the same nav file.
If our orbits, clocks, time scales (BDT = GPST - 14 s), BDS GEO rotation and group delays agree
with RTKLIB's, its position lands on ours to millimetres; any disagreement of a few ns or metres
in one satellite shows up as centimetres to metres.

How RTKLIB 2.4.3 b34 treats the single-frequency code (src/pntpos.c prange()): GPS L1 minus TGD;
Galileo E1 minus BGD(E1,E5b) with its default I/NAV ephemeris choice (E1 minus BGD(E1,E5a) for
F/NAV); BDS B1I (C2I) minus TGD1.  One quirk: its gettgd() takes the group delay of the first
ephemeris of the satellite in its table (sorted by transmission time), not of the ephemeris it
selected for the orbit; Galileo BGDs change during the day in the 2023 file, so the test applies
the group delay of the earliest-transmitted set, as RTKLIB does, to compare like with like.
Selection: RTKLIB picks the nearest toe without looking at health, then rejects an unhealthy
satellite; so do we here (allow_unhealthy=True, then drop unhealthy).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from augnet.gnss import time as gtime
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, group_delay_s, transit
from augnet.gnss.geometry import azimuth_elevation, geodetic_deg_to_ecef
from augnet.gnss.rinex.nav import read_nav
from augnet.gnss.rinex.obs import ObsHeader, empty_obs, write_obs
from tests.conftest import require_tool

pytestmark = [pytest.mark.rtklib, pytest.mark.shared_data]

NAVSYS_BITS = {"G": 1, "E": 8, "C": 32}  # RTKLIB pos1-navsys bits
SIGNAL = {"G": "1C", "E": "1C", "C": "2I"}  # the code RTKLIB's single-frequency SPP uses
ELEVATION_MASK_DEG = 5.0
RECEIVER_CLOCK_S = 1.234e-4  # a receiver clock offset (37 km), to exercise the time tags
TOLERANCE_M = 0.05


def _rtklib_group_delay(nav: NavigationData, sat: str, code: str) -> float:
    """Group delay of the satellite's earliest-transmitted set (what RTKLIB's gettgd uses)."""
    tb = nav.table
    rows = np.flatnonzero(tb.sat == sat)
    ttr = tb.toe_gpst[rows] + gtime.time_of_week_difference(tb.transmission_time[rows], tb.toe[rows])
    first = rows[np.lexsort((tb.toe_gpst[rows], ttr))][0]
    return float(group_delay_s(tb.take([first]), code)[0])


def _simulate(nav: NavigationData, system: str, receiver_ecef, epochs_gpst, *, with_group_delay=True):
    """Error-free pseudoranges: (times as receiver time tags, sats, (E, S) pseudoranges, used)."""
    sats = [s for s in nav.satellites if s[0] == system]
    tr = transit(nav, sats, receiver_ecef, epochs_gpst)
    _, el = azimuth_elevation(receiver_ecef, tr.sat_position_m)
    rows = nav.table.take(np.where(tr.valid, tr.ephemeris_index, 0))
    healthy = tr.valid & (rows.health == 0)
    visible = healthy & (np.degrees(np.nan_to_num(el, nan=-90.0)) > ELEVATION_MASK_DEG)
    code = SIGNAL[system]
    gd = np.array([_rtklib_group_delay(nav, s, code) for s in sats]) if with_group_delay else np.zeros(len(sats))
    pr = tr.range_m + SPEED_OF_LIGHT_M_S * (RECEIVER_CLOCK_S - tr.sat_clock_bias_s + gd[None, :])
    pr = np.where(visible, pr, np.nan)
    return np.asarray(epochs_gpst) + RECEIVER_CLOCK_S, np.array(sats), pr, visible


def _write_obs(path: Path, system: str, receiver_ecef, times, sats, pr):
    code = SIGNAL[system]
    header = ObsHeader(
        marker_name="AUGNET-SIM",
        receiver_type="augnet error-free",
        antenna_type="NONE",
        approx_position_m=tuple(float(v) for v in receiver_ecef),
        obs_types={system: [f"C{code}", f"S{code}"]},
        signal_strength_unit="DBHZ",
        interval_s=None,
        time_system="GPS",
    )
    data = empty_obs(header, times, sats)
    data.obs[f"C{code}"][:] = pr
    data.obs[f"S{code}"][:] = np.where(np.isnan(pr), np.nan, 45.0)
    write_obs(path, data)


def _run_rnx2rtkp(tmp_path: Path, system: str, obs: Path, nav_file: Path):
    conf = tmp_path / "spp.conf"
    conf.write_text(
        "\n".join(
            [
                "pos1-posmode=single",
                "pos1-frequency=l1",
                f"pos1-elmask={ELEVATION_MASK_DEG - 2.0}",
                "pos1-ionoopt=off",
                "pos1-tropopt=off",
                "pos1-sateph=brdc",
                f"pos1-navsys={NAVSYS_BITS[system]}",
                "out-solformat=xyz",
                "out-outhead=on",
                "out-outstat=residual",
                "",
            ]
        )
    )
    out = tmp_path / f"{system}.pos"
    proc = subprocess.run(
        [require_tool("rnx2rtkp"), "-k", str(conf), "-o", str(out), str(obs), str(nav_file)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    sols = []
    for line in out.read_text().splitlines():
        if not line.strip() or line.startswith("%"):
            continue
        f = line.split()
        sols.append((f[0] + " " + f[1], np.array([float(f[2]), float(f[3]), float(f[4])]), int(f[5]), int(f[6])))
    stat = Path(str(out) + ".stat")
    used = set()
    if stat.exists():
        for line in stat.read_text().splitlines():
            # In single mode RTKLIB writes a $SAT residual line only for satellites its
            # solution used (ssat.vs); the vsat column is an RTK-mode flag.
            if line.startswith("$SAT"):
                p = line.split(",")
                used.add(p[3])
                assert abs(float(p[7])) < TOLERANCE_M, f"residual of {p[3]} at {p[2]}: {p[7]} m"
    return sols, used


def _check(tmp_path, nav_path, system, receiver_ecef, epochs, need_geo=False, sabotage=None):
    nav = NavigationData(read_nav(nav_path).ephemerides, galileo_source="inav", allow_unhealthy=True)
    with_group_delay = True
    if sabotage == "no-geo-rotation":
        nav.table.is_geo[:] = False  # compute BDS GEOs like IGSO/MEO satellites
    elif sabotage == "no-group-delay":
        with_group_delay = False
    times, sats, pr, visible = _simulate(nav, system, receiver_ecef, epochs, with_group_delay=with_group_delay)
    assert visible.sum(axis=1).min() >= 5, f"too few {system} satellites: {visible.sum(axis=1)}"
    obs = tmp_path / f"sim-{system}.obs"
    _write_obs(obs, system, receiver_ecef, times, sats, pr)
    sols, used = _run_rnx2rtkp(tmp_path, system, obs, nav_path)
    assert len(sols) == len(epochs), f"rnx2rtkp solved {len(sols)} of {len(epochs)} epochs"
    errors = np.array([np.linalg.norm(xyz - receiver_ecef) for _, xyz, _, _ in sols])
    for (when, _, q, ns), err, n_vis in zip(sols, errors, visible.sum(axis=1)):
        assert q == 5, f"{when}: solution quality {q}, expected 5 (single)"
        assert ns == n_vis, f"{when}: RTKLIB used {ns} satellites, we simulated {n_vis}"
    assert errors.max() < TOLERANCE_M, f"{system}: RTKLIB position off by {errors.round(4)} m"
    if need_geo:
        from augnet.gnss.constants import BDS_GEO_PRNS

        geos = {s for s in used if s.startswith("C") and int(s[1:]) in BDS_GEO_PRNS}
        assert geos, f"no BDS GEO used by RTKLIB: used {sorted(used)}"
    return errors, used


# A point near Tokyo: GPS, Galileo and BDS MEO/IGSO are all in view.
TOKYO = geodetic_deg_to_ecef(35.6812, 139.7671, 40.0)
# 2023-07-11, spread over the day; never on a Galileo toe (10-minute grid, where "toe before t"
# flips with the receiver clock's microseconds) nor midway between two GPS toes (a tie).
EPOCHS_2023 = gtime.from_calendar(2023, 7, 11, 0, 0, 0) + np.array([0.52, 3.27, 7.61, 11.13, 15.92, 20.41]) * 3600.0


@pytest.mark.parametrize("system", ["G", "E", "C"])
def test_rnx2rtkp_single_point_matches_our_orbits_and_clocks(tmp_path, shared_data, system):
    nav_path = shared_data / "nav" / "brdm-2023-07-11.nav"
    errors, _ = _check(tmp_path, nav_path, system, TOKYO, EPOCHS_2023)
    print(f"{system}: max 3-D error {errors.max() * 1000:.2f} mm over {len(errors)} epochs")


def test_rnx2rtkp_single_point_bds_with_geo(tmp_path, shared_data):
    """The 2023 file holds no BDS GEO ephemeris; the 2024 static data's nav file does (C01-C05,
    C59-C62), so BDS-alone with GEOs is checked there, at that receiver's own site."""
    nav_path = shared_data / "rinex" / "static-1m-2024" / "base.nav"
    lat, lon, h = (float(v) for v in (shared_data / "rinex" / "static-1m-2024" / "base_position.txt").read_text().split()[:3])
    site = geodetic_deg_to_ecef(lat, lon, h)
    epochs = gtime.from_calendar(2024, 6, 24, 8, 20, 0) + np.arange(0.0, 300.0, 60.0)
    errors, used = _check(tmp_path, nav_path, "C", site, epochs, need_geo=True)
    print(f"C with GEO: max 3-D error {errors.max() * 1000:.2f} mm; used {sorted(used)}")


@pytest.mark.parametrize("sabotage", ["no-group-delay", "no-geo-rotation"])
def test_the_comparison_detects_a_wrong_model(tmp_path, shared_data, sabotage):
    """Negative control: leave out the BDS TGD1 or the GEO rotation and RTKLIB disagrees."""
    nav_path = shared_data / "rinex" / "static-1m-2024" / "base.nav"
    site = geodetic_deg_to_ecef(35.134707705, 136.977577939, 104.853)
    epochs = gtime.from_calendar(2024, 6, 24, 8, 20, 0) + np.arange(0.0, 300.0, 100.0)
    with pytest.raises(AssertionError):
        _check(tmp_path, nav_path, "C", site, epochs, need_geo=True, sabotage=sabotage)
