"""A nominal GPS + Galileo + BeiDou constellation owned by the project, as broadcast-ephemeris sets.

The project cannot ship a real broadcast file, so it builds its own from public orbital slots:

* GPS: six planes (A-F) 60 deg apart in right ascension, 55 deg inclination, semi-major axis
  26,559.7 km (IS-GPS-200 / GPS SPS Performance Standard 2020, 3.1: "six orbital planes, 24 baseline
  slots", "expandable slots" in B, D, F: 27 satellites here).  Slot phases are a nominal layout with
  the baseline's uneven spacing, not the SPS PS table values.
* Galileo: Walker 24/3/1 at 29,600 km semi-major axis, 56 deg (Galileo OS SDD 2019, 2.1).
* BeiDou-3: MEO Walker 24/3/1 at 21,528 km altitude, 55 deg; three IGSO at 35,786 km altitude,
  55 deg, sharing one ground track centred on 118 E; GEO at the published longitudes 140, 80,
  110.5, 160 and 58.75 E (PRN C01-C05, BDS-SIS-ICD-B1I 3.0; served with the D2 GEO model).

Every satellite follows one Keplerian orbit (with the J2 nodal regression of its altitude and
inclination for MEO) and one clock line; each broadcast set at toe is that same orbit and clock
re-expressed at its toe and rounded to the broadcast resolution, so consecutive sets agree to
that resolution (centimetres, a fraction of a nanosecond).
Updates: GPS every 2 h, Galileo every 10 min, BeiDou every 1 h, as the systems do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.constants import (GM_BDS_M3_S2, GM_GAL_M3_S2, GM_GPS_M3_S2, OMEGA_E_BDS_RAD_S,
                                   OMEGA_E_GAL_RAD_S, OMEGA_E_GPS_RAD_S, WGS84_A_M)
from augnet.gnss.ephemeris import Ephemeris
from augnet.gnss.rtcm.ephemeris import quantise

J2 = 1.08262668e-3  # Earth's second zonal harmonic (EGM96), for nominal nodal regression

GPS_A_M = 26_559_700.0  # IS-GPS-200: nominal semi-major axis (half a sidereal day period)
GPS_INC_DEG = 55.0
GAL_A_M = 29_600_318.0  # Galileo OS SDD: 29,600 km (23,222 km altitude)
GAL_INC_DEG = 56.0
BDS_MEO_A_M = 21_528_000.0 + WGS84_A_M  # BDS ICD: MEO altitude 21,528 km
BDS_INC_DEG = 55.0
BDS_IGSO_INC_DEG = 55.0
BDS_IGSO_CROSSING_LON_DEG = 118.0
BDS_GEO_LON_DEG = {1: 140.0, 2: 80.0, 3: 110.5, 4: 160.0, 5: 58.75}
BDS_IGSO_PRNS = (38, 39, 40)
BDS_MEO_PRNS = tuple(range(19, 31)) + tuple(range(32, 38)) + tuple(range(41, 47))  # 24 MEO

# Broadcast update intervals [s]: GPS LNAV 2 h, Galileo I/NAV 10 min, BDS D1/D2 1 h.
TOE_INTERVAL_S = {"G": 7200.0, "E": 600.0, "C": 3600.0}
# Galileo I/NAV on E1-B and E5b-I, clock for E1,E5b (RINEX 3.04 Table A8): bits 0, 2, 9.
GAL_INAV_DATA_SOURCES = 517
NOMINAL_ECCENTRICITY_MAX = 0.008  # real MEO eccentricities are mostly below 0.01
URA_M = 2.0  # broadcast accuracy (GPS URA index 0-1 range, Galileo SISA 1-2 m)

# GPS nominal slots: argument of latitude [deg] at the reference time, per plane (A..F).
_GPS_SLOTS = {
    0: (11.7, 41.8, 161.8, 268.1),
    1: (80.9, 173.0, 204.3, 309.9, 111.9),
    2: (111.9, 11.8, 339.7, 241.6),
    3: (135.2, 167.4, 265.2, 35.2, 197.0),
    4: (197.0, 302.6, 66.6, 333.7),
    5: (238.9, 345.2, 105.2, 135.3, 0.0),
}


@dataclass(frozen=True)
class NominalOrbit:
    """One satellite's orbit and clock, the truth reference its broadcast sets are cut from."""

    sat: str
    a_m: float
    e: float
    inc_rad: float
    node_lon_ref_rad: float  # longitude of ascending node in ECEF at t_ref
    node_rate_rad_s: float  # d(node longitude)/dt in ECEF, -omega_e + nodal regression (not GEO)
    raan_rate_rad_s: float  # inertial nodal regression (the broadcast OMEGA DOT)
    arg_perigee_rad: float
    mean_anomaly_ref_rad: float
    t_ref_gpst: float
    af0_ref_s: float
    af1: float
    geo: bool = False

    @property
    def system(self) -> str:
        return self.sat[0]

    @property
    def prn(self) -> int:
        return int(self.sat[1:])


