"""Broadcast ephemeris -> satellite position, velocity, clock; ephemeris selection; signal transit.

Covers the Keplerian broadcast messages: GPS LNAV (and QZSS, same layout), Galileo I/NAV and F/NAV,
BeiDou D1 (MEO/IGSO) and D2 (GEO).  References:
  IS-GPS-200N 20.3.3.4.3 (Table 20-IV) user algorithm, 20.3.3.3.3 clock and relativity, TGD;
  Galileo OS SIS ICD 2.0 5.1.1 (orbit), 5.1.4 (clock), 5.1.5 (BGD);
  BDS-SIS-ICD-B1I 3.0 5.2.4.12 (orbit incl. GEO), 5.2.4.10 (clock), 5.2.4.11 (TGD).

`Ephemeris` keeps the broadcast parameters with their RINEX 3 / ICD names and units (radians, not
semicircles; seconds; metres), so RINEX nav and RTCM 1019/1042/1045/1046 map onto it field by field.
Times in it are what the message carries: `week`, `toe` and `toc` in the satellite system's own
time scale and week numbering (GPS week for G/J, Galileo week for E, BDS week for C; full week
numbers, no roll-over).  Everything computed from it uses augnet's GPST seconds (see `time.py`).

Mapping to RTCM 3 (RTCM 10403.3 3.5.x): angles there are semicircles (multiply by pi), weeks are
truncated (1019: GPS week mod 1024; 1045/1046: GST week mod 4096; 1042: BDT week mod 8192) and
must be resolved to the full week near the current time; BDS toe/toc are BDT seconds of week as
here.  1046 is I/NAV (data_sources 517), 1045 F/NAV (258): the clock pair and the BGD that goes
with it follow from that.

Vectorised: `EphemerisTable` is a struct of arrays over many ephemerides; `satellite_state`
evaluates all of them at once (any broadcastable time array), the Kepler equation included.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Iterable, NamedTuple, Sequence

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.constants import (
    BDS_GEO_PRNS,
    GM_BDS_M3_S2,
    GM_GAL_M3_S2,
    GM_GPS_M3_S2,
    OMEGA_E_BDS_RAD_S,
    OMEGA_E_GAL_RAD_S,
    OMEGA_E_GPS_RAD_S,
    SPEED_OF_LIGHT_M_S,
)
from augnet.gnss.signals import FREQ_B1I_HZ, FREQ_B3I_HZ, FREQ_E5B_HZ, FREQ_L1_HZ, FREQ_L2_HZ, FREQ_L5_HZ

KEPLER_SYSTEMS = ("G", "E", "C", "J")

# Kepler's equation: Newton iterations until |dE| below this [rad] (1e-13 rad ~ 3 um along track).
KEPLER_TOLERANCE_RAD = 1e-13
KEPLER_MAX_ITERATIONS = 30

# BDS GEO: the orbit is computed in a frame inclined by -5 degrees about X (BDS-SIS-ICD-B1I 5.2.4.12).
BDS_GEO_TILT_RAD = math.radians(-5.0)

# How far from toe an ephemeris may be used [s].  GPS: the 4-hour curve fit centred on toe
# (IS-GPS-200 20.3.4.4, fit interval flag 0), so +-2 h; a longer broadcast fit interval widens it.
# Galileo: a batch is valid 4 h after toe (OS SIS ICD 5.1.9: nominal validity), used only after toe
# (age of data > 0).  BeiDou: updated hourly, RTKLIB accepts +-6 h; we keep RTKLIB 2.4.3's limits
# (MAXDTOE*) so our choice and RTKLIB's agree.
MAX_TOE_DISTANCE_S = {"G": 7200.0, "J": 7200.0, "E": 14400.0, "C": 21600.0}

# Galileo "data sources" bits (RINEX 3.04 Table A8): which message and which clock pair.
GAL_SOURCE_INAV_E1B = 1 << 0
GAL_SOURCE_FNAV_E5A = 1 << 1
GAL_SOURCE_INAV_E5B = 1 << 2
GAL_CLOCK_E5A_E1 = 1 << 8  # af0..af2 and toc refer to the E1,E5a pair (F/NAV)
GAL_CLOCK_E5B_E1 = 1 << 9  # af0..af2 and toc refer to the E1,E5b pair (I/NAV)


class EphemerisError(ValueError):
    """An ephemeris that cannot be used (unknown system, non-physical orbit)."""


@dataclass(frozen=True, slots=True)
class Ephemeris:
    """One broadcast ephemeris and clock set (GPS LNAV, Galileo I/NAV or F/NAV, BDS D1/D2, QZSS).

    Units: seconds, metres, radians (RINEX converts ICD semicircles to radians; so do we).
    Field names follow RINEX 3 navigation records; per-system meanings noted.
    """

    system: str  # 'G', 'E', 'C' or 'J'
    prn: int
    week: int  # week of toe in the system's own numbering (GPS / GST / BDT week), full number
    toe: float  # time of ephemeris [s of week, system time]
    toc: float  # time of clock [s of week, system time]
    af0: float  # clock bias [s]
    af1: float  # clock drift [s/s]
    af2: float  # clock drift rate [s/s^2]
    iode: int  # GPS IODE, Galileo IODnav, BDS AODE
    crs: float  # [m]
    delta_n: float  # mean motion difference [rad/s]
    m0: float  # mean anomaly at toe [rad]
    cuc: float  # [rad]
    e: float  # eccentricity
    cus: float  # [rad]
    sqrt_a: float  # [m^0.5]
    cic: float  # [rad]
    omega0: float  # longitude of ascending node at weekly epoch [rad]
    cis: float  # [rad]
    i0: float  # inclination at toe [rad]
    crc: float  # [m]
    omega: float  # argument of perigee [rad]
    omega_dot: float  # rate of right ascension [rad/s]
    idot: float  # rate of inclination [rad/s]
    health: int = 0  # GPS SV health (6 bits), Galileo health/DVS bits, BDS SatH1; 0 = healthy
    accuracy_m: float = 0.0  # GPS URA, Galileo SISA, BDS URA [m]
    iodc: int = 0  # GPS IODC, BDS AODC; Galileo: unused
    tgd: float = 0.0  # GPS/QZSS TGD [s]
    tgd1: float = 0.0  # BDS TGD1, B1I relative to B3I [s]
    tgd2: float = 0.0  # BDS TGD2, B2I relative to B3I [s]
    bgd_e5a_e1: float = 0.0  # Galileo BGD(E1,E5a) [s]
    bgd_e5b_e1: float = 0.0  # Galileo BGD(E1,E5b) [s]
    data_sources: int = 0  # Galileo data sources bits (GAL_SOURCE_* | GAL_CLOCK_*)
    codes_on_l2: int = 0  # GPS
    l2p_data_flag: int = 0  # GPS
    fit_interval_h: float = 0.0  # GPS fit interval [h] (0 = 4 h curve fit); QZSS flag
    transmission_time: float = 0.0  # [s of week, system time] when the message was received

    @property
    def sat(self) -> str:
        """RINEX satellite id, e.g. 'G05'."""
        return f"{self.system}{self.prn:02d}"

    @property
    def toe_gpst(self) -> float:
        return float(gtime.gpst_from_system_week_tow(self.system, self.week, self.toe))

    @property
    def toc_gpst(self) -> float:
        """toc as GPST seconds, in the week that puts it nearest toe."""
        return float(gtime.gpst_from_system_week_tow(self.system, self.week, gtime.resolve_tow(self.toc, self.toe)))

    @property
    def is_bds_geo(self) -> bool:
        return self.system == "C" and self.prn in BDS_GEO_PRNS

    def replace(self, **changes) -> "Ephemeris":
        return dataclasses.replace(self, **changes)


NUMERIC_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(Ephemeris) if f.name not in ("system",))


def _system_constants(system: np.ndarray):
    """(GM, Earth rotation rate, relativistic F) per row, by system letter (ICD values)."""
    gm = np.where(system == "E", GM_GAL_M3_S2, np.where(system == "C", GM_BDS_M3_S2, GM_GPS_M3_S2))
    omge = np.where(system == "E", OMEGA_E_GAL_RAD_S, np.where(system == "C", OMEGA_E_BDS_RAD_S, OMEGA_E_GPS_RAD_S))
    rel_f = -2.0 * np.sqrt(gm) / SPEED_OF_LIGHT_M_S**2
    return gm, omge, rel_f


@dataclass(frozen=True)
class EphemerisTable:
    """Struct of arrays over n ephemerides: one array per `Ephemeris` field, plus derived times.

    `toe_gpst` and `toc_gpst` are absolute GPST seconds; `sat` holds RINEX ids ('G05').
    """

    system: np.ndarray  # (n,) '<U1'
    sat: np.ndarray  # (n,) '<U3'
    columns: dict[str, np.ndarray]
    toe_gpst: np.ndarray
    toc_gpst: np.ndarray
    is_geo: np.ndarray
    records: tuple[Ephemeris, ...] = field(repr=False)

    @classmethod
    def from_list(cls, ephemerides: Iterable[Ephemeris]) -> "EphemerisTable":
        recs = tuple(ephemerides)
        for r in recs:
            if r.system not in KEPLER_SYSTEMS:
                raise EphemerisError(f"{r.sat}: no Keplerian broadcast model for system {r.system!r}")
        system = np.array([r.system for r in recs], dtype="<U1")
        cols = {name: np.array([getattr(r, name) for r in recs], dtype=float) for name in NUMERIC_FIELDS}
        week = cols["week"]
        toe_gpst = np.array(
            [gtime.gpst_from_system_week_tow(s, w, t) for s, w, t in zip(system, week, cols["toe"])], dtype=float
        ).reshape(-1)
        toc_sow = gtime.resolve_tow(cols["toc"], cols["toe"])
        toc_gpst = np.array(
            [gtime.gpst_from_system_week_tow(s, w, t) for s, w, t in zip(system, week, toc_sow)], dtype=float
        ).reshape(-1)
        prn = cols["prn"].astype(int)
        is_geo = np.array([s == "C" and p in BDS_GEO_PRNS for s, p in zip(system, prn)], dtype=bool)
        sat = np.array([f"{s}{p:02d}" for s, p in zip(system, prn)], dtype="<U3")
        return cls(system, sat, cols, toe_gpst, toc_gpst, is_geo, recs)

    def __len__(self) -> int:
        return len(self.records)

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self.__dict__["columns"][name]
        except KeyError:
            raise AttributeError(name) from None

    def take(self, index) -> "EphemerisTable":
        """Rows at `index` (any integer array; the result's arrays take its shape)."""
        idx = np.asarray(index, dtype=int)
        return EphemerisTable(
            self.system[idx],
            self.sat[idx],
            {k: v[idx] for k, v in self.columns.items()},
            self.toe_gpst[idx],
            self.toc_gpst[idx],
            self.is_geo[idx],
            self.records,
        )


class SatelliteState(NamedTuple):
    """Satellite states at given GPST times; arrays broadcast to the shape of (table rows, times)."""

    position_m: np.ndarray  # (..., 3) ECEF at the evaluation time (broadcast system's frame)
    velocity_m_s: np.ndarray  # (..., 3) ECEF velocity (rotating frame)
    clock_bias_s: np.ndarray  # (...) af-polynomial + relativistic term (no TGD/BGD)
    clock_drift_s_s: np.ndarray  # (...) its time derivative
    relativistic_s: np.ndarray  # (...) the relativistic term alone (already in clock_bias_s)


def solve_kepler(mean_anomaly, eccentricity, groups=None):
    """Eccentric anomaly E with E - e sin E = M, by Newton's method on whole arrays.

    `groups` (flat arrays only: a non-negative int per element) iterates each group as if solved alone: a group
    stops once all its steps are within tolerance, so many receivers solved in one call give the same bits as
    one call each."""
    m = np.asarray(mean_anomaly, dtype=float)
    e = np.asarray(eccentricity, dtype=float)
    ecc = np.array(m, copy=True)
    live = None if groups is None or not m.size else np.ones(m.shape, dtype=bool)
    for _ in range(KEPLER_MAX_ITERATIONS):
        step = (ecc - e * np.sin(ecc) - m) / (1.0 - e * np.cos(ecc))
        converged = np.abs(step) <= KEPLER_TOLERANCE_RAD
        if live is None:
            ecc = ecc - step
            if np.all(converged):
                break
            continue
        ecc = np.where(live, ecc - step, ecc)
        open_groups = np.bincount(groups, weights=live & ~converged, minlength=int(groups.max()) + 1) > 0
        live &= open_groups[groups]
        if not live.any():
            break
    return ecc


def satellite_state(table: EphemerisTable, t_gpst, offset_s=0.0, groups=None) -> SatelliteState:
    """Evaluate every row of `table` at GPST time(s) `t_gpst` + `offset_s` (shapes broadcast).

    `offset_s` keeps small time differences (a signal transit time, a finite-difference step) at
    full precision: it is added after subtracting toe/toc, where float64 resolves picoseconds.

    Position and velocity are analytic (derivatives of the ICD algorithm), the clock is the
    af-polynomial about toc plus the relativistic term F e sqrt(A) sin E; TGD/BGD are not included
    (add `group_delay_s` for the signal used).  BDS GEO rows get the D2 -5 degree frame rotation.
    `groups`: as `solve_kepler`'s (flat rows, several receivers' satellites in one call).
    """
    t = np.asarray(t_gpst, dtype=float)
    c = table.columns
    gm, omge, rel_f = _system_constants(table.system)
    a = c["sqrt_a"] ** 2
    if np.any(a <= 0):
        raise EphemerisError("ephemeris with a non-positive semi-major axis")
    n = np.sqrt(gm / a**3) + c["delta_n"]
    off = np.asarray(offset_s, dtype=float)
    tk = (t - table.toe_gpst) + off
    e = c["e"]
    m = c["m0"] + n * tk
    ecc = solve_kepler(m, e, groups)
    sin_e, cos_e = np.sin(ecc), np.cos(ecc)
    one_m_ecos = 1.0 - e * cos_e
    e_dot = n / one_m_ecos
    sq1me2 = np.sqrt(1.0 - e * e)
    nu = np.arctan2(sq1me2 * sin_e, cos_e - e)
    nu_dot = e_dot * sq1me2 / one_m_ecos
    phi = nu + c["omega"]
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    u = phi + c["cus"] * s2 + c["cuc"] * c2
    r = a * one_m_ecos + c["crs"] * s2 + c["crc"] * c2
    inc = c["i0"] + c["idot"] * tk + c["cis"] * s2 + c["cic"] * c2
    u_dot = nu_dot * (1.0 + 2.0 * (c["cus"] * c2 - c["cuc"] * s2))
    r_dot = a * e * sin_e * e_dot + 2.0 * nu_dot * (c["crs"] * c2 - c["crc"] * s2)
    i_dot = c["idot"] + 2.0 * nu_dot * (c["cis"] * c2 - c["cic"] * s2)

    xp, yp = r * np.cos(u), r * np.sin(u)
    xp_dot = r_dot * np.cos(u) - yp * u_dot
    yp_dot = r_dot * np.sin(u) + xp * u_dot

    geo = table.is_geo
    # Node longitude: MEO/IGSO are referred to the rotating Earth frame directly; BDS GEO is
    # computed in an inertial-like frame and rotated afterwards (no -omge*tk here).
    node_rate = np.where(geo, c["omega_dot"], c["omega_dot"] - omge)
    node = c["omega0"] + node_rate * tk - omge * c["toe"]
    sin_o, cos_o = np.sin(node), np.cos(node)
    sin_i, cos_i = np.sin(inc), np.cos(inc)
    x = xp * cos_o - yp * cos_i * sin_o
    y = xp * sin_o + yp * cos_i * cos_o
    z = yp * sin_i
    x_dot = xp_dot * cos_o - yp_dot * cos_i * sin_o + yp * sin_i * sin_o * i_dot - y * node_rate
    y_dot = xp_dot * sin_o + yp_dot * cos_i * cos_o - yp * sin_i * cos_o * i_dot + x * node_rate
    z_dot = yp_dot * sin_i + yp * cos_i * i_dot

    if np.any(geo):
        # r_ecef = Rz(omge tk) Rx(-5 deg) r_geo; derivative adds the frame rotation term.
        cf, sf = math.cos(BDS_GEO_TILT_RAD), math.sin(BDS_GEO_TILT_RAD)
        q1 = y * cf + z * sf
        q2 = -y * sf + z * cf
        q1_dot = y_dot * cf + z_dot * sf
        q2_dot = -y_dot * sf + z_dot * cf
        ang = omge * tk
        sa, ca = np.sin(ang), np.cos(ang)
        gx = x * ca + q1 * sa
        gy = -x * sa + q1 * ca
        gx_dot = x_dot * ca + q1_dot * sa + omge * gy
        gy_dot = -x_dot * sa + q1_dot * ca - omge * gx
        x, y, z = np.where(geo, gx, x), np.where(geo, gy, y), np.where(geo, q2, z)
        x_dot, y_dot, z_dot = (
            np.where(geo, gx_dot, x_dot),
            np.where(geo, gy_dot, y_dot),
            np.where(geo, q2_dot, z_dot),
        )

    dt_clk = (t - table.toc_gpst) + off
    rel = rel_f * e * c["sqrt_a"] * sin_e
    rel_dot = rel_f * e * c["sqrt_a"] * cos_e * e_dot
    bias = c["af0"] + c["af1"] * dt_clk + c["af2"] * dt_clk**2 + rel
    drift = c["af1"] + 2.0 * c["af2"] * dt_clk + rel_dot
    pos = np.stack(np.broadcast_arrays(x, y, z), axis=-1)
    vel = np.stack(np.broadcast_arrays(x_dot, y_dot, z_dot), axis=-1)
    return SatelliteState(pos, vel, bias, drift, np.broadcast_to(rel, bias.shape))


# ---------------------------------------------------------------------------------------------
# group delays


def group_delay_s(table: EphemerisTable, rinex_code: str) -> np.ndarray:
    """Signal group delay [s] a single-frequency user adds to the broadcast clock bias.

    pseudorange(signal) = geometric range + c (dt_rx - clock_bias + group_delay).  Sign and scaling:
      GPS/QZSS LNAV: L1 P/C/A +TGD, L2 +(f1/f2)^2 TGD (IS-GPS-200 20.3.3.3.3.2); L5 needs CNAV ISCs.
      Galileo (OS SIS ICD 5.1.5): the clock refers to the E1/E5b ionosphere-free pair for I/NAV,
        E1/E5a for F/NAV; with BGD_clk the BGD of that pair, E1 +BGD_clk, E5a
        +(g_a - 1) BGD(E1,E5a) + BGD_clk, E5b +(g_b - 1) BGD(E1,E5b) + BGD_clk, g_x = (f1/fx)^2
        (E5a with an F/NAV clock reduces to the ICD's g_a BGD(E1,E5a); likewise E5b with I/NAV).
      BDS (clock refers to B3I): B1I +TGD1, B2I +TGD2, B3I 0 (BDS-SIS-ICD-B1I 5.2.4.10).
    Signals the broadcast set does not describe give NaN.
    `rinex_code` is the two-character RINEX code ('1C', '2I', ...), applied to every row's system.
    """
    c = table.columns
    band = rinex_code[0]
    sysl = table.system
    out = np.full(sysl.shape, np.nan)
    gps = (sysl == "G") | (sysl == "J")
    if band == "1":
        out = np.where(gps, c["tgd"], out)
    elif band == "2":
        out = np.where(gps, (FREQ_L1_HZ / FREQ_L2_HZ) ** 2 * c["tgd"], out)
        out = np.where(sysl == "C", c["tgd1"], out)
    elif band == "6":
        out = np.where(sysl == "C", 0.0, out)
    elif band == "7":
        out = np.where(sysl == "C", c["tgd2"], out)
    gal = sysl == "E"
    if gal.any():
        fnav = (c["data_sources"].astype(np.int64) & GAL_CLOCK_E5A_E1) != 0
        bgd_clk = np.where(fnav, c["bgd_e5a_e1"], c["bgd_e5b_e1"])
        if band == "1":
            out = np.where(gal, bgd_clk, out)
        elif band == "5":
            out = np.where(gal, ((FREQ_L1_HZ / FREQ_L5_HZ) ** 2 - 1.0) * c["bgd_e5a_e1"] + bgd_clk, out)
        elif band == "7":
            out = np.where(gal, ((FREQ_L1_HZ / FREQ_E5B_HZ) ** 2 - 1.0) * c["bgd_e5b_e1"] + bgd_clk, out)
    return out


# BDS B1I/B3I frequency ratio, for callers forming B1I-B3I combinations with TGD1.
GAMMA_BDS_B1I_B3I = (FREQ_B1I_HZ / FREQ_B3I_HZ) ** 2


# ---------------------------------------------------------------------------------------------
# selection


def _is_inav(data_sources: np.ndarray) -> np.ndarray:
    ds = data_sources.astype(np.int64)
    return ((ds & GAL_CLOCK_E5B_E1) != 0) | (((ds & (GAL_SOURCE_INAV_E1B | GAL_SOURCE_INAV_E5B)) != 0) & ((ds & GAL_CLOCK_E5A_E1) == 0))


def _is_fnav(data_sources: np.ndarray) -> np.ndarray:
    ds = data_sources.astype(np.int64)
    return ((ds & GAL_CLOCK_E5A_E1) != 0) | ((ds & GAL_SOURCE_FNAV_E5A) != 0)


class NavigationData:
    """Broadcast ephemerides of many satellites, with the rules to pick the set valid at a time.

    Selection (per satellite and time): same satellite; healthy (unless `allow_unhealthy`);
    |t - toe| within the system's limit (GPS: half the fit interval, at least 2 h; Galileo 4 h and
    only after toe, i.e. age of data > 0; BDS 6 h); Galileo of the preferred data source (I/NAV by
    default, as the E1/E5b dual-frequency clock; `galileo_source='fnav'` or 'any'; a set whose
    data_sources is 0 (unknown) is accepted either way); RTCM 1046 is I/NAV (set data_sources
    GAL_SOURCE_INAV_E1B | GAL_SOURCE_INAV_E5B | GAL_CLOCK_E5B_E1 = 517), 1045 F/NAV (258);
    then the set with toe nearest t, ties going to the later toe (the newer upload).
    """

    def __init__(self, ephemerides: Iterable[Ephemeris], *, galileo_source: str = "inav",
                 allow_unhealthy: bool = False):
        if galileo_source not in ("inav", "fnav", "any"):
            raise ValueError(f"galileo_source must be 'inav', 'fnav' or 'any', not {galileo_source!r}")
        recs = [r for r in ephemerides if r.system in KEPLER_SYSTEMS]
        self.table = EphemerisTable.from_list(recs)
        self.galileo_source = galileo_source
        self.allow_unhealthy = allow_unhealthy
        tb = self.table
        usable = np.ones(len(tb), dtype=bool)
        if not allow_unhealthy and len(tb):
            usable &= tb.health == 0
        if len(tb) and galileo_source != "any":
            wanted = _is_inav(tb.data_sources) if galileo_source == "inav" else _is_fnav(tb.data_sources)
            # data_sources 0 = not recorded (e.g. a converter that left it out): accept the set.
            usable &= (tb.system != "E") | wanted | (tb.data_sources == 0)
        max_dist = np.array([MAX_TOE_DISTANCE_S[s] for s in tb.system], dtype=float)
        if len(tb):
            gps_fit = (tb.system == "G") & (tb.fit_interval_h > 4.0)
            max_dist = np.where(gps_fit, tb.fit_interval_h * 3600.0 / 2.0, max_dist)
        self._max_dist = max_dist
        self._usable = usable
        self._by_sat: dict[str, np.ndarray] = {}
        for sat in np.unique(tb.sat):
            rows = np.flatnonzero((tb.sat == sat) & usable)
            # Latest toe first: argmin below returns the first of equal distances, the newer set.
            self._by_sat[str(sat)] = rows[np.argsort(-tb.toe_gpst[rows], kind="stable")]

    def pinned(self, sats: Sequence[str], t_gpst: float) -> "NavigationData":
        """The same data with each satellite held to the set selected at `t_gpst`, at any time: one model across an
        interval that an upload crosses (a change of set steps the computed range by decimetres)."""
        idx = self.select(sats, float(t_gpst))
        out = copy.copy(self)
        out._by_sat = {str(s): np.array([i]) for s, i in zip(sats, idx) if i >= 0}
        out._max_dist = np.full_like(self._max_dist, np.inf)
        return out

    def __len__(self) -> int:
        return len(self.table)

    @property
    def satellites(self) -> list[str]:
        return sorted(s for s, idx in self._by_sat.items() if len(idx))

    def select(self, sats: Sequence[str], t_gpst) -> np.ndarray:
        """Row index into `self.table` of the set to use for each (time, satellite); -1 if none.

        `t_gpst` of shape T (any), `sats` of length N: the result has shape T + (N,).
        """
        t = np.asarray(t_gpst, dtype=float)
        sats = [str(s) for s in sats]
        out = np.full(t.shape + (len(sats),), -1, dtype=int)
        tb = self.table
        for j, sat in enumerate(sats):
            cand = self._by_sat.get(sat)
            if cand is None or len(cand) == 0:
                continue
            dt = t[..., None] - tb.toe_gpst[cand]  # (T..., k)
            ok = np.abs(dt) <= self._max_dist[cand]
            ok &= (tb.system[cand] != "E") | (dt > 0.0)
            cost = np.where(ok, np.abs(dt), np.inf)  # nearest toe; ties -> later toe (order above)
            best = np.argmin(cost, axis=-1)
            found = np.take_along_axis(ok, best[..., None], axis=-1)[..., 0]
            out[..., j] = np.where(found, cand[best], -1)
        return out

    def select_each(self, sats: Sequence[str], t_gpst) -> np.ndarray:
        """`select` of element-wise pairs: row index of the set for satellite sats[i] at time t_gpst[i] (flat,
        same length), -1 if none; one pass per distinct satellite instead of one per pair."""
        t = np.asarray(t_gpst, dtype=float).reshape(-1)
        sats = np.asarray([str(s) for s in sats], dtype=object)
        out = np.full(t.shape, -1, dtype=int)
        tb = self.table
        for sat in dict.fromkeys(sats.tolist()):
            cand = self._by_sat.get(sat)
            if cand is None or len(cand) == 0:
                continue
            at = np.flatnonzero(sats == sat)
            dt = t[at, None] - tb.toe_gpst[cand]
            ok = np.abs(dt) <= self._max_dist[cand]
            ok &= (tb.system[cand] != "E") | (dt > 0.0)
            cost = np.where(ok, np.abs(dt), np.inf)  # as `select`: nearest toe, ties to the later toe
            best = np.argmin(cost, axis=-1)
            found = np.take_along_axis(ok, best[..., None], axis=-1)[..., 0]
            out[at] = np.where(found, cand[best], -1)
        return out

    def states(self, sats: Sequence[str], t_gpst) -> tuple[SatelliteState, np.ndarray]:
        """Satellite states for each (time, satellite) and the validity mask (an ephemeris found).

        Invalid entries are NaN.
        """
        idx = self.select(sats, t_gpst)
        valid = idx >= 0
        if not len(self.table):
            return _nan_state(idx.shape), valid
        rows = self.table.take(np.where(valid, idx, 0))
        t = np.broadcast_to(np.asarray(t_gpst, dtype=float)[..., None], idx.shape)
        st = satellite_state(rows, t)
        return _mask_state(st, valid), valid


def _nan_state(shape: tuple[int, ...]) -> SatelliteState:
    nan3, nan1 = np.full(shape + (3,), np.nan), np.full(shape, np.nan)
    return SatelliteState(nan3, nan3.copy(), nan1, nan1.copy(), nan1.copy())


def _mask_state(st: SatelliteState, valid: np.ndarray) -> SatelliteState:
    v3 = valid[..., None]
    return SatelliteState(
        np.where(v3, st.position_m, np.nan),
        np.where(v3, st.velocity_m_s, np.nan),
        np.where(valid, st.clock_bias_s, np.nan),
        np.where(valid, st.clock_drift_s_s, np.nan),
        np.where(valid, st.relativistic_s, np.nan),
    )


# ---------------------------------------------------------------------------------------------
# signal transit: receiver position + receive time -> ranges, satellite states at transmission

# Transit-time iterations: each shrinks the error by ~v_sat/c ~ 1e-5, three give < 1 um.
TRANSIT_ITERATIONS = 4
NOMINAL_TRANSIT_S = 0.075


class Transit(NamedTuple):
    """Signal path from satellites to a receiver, shapes T + (N,) (T = receive-time shape)."""

    range_m: np.ndarray  # geometric range incl. Earth rotation during transit (Sagnac)
    transmit_time_gpst: np.ndarray  # GPST of transmission
    sat_position_m: np.ndarray  # (..., 3) ECEF at transmission, in the ECEF frame of that instant
    sat_velocity_m_s: np.ndarray  # (..., 3)
    sat_clock_bias_s: np.ndarray  # incl. relativistic term, no group delay
    sat_clock_drift_s_s: np.ndarray
    line_of_sight: np.ndarray  # (..., 3) unit vector receiver -> satellite (receive-time frame)
    ephemeris_index: np.ndarray  # row in NavigationData.table, -1 where none
    valid: np.ndarray  # bool


def transit(nav: NavigationData, sats: Sequence[str], receiver_ecef_m, t_receive_gpst,
            *, iterations: int = TRANSIT_ITERATIONS) -> Transit:
    """Iterate the signal transit time for many satellites (and epochs) at once.

    `t_receive_gpst` is the true GPST of reception (shape T), `receiver_ecef_m` of shape (3,) or
    T + (3,).  The satellite position is computed at transmission time and rotated by the Earth's
    rotation during the transit (Sagnac) into the receive-time ECEF frame; the range is the
    distance in that frame.  Ephemerides are selected at the receive time.
    """
    t_rx = np.asarray(t_receive_gpst, dtype=float)
    rx = np.asarray(receiver_ecef_m, dtype=float)
    idx = nav.select(sats, t_rx)
    t_rx_b = np.broadcast_to(t_rx[..., None], idx.shape)
    return _transit_rows(nav, idx, rx[..., None, :] if rx.ndim > 1 else rx, t_rx_b, iterations, None)


def transit_each(nav: NavigationData, sats: Sequence[str], receiver_ecef_m, t_receive_gpst, groups,
                 *, iterations: int = TRANSIT_ITERATIONS) -> Transit:
    """`transit` of element-wise triples, flat (M,): satellite sats[i] seen from receiver_ecef_m[i] (M, 3) at
    t_receive_gpst[i]; `groups` (M,) numbers the receivers, whose Kepler iterations run as in one `transit` call
    each (the same bits), so a network's stations share one evaluation per epoch."""
    t_rx = np.asarray(t_receive_gpst, dtype=float).reshape(-1)
    idx = nav.select_each(sats, t_rx)
    return _transit_rows(nav, idx, np.asarray(receiver_ecef_m, dtype=float).reshape(-1, 3), t_rx, iterations,
                         np.asarray(groups, dtype=int).reshape(-1))


def _transit_rows(nav: NavigationData, idx: np.ndarray, rx_b: np.ndarray, t_rx_b: np.ndarray, iterations: int,
                  groups) -> Transit:
    """The transit iteration for selected ephemeris rows `idx` (-1: none), receivers `rx_b` and receive times
    `t_rx_b` broadcast to idx's shape."""
    valid = idx >= 0
    if not len(nav.table):
        st = _nan_state(idx.shape)
        nan1 = np.full(idx.shape, np.nan)
        return Transit(nan1, nan1.copy(), st.position_m, st.velocity_m_s, st.clock_bias_s,
                       st.clock_drift_s_s, np.full(idx.shape + (3,), np.nan), idx, valid)
    rows = nav.table.take(np.where(valid, idx, 0))
    _, omge, _ = _system_constants(rows.system)
    tau = np.full(idx.shape, NOMINAL_TRANSIT_S)
    for _ in range(iterations):
        st = satellite_state(rows, t_rx_b, -tau, groups)
        rot = _rotate_z(st.position_m, omge * tau)
        los = rot - rx_b
        rng = np.linalg.norm(los, axis=-1)
        tau = rng / SPEED_OF_LIGHT_M_S
    st = satellite_state(rows, t_rx_b, -tau, groups)
    rot = _rotate_z(st.position_m, omge * tau)
    los = rot - rx_b
    rng = np.linalg.norm(los, axis=-1)
    st = _mask_state(st, valid)
    return Transit(
        np.where(valid, rng, np.nan),
        np.where(valid, t_rx_b - tau, np.nan),
        st.position_m,
        st.velocity_m_s,
        st.clock_bias_s,
        st.clock_drift_s_s,
        np.where(valid[..., None], los / rng[..., None], np.nan),
        idx,
        valid,
    )


def _rotate_z(pos: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotate ECEF vectors by `angle` about Z, frame-wise: coordinates of a fixed inertial point
    after the Earth turned by `angle` (x' = x cos a + y sin a, y' = -x sin a + y cos a)."""
    ca, sa = np.cos(angle), np.sin(angle)
    x, y, z = pos[..., 0], pos[..., 1], pos[..., 2]
    return np.stack((x * ca + y * sa, -x * sa + y * ca, z), axis=-1)
