"""Virtual reference stations: observations the network synthesises for a point (a train, a surveyor).

For every point, per satellite (network-rtk.md, step 5):

    P_vrs = P_m + (g_v - g_m) + (T_v - T_m) + dT + mu_k dI
    L_vrs = L_m + [(g_v - g_m) + (T_v - T_m) + dT - mu_k dI] / lambda_k

where m is the point's master station (the nearest station with data), g = rho - c dts the geometric term
computed at each position with its own transit time and Sagnac rotation (so satellite clock and Earth
rotation stay consistent), T the troposphere model at each position and height, dT and dI the interpolated
non-dispersive and dispersive (f1 ionosphere) corrections between point and master, and
mu_k = (f1 / f_k)^2. The VRS inherits the master's receiver clock and ambiguities, so a rover's double
differences against it have integer ambiguities, and moving the point (a train running along the line)
steps the observations by the geometric shift only: the rover sees a new base position with the same
ambiguities.

Satellites without network corrections (not fixed on the baselines around the point) are left out of a
VRS, unless the point is within `UNCORRECTED_MAX_DISTANCE_M` of its master, where the single-base error is
small (their absence is what the quality flags report).

Everything is vectorised over points and satellites: a VRS for 2,000 trains is a few array operations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from augnet.centre import interpolation
from augnet.centre.network import NetworkEpoch
from augnet.centre.observations import StationEpoch
from augnet.centre.satellite_geometry import MIN_MODEL_ELEVATION_RAD
from augnet.gnss import troposphere
from augnet.gnss.constants import OMEGA_E_BDS_RAD_S, OMEGA_E_GPS_RAD_S, SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, transit
from augnet.gnss.geometry import azimuth_elevation, ecef_to_enu, ecef_to_geodetic
from augnet.gnss.time import to_datetime

C = SPEED_OF_LIGHT_M_S
# Within this distance of its master a point may use satellites the network has no corrections for: the
# single-base DD ionosphere there is a few mm (quiet ionosphere, 1-4 ppm; network-rtk.md).
UNCORRECTED_MAX_DISTANCE_M = 5_000.0
# Stations used for a point's interpolation: its nearest ones ("the surrounding stations").
SUBNET_STATIONS = 4
TRANSIT_CARRY_ITERATIONS = 3  # each shrinks the transit-time error by v_sat/c ~ 1e-5


@dataclass
class VrsEpoch:
    """Synthesised observations for many points at one epoch (points x satellites x 2 frequencies)."""

    t_gpst: float
    points_ecef_m: np.ndarray  # (T, 3)
    master: list[str]  # (T,) master station of each point
    sats: np.ndarray  # (S,)
    codes: np.ndarray  # (S, 2) RINEX codes
    freq_hz: np.ndarray  # (S, 2)
    code_m: np.ndarray  # (T, S, 2) NaN where the satellite is left out for that point
    phase_cyc: np.ndarray  # (T, S, 2)
    cnr_dbhz: np.ndarray  # (T, S, 2)
    lli: np.ndarray  # (T, S, 2) int8
    corrected: np.ndarray  # (T, S) bool: network corrections applied
    model: np.ndarray  # (T, S) int8: interpolation model (interpolation.MODEL_CODES; -1 none)
    distance_to_master_m: np.ndarray  # (T,)
    flags: dict = field(default_factory=dict)

    def station_epoch(self, i: int, name: str = "VRS") -> StationEpoch:
        """Point i as an ordinary station epoch (for RINEX output or a rover engine)."""
        keep = np.isfinite(self.code_m[i]).any(axis=1)
        return StationEpoch(name, self.t_gpst, self.sats[keep], self.code_m[i][keep], self.phase_cyc[i][keep],
                            self.lli[i][keep], self.cnr_dbhz[i][keep], self.freq_hz[keep], self.codes[keep])


def geometry_many(sats, t_tag: float, clock_s, points_ecef_m: np.ndarray, nav: NavigationData):
    """g = rho - c dts, troposphere model and elevation at many points (T, S) for one epoch tag.

    The satellite states are computed once, at the transmission time for a reference point (the points'
    centre), and carried to each point's own transmission time with the satellite velocity and clock drift:
    transmission times differ by under a millisecond across a network (300 km), over which the linear
    carry is exact to a micrometre (satellite acceleration ~0.6 m/s^2). This keeps thousands of points to
    one orbit evaluation per satellite. `clock_s`: the receiver clock offset, one for all points or one
    per point (a VRS takes its master's)."""
    pts = np.atleast_2d(np.asarray(points_ecef_m, float))
    clk = np.broadcast_to(np.asarray(clock_s, float), (len(pts),))
    t_rx0 = t_tag - float(np.median(clk))
    d_rx = (t_tag - clk) - t_rx0  # (T,) each point's reception time against the reference one
    tr = transit(nav, list(sats), pts.mean(axis=0), t_rx0)
    tau0 = t_rx0 - tr.transmit_time_gpst  # (S,)
    omega = np.array([OMEGA_E_BDS_RAD_S if str(s)[0] == "C" else OMEGA_E_GPS_RAD_S for s in sats])
    tau = np.broadcast_to(tau0, (len(pts), len(tau0))).copy()
    for _ in range(TRANSIT_CARRY_ITERATIONS):
        dt_tx = d_rx[:, None] - (tau - tau0)  # transmission time against the reference one
        xs = tr.sat_position_m[None] + tr.sat_velocity_m_s[None] * dt_tx[..., None]
        ang = omega * tau
        ca, sa = np.cos(ang), np.sin(ang)
        rot = np.stack((xs[..., 0] * ca + xs[..., 1] * sa, -xs[..., 0] * sa + xs[..., 1] * ca, xs[..., 2]), axis=-1)
        rng = np.linalg.norm(rot - pts[:, None, :], axis=-1)
        tau = rng / C
    dts = tr.sat_clock_bias_s[None] + tr.sat_clock_drift_s_s[None] * (d_rx[:, None] - (tau - tau0))
    _, el = azimuth_elevation(pts[:, None, :], rot)
    llh = ecef_to_geodetic(pts)
    doy = to_datetime(t_tag).timetuple().tm_yday
    el_c = np.clip(np.where(np.isfinite(el), el, np.pi / 2), MIN_MODEL_ELEVATION_RAD, None)
    trop = troposphere.slant_delay_m(el_c, llh[:, 0:1], llh[:, 2:3], doy)
    return rng - C * dts, trop, el


def synthesize(net: NetworkEpoch, station_epochs: dict[str, StationEpoch], points_ecef_m,
               nav: NavigationData, clocks: dict[str, float] | None = None) -> VrsEpoch | None:
    """VRS observations for each point, from the network's residuals and the master stations' data.

    Receiver clocks of the masters default to the network's estimates; satellites the integrity monitor
    excluded are left out of every VRS."""
    clocks = net.clocks if clocks is None else clocks
    pts = np.atleast_2d(np.asarray(points_ecef_m, float))
    T = len(pts)
    present = [i for i, s in enumerate(net.stations) if station_epochs.get(s) is not None]
    if not present:
        return None
    xyz = net.station_xyz_m
    d = np.linalg.norm(pts[:, None, :] - xyz[None, present, :], axis=2)
    master_idx = np.array(present)[np.argmin(d, axis=1)]  # (T,) row in net.stations
    # the union of satellites the masters observe, in a fixed order
    sat_set = sorted({str(s) for i in set(master_idx.tolist()) for s in station_epochs[net.stations[i]].sats}
                     - set(net.excluded))
    sats = np.array(sat_set)
    S = len(sats)
    code = np.full((T, S, 2), np.nan)
    phase = np.full((T, S, 2), np.nan)
    cnr = np.full((T, S, 2), np.nan)
    lli = np.zeros((T, S, 2), np.int8)
    freq = np.full((S, 2), np.nan)
    codes = np.full((S, 2), "", dtype="<U2")
    corrected = np.zeros((T, S), bool)
    model = np.full((T, S), -1, np.int8)
    net_col = {s: k for k, s in enumerate(net.sats)}
    cols_in_net = np.array([net_col.get(s, -1) for s in sats])
    # interpolated corrections relative to the network master, per point (T, S)
    dI = np.full((T, S), np.nan)
    dT = np.full((T, S), np.nan)
    origin = xyz[0]
    rover_en = ecef_to_enu(pts - origin, origin)[:, :2]
    have_rows = [i for i in range(len(net.stations)) if net.stations[i] in net.present]
    if len(net.sats) and have_rows:
        subnet_keys = _subnets(net.station_en_m, have_rows, rover_en)
        uniq, group = np.unique(subnet_keys, axis=0, return_inverse=True)
        group = np.asarray(group).reshape(-1)
        for g, key in enumerate(uniq):
            rows = np.array(key)
            who = np.flatnonzero(group == g)
            sub_master = int(np.argmin([np.linalg.norm(net.station_en_m[r]) for r in rows]))
            base_i = net.dd_iono_m[rows[sub_master]]
            base_t = net.dd_trop_m[rows[sub_master]]
            # ionosphere and troposphere side by side: the same stations have both, so one set of weights
            nsat = base_i.shape[0]
            both = np.hstack([net.dd_iono_m[rows] - base_i, net.dd_trop_m[rows] - base_t])
            c_both, m_both = interpolation.interpolate(net.station_en_m[rows], rover_en[who], both, master=sub_master)
            ci, ct, mi = c_both[:, :nsat], c_both[:, nsat:], m_both[:nsat]
            ok = cols_in_net >= 0
            dI[np.ix_(who, np.flatnonzero(ok))] = (ci + base_i)[:, cols_in_net[ok]]
            dT[np.ix_(who, np.flatnonzero(ok))] = (ct + base_t)[:, cols_in_net[ok]]
            model[np.ix_(who, np.flatnonzero(ok))] = mi[cols_in_net[ok]]
    dist = d[np.arange(T), np.searchsorted(present, master_idx)] if T else np.zeros(0)
    masters = sorted(set(master_idx.tolist()))
    # one geometry computation for every master and every point (each at its master's receiver clock)
    t_tag = float(station_epochs[net.stations[masters[0]]].t_gpst)
    all_pts = np.vstack([xyz[masters], pts])
    all_clk = np.array([clocks.get(net.stations[m], 0.0) for m in masters]
                       + [clocks.get(net.stations[m], 0.0) for m in master_idx])
    G, TROP, EL = geometry_many(sats, t_tag, all_clk, all_pts, nav)
    for m_i, mrow in enumerate(masters):
        name = net.stations[mrow]
        ep = station_epochs[name]
        ep = ep.subset(~np.isin(ep.sats, list(net.excluded))) if net.excluded else ep
        who = np.flatnonzero(master_idx == mrow)
        col = np.searchsorted(sats, ep.sats)
        g_m, trop_m = G[m_i, col][None], TROP[m_i, col][None]
        rows_v = len(masters) + who
        g_v, trop_v, el_v = G[np.ix_(rows_v, col)], TROP[np.ix_(rows_v, col)], EL[np.ix_(rows_v, col)]
        # corrections between point and this master: (point - net master) - (this master - net master)
        m_cols = cols_in_net[col]
        if len(net.sats):
            mi = np.where(m_cols >= 0, net.dd_iono_m[mrow][np.maximum(m_cols, 0)], np.nan)
            mt = np.where(m_cols >= 0, net.dd_trop_m[mrow][np.maximum(m_cols, 0)], np.nan)
        else:  # no baseline solved this epoch: no corrections at all
            mi = mt = np.full(len(col), np.nan)
        di = dI[np.ix_(who, col)] - mi
        dt_ = dT[np.ix_(who, col)] - mt
        has = np.isfinite(di) & np.isfinite(dt_)
        near = dist[who] <= UNCORRECTED_MAX_DISTANCE_M
        use = (has | near[:, None]) & np.isfinite(g_v) & (el_v > 0)
        di = np.where(has, di, 0.0)
        dt_ = np.where(has, dt_, 0.0)
        shift = (g_v - g_m) + (trop_v - trop_m) + dt_  # (t, s)
        f = ep.freq_hz
        mu = (f[:, 0:1] / f) ** 2  # (s, 2)
        lam = C / f
        pc = ep.code_m[None] + shift[..., None] + mu[None] * di[..., None]
        pl = ep.phase_cyc[None] + (shift[..., None] - mu[None] * di[..., None]) / lam[None]
        u3 = use[..., None]
        code[np.ix_(who, col)] = np.where(u3, pc, np.nan)
        phase[np.ix_(who, col)] = np.where(u3, pl, np.nan)
        cnr[np.ix_(who, col)] = np.where(u3, ep.cnr_dbhz[None], np.nan)
        lli[np.ix_(who, col)] = np.where(u3, ep.lli[None], 0)
        corrected[np.ix_(who, col)] = has & use
        freq[col] = f
        codes[col] = ep.codes
    return VrsEpoch(t_gpst=float(station_epochs[net.stations[present[0]]].t_gpst),
                    points_ecef_m=pts, master=[net.stations[i] for i in master_idx], sats=sats, codes=codes,
                    freq_hz=freq, code_m=code, phase_cyc=phase, cnr_dbhz=cnr, lli=lli, corrected=corrected,
                    model=model, distance_to_master_m=dist)


def _subnets(station_en: np.ndarray, rows: list[int], rover_en: np.ndarray) -> np.ndarray:
    """Each point's surrounding stations (points x k station rows, sorted): its SUBNET_STATIONS nearest
    among those with data."""
    rows_a = np.array(rows)
    d = np.linalg.norm(rover_en[:, None, :] - station_en[rows_a][None, :, :], axis=2)
    k = min(SUBNET_STATIONS, len(rows))
    return np.sort(rows_a[np.argsort(d, axis=1)[:, :k]], axis=1)