def _gm_omge(system: str) -> tuple[float, float]:
    return {"G": (GM_GPS_M3_S2, OMEGA_E_GPS_RAD_S), "E": (GM_GAL_M3_S2, OMEGA_E_GAL_RAD_S),
            "C": (GM_BDS_M3_S2, OMEGA_E_BDS_RAD_S)}[system]


def _nodal_regression(gm: float, a: float, inc: float) -> float:
    """J2 secular drift of the node [rad/s] (circular orbit)."""
    n = math.sqrt(gm / a**3)
    return -1.5 * n * J2 * (WGS84_A_M / a) ** 2 * math.cos(inc)


def nominal_orbits(systems, t_ref_gpst: float, seed: int) -> list[NominalOrbit]:
    """The nominal constellation for the given systems, at reference time t_ref (GPST seconds).

    The seed draws the small things real satellites differ in: eccentricity, perigee, clock offset
    and drift.  The slots themselves are fixed.
    """
    rng = np.random.default_rng([seed, 0xC0457])
    out: list[NominalOrbit] = []

    def add(sat, a, inc_deg, node_lon_deg, u_deg, geo=False, circular=False):
        system = sat[0]
        gm, omge = _gm_omge(system)
        inc = math.radians(inc_deg)
        # GEO: exactly circular.  The D2 model keeps the node fixed in a frame that turns with the
        # Earth from each toe, so an eccentric GEO could not be cut into consecutive sets that agree.
        e = 0.0 if geo else 0.0003 if circular else float(rng.uniform(0.0005, NOMINAL_ECCENTRICITY_MAX))
        w = float(rng.uniform(0, 2 * math.pi))
        regress = 0.0 if (geo or circular) else _nodal_regression(gm, a, inc)
        out.append(NominalOrbit(
            sat=sat, a_m=a, e=e, inc_rad=inc, node_lon_ref_rad=math.radians(node_lon_deg),
            node_rate_rad_s=(0.0 if geo else regress - omge), raan_rate_rad_s=regress,
            arg_perigee_rad=w, mean_anomaly_ref_rad=math.radians(u_deg) - w, t_ref_gpst=t_ref_gpst,
            # Satellite clocks: offsets within +-0.5 ms and drifts of 1e-12..1e-11 (rubidium /
            # hydrogen maser after steering), the ranges seen in real broadcast files.
            af0_ref_s=float(rng.uniform(-5e-4, 5e-4)), af1=float(rng.uniform(-1e-11, 1e-11)), geo=geo))

    if "G" in systems:
        prn = 1
        for plane, slots in _GPS_SLOTS.items():
            for u in slots:
                add(f"G{prn:02d}", GPS_A_M, GPS_INC_DEG, 17.0 + 60.0 * plane, u)
                prn += 1
    if "E" in systems:
        prn = 1
        for plane in range(3):  # Walker 24/3/1: phase offset 1 * 360 / 24 = 15 deg between planes
            for k in range(8):
                add(f"E{prn:02d}", GAL_A_M, GAL_INC_DEG, 45.0 + 120.0 * plane, 45.0 * k + 15.0 * plane)
                prn += 1
    if "C" in systems:
        for j, prn in enumerate(BDS_MEO_PRNS):
            plane, k = divmod(j, 8)
            add(f"C{prn:02d}", BDS_MEO_A_M, BDS_INC_DEG, 75.0 + 120.0 * plane, 45.0 * k + 15.0 * plane)
        gm, omge = _gm_omge("C")
        a_geo = (gm / omge**2) ** (1.0 / 3.0)  # geosynchronous: mean motion = Earth rotation rate
        for k, prn in enumerate(BDS_IGSO_PRNS):
            # Same ground track: node longitude = crossing longitude - phase (see module doc).
            u0 = 120.0 * k
            add(f"C{prn:02d}", a_geo, BDS_IGSO_INC_DEG, BDS_IGSO_CROSSING_LON_DEG - u0, u0, circular=True)
        for prn, lon in BDS_GEO_LON_DEG.items():
            # D2 GEO: orbit tilted +5 deg in the ICD's intermediate frame with its node on the -X
            # axis, so the -5 deg rotation about X brings it to the equator; the satellite then sits
            # at longitude u + 180 deg.
            add(f"C{prn:02d}", a_geo, 5.0, 180.0, lon - 180.0, geo=True, circular=True)
    return sorted(out, key=lambda o: ("GEC".index(o.sat[0]), o.prn))


def broadcast_set(orbit: NominalOrbit, toe_gpst: float, iode: int, quantised: bool = True) -> Ephemeris:
    """The broadcast ephemeris with toe = toc = toe_gpst of a nominal orbit (no fit error).

    `quantised=False` keeps full precision: the truth orbit, continuous from set to set.
    """
    system = orbit.system
    gm, omge = _gm_omge(system)
    dt = toe_gpst - orbit.t_ref_gpst
    n = math.sqrt(gm / orbit.a_m**3)
    week, toe = gtime.system_week_tow(system, toe_gpst)
    week, toe = int(week), float(toe)
    m0 = math.remainder(orbit.mean_anomaly_ref_rad + n * dt, 2 * math.pi)
    if orbit.geo:
        # D2: node = omega0 + omega_dot tk - omge toe stays fixed in the tilted frame and the
        # Earth's rotation enters as Rz(omge tk) from toe, so longitude(t) = u(t) + node - omge tk.
        # Keep the node at 180 deg at every toe; with n = omge the phase, hence the longitude,
        # stays put.
        omega0 = math.remainder(orbit.node_lon_ref_rad + omge * toe, 2 * math.pi)
        m0 = math.remainder(orbit.mean_anomaly_ref_rad + (n - omge) * dt, 2 * math.pi)
    else:
        node_lon = orbit.node_lon_ref_rad + orbit.node_rate_rad_s * dt  # ECEF longitude at toe
        omega0 = math.remainder(node_lon + omge * toe, 2 * math.pi)
    af0 = orbit.af0_ref_s + orbit.af1 * dt
    common = dict(system=system, prn=orbit.prn, week=week, toe=toe, toc=toe, af0=af0, af1=orbit.af1,
                  af2=0.0, iode=iode, crs=0.0, delta_n=0.0, m0=m0, cuc=0.0, e=orbit.e, cus=0.0,
                  sqrt_a=math.sqrt(orbit.a_m), cic=0.0, omega0=omega0, cis=0.0, i0=orbit.inc_rad,
                  crc=0.0, omega=math.remainder(orbit.arg_perigee_rad, 2 * math.pi),
                  omega_dot=orbit.raan_rate_rad_s, idot=0.0,
                  health=0, accuracy_m=URA_M, iodc=iode, transmission_time=toe)
    if system == "G":
        common.update(codes_on_l2=1, fit_interval_h=4.0)
    elif system == "E":
        common.update(data_sources=GAL_INAV_DATA_SOURCES)
    # On the broadcast resolution, like a real upload: what nav.rnx holds is exactly what a receiver
    # decodes from RTCM 1019/1042/1046.  Consecutive sets then differ by the quantisation (cm, 0.1 ns).
    eph = Ephemeris(**common)
    return quantise(eph) if quantised else eph


def issue_of_data(system: str, toe_gpst: float) -> int:
    """Issue of data for the set at toe: unique within its range for the sets a day holds.

    GPS IODE 8 bits (2-hourly: 84 sets a week), Galileo IODnav 10 bits (10-min: 1008 a week),
    BDS AODE 5 bits (hourly: 24 a day).
    """
    k = int(round(float(gtime.gpst_to_system(system, toe_gpst)) / TOE_INTERVAL_S[system]))
    return k % {"G": 256, "E": 1024, "C": 32}[system]


def toe_for(system: str, t_gpst) -> np.ndarray:
    """GPST of the toe of the set broadcast at time t: the latest toe at or before t.

    Toes are whole multiples of the update interval in the system's own time (BDT for BeiDou), so
    they fit the ICD's toe resolution (16 s GPS, 60 s Galileo, 8 s BDS).
    """
    step = TOE_INTERVAL_S[system]
    t_sys = gtime.gpst_to_system(system, t_gpst)
    return gtime.system_to_gpst(system, np.floor(t_sys / step) * step)


def broadcast_ephemerides(orbits: list[NominalOrbit], t0_gpst: float, t1_gpst: float,
                          quantised: bool = True) -> list[Ephemeris]:
    """Every broadcast set a receiver sees between t0 and t1 (GPST seconds), in time order.

    `quantised=False`: the same sets at full precision, i.e. the truth orbits and clocks.
    """
    out = []
    for orb in orbits:
        step = TOE_INTERVAL_S[orb.system]
        # from one set before t0: Galileo sets are used only after their toe (age of data > 0)
        toe = float(toe_for(orb.system, t0_gpst)) - step
        while toe <= t1_gpst:
            out.append(broadcast_set(orb, toe, issue_of_data(orb.system, toe), quantised))
            toe += step
    out.sort(key=lambda e: (e.toe_gpst, "GEC".index(e.system), e.prn))
    return out
