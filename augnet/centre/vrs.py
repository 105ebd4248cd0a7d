"""Virtual reference stations: observations the network synthesises for a point (a train, a surveyor).

For every point, per satellite (network-rtk.md, step 5):

    P_vrs = P_m + (g_v - g_m) + (T_v - T_m) + dT + mu_k dI
    L_vrs = L_m + [(g_v - g_m) + (T_v - T_m) + dT - mu_k dI] / lambda_k

where m is the point's master station (the nearest station with data, kept with a hysteresis while the
network lacks the integers to hand the VRS over to another: `choose_masters`, vrs_handover.py), g = rho - c dts
the geometric term computed at each position with its own transit time and Sagnac rotation (so satellite clock and Earth
rotation stay consistent), T the troposphere model at each position and height, dT and dI the interpolated
non-dispersive and dispersive (f1 ionosphere) corrections between point and master, and
mu_k = (f1 / f_k)^2. The VRS inherits the master's receiver clock and ambiguities, so a rover's double
differences against it have integer ambiguities, and moving the point (a train running along the line)
steps the observations by the geometric shift only: the rover sees a new base position with the same
ambiguities.

Antennas. The network's residuals refer to the stations' antenna reference points when their antennas are
modelled (`NetworkEpoch.antenna_m`); the master's observations then get its phase-centre correction too, so
the VRS is that of a null antenna at the point (phase centre at the point, no variations: RTCM 1033 and RINEX
antenna type `ADVNULLANTENNA`, what commercial VRS send), and a rover applies its own antenna model only.
Without antenna models the VRS carries the master's antenna, as before.

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
# Stations used for a point's interpolation: its nearest ones ("the surrounding stations"). Universal kriging
# spends three stations on its plane, and on a railway the four nearest leave the field's curvature along the line
# unknown; the next stations along the line give it (docs/decisions/0001-vrs-subnet-six-stations.md).
SUBNET_STATIONS = 6
TRANSIT_CARRY_ITERATIONS = 3  # each shrinks the transit-time error by v_sat/c ~ 1e-5
# A point keeps its master unless another station is nearer by this much: far above the GGA noise of a train
# standing at a midpoint (metres), small beside the ~70 km station spacing (decision 0223).
MASTER_SWITCH_MARGIN_M = 2_000.0
# ... and unless the network has the DD integers between the two masters for this many satellites (the
# handover keeps those locks, vrs_handover.py): a network epoch's five DD (postprocess.MIN_NETWORK_DD) and a
# reference satellite in each of three systems (decision 0223)
HANDOVER_MIN_SATELLITES = 8
# Beyond this a point leaves its master for the nearest even without the integers: a backstop (half the
# station spacing of the demo and network-70km), the corrections are interpolated at the point either way.
MASTER_FORCE_MARGIN_M = 35_000.0


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
    # (T,) bool: the point changed its master and the phase was handed over (vrs_handover.py: the satellites
    # not flagged loss-of-lock keep their lock); None: no handover, a master change restarts every lock
    handed_over: np.ndarray | None = None

    def rows(self, sl: slice) -> "VrsEpoch":
        """The points in `sl` (views, not copies)."""
        return VrsEpoch(self.t_gpst, self.points_ecef_m[sl], self.master[sl], self.sats, self.codes, self.freq_hz,
                        self.code_m[sl], self.phase_cyc[sl], self.cnr_dbhz[sl], self.lli[sl], self.corrected[sl],
                        self.model[sl], self.distance_to_master_m[sl], self.flags,
                        None if self.handed_over is None else self.handed_over[sl])

    def station_epoch(self, i: int, name: str = "VRS") -> StationEpoch:
        """Point i as an ordinary station epoch (for RINEX output or a rover engine)."""
        keep = np.isfinite(self.code_m[i]).any(axis=1)
        return StationEpoch(name, self.t_gpst, self.sats[keep], self.code_m[i][keep], self.phase_cyc[i][keep],
                            self.lli[i][keep], self.cnr_dbhz[i][keep], self.freq_hz[keep], self.codes[keep])


class GeometryFrame:
    """Satellite states for one epoch tag, computed once at a reference reception time and point, from
    which the geometry at any number of points is carried (`at`); more satellites can be added later
    (`extend`) with the same reference, so columns and rows computed at different times agree exactly."""

    def __init__(self, t_tag: float, t_rx0: float, ref_pos: np.ndarray, nav: NavigationData, sats=()):
        self.t_tag = float(t_tag)
        self.t_rx0 = float(t_rx0)
        self.ref_pos = np.asarray(ref_pos, float)
        self.nav = nav
        self.col: dict[str, int] = {}
        self.pos = np.zeros((0, 3))
        self.vel = np.zeros((0, 3))
        self.clk = np.zeros(0)
        self.drift = np.zeros(0)
        self.tau0 = np.zeros(0)
        self.omega = np.zeros(0)
        self.doy = to_datetime(self.t_tag).timetuple().tm_yday
        self.extend(sats)

    def extend(self, sats) -> None:
        new = [str(s) for s in dict.fromkeys(sats) if str(s) not in self.col]
        if not new:
            return
        tr = transit(self.nav, new, self.ref_pos, self.t_rx0)
        for s in new:
            self.col[s] = len(self.col)
        self.pos = np.vstack([self.pos, tr.sat_position_m])
        self.vel = np.vstack([self.vel, tr.sat_velocity_m_s])
        self.clk = np.concatenate([self.clk, tr.sat_clock_bias_s])
        self.drift = np.concatenate([self.drift, tr.sat_clock_drift_s_s])
        self.tau0 = np.concatenate([self.tau0, self.t_rx0 - tr.transmit_time_gpst])
        self.omega = np.concatenate([self.omega, [OMEGA_E_BDS_RAD_S if s[0] == "C" else OMEGA_E_GPS_RAD_S
                                                  for s in new]])

    def cols(self, sats) -> np.ndarray:
        self.extend(sats)
        return np.array([self.col[str(s)] for s in sats], dtype=int)

    def at(self, points_ecef_m, clock_s, cols: np.ndarray | None = None):
        """g = rho - c dts, troposphere model and elevation (points x satellites `cols`)."""
        pts = np.atleast_2d(np.asarray(points_ecef_m, float))
        clk = np.broadcast_to(np.asarray(clock_s, float), (len(pts),))
        cols = np.arange(len(self.col)) if cols is None else cols
        pos, vel, omega, tau0 = self.pos[cols], self.vel[cols], self.omega[cols], self.tau0[cols]
        d_rx = (self.t_tag - clk) - self.t_rx0  # (T,) each point's reception time against the reference one
        tau = np.broadcast_to(tau0, (len(pts), len(tau0))).copy()
        for _ in range(TRANSIT_CARRY_ITERATIONS):
            dt_tx = d_rx[:, None] - (tau - tau0)  # transmission time against the reference one
            xs = pos[None] + vel[None] * dt_tx[..., None]
            ang = omega * tau
            ca, sa = np.cos(ang), np.sin(ang)
            rot = np.stack((xs[..., 0] * ca + xs[..., 1] * sa, -xs[..., 0] * sa + xs[..., 1] * ca, xs[..., 2]),
                           axis=-1)
            rng = np.linalg.norm(rot - pts[:, None, :], axis=-1)
            tau = rng / C
        dts = self.clk[cols][None] + self.drift[cols][None] * (d_rx[:, None] - (tau - tau0))
        _, el = azimuth_elevation(pts[:, None, :], rot)
        llh = ecef_to_geodetic(pts)
        el_c = np.clip(np.where(np.isfinite(el), el, np.pi / 2), MIN_MODEL_ELEVATION_RAD, None)
        trop = troposphere.slant_delay_m(el_c, llh[:, 0:1], llh[:, 2:3], self.doy)
        return rng - C * dts, trop, el


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
    frame = GeometryFrame(t_tag, t_tag - float(np.median(clk)), pts.mean(axis=0), nav, list(sats))
    return frame.at(pts, clk)


class VrsPlan:
    """Everything a VRS epoch needs but the master stations' observations, for one network epoch (the
    corrections), one epoch tag and one set of stations with data: each point's master, its interpolated
    corrections and the geometry at the point and at the masters.

    `synthesize` builds one when given none. The centre builds the next epoch's ahead, while it waits for
    that epoch's data (`VrsEngine.prepare_next`): then only the observations are added when they arrive.
    Points are rows keyed by their client; a client that moved or is new gets its row when asked
    (`rows_for`), satellites new at the epoch get their geometry columns the same way, with the same
    reference, so a plan made ahead gives the very numbers a plan made on the spot would."""

    def __init__(self, net: NetworkEpoch, nav: NavigationData, t_tag: float, present: list[str],
                 clocks: dict[str, float] | None = None, masters: dict | None = None):
        """`masters`: the current master of each point key, kept by `choose_masters`'s hysteresis."""
        self.net = net
        self.current_masters = masters or {}
        self.nav = nav
        self.t_tag = float(t_tag)
        self.clocks = net.clocks if clocks is None else clocks
        # stations whose coordinates the network flagged serve no point (NetworkEpoch.vrs_excluded, decision 0254)
        present = [s for s in present if s not in net.vrs_excluded]
        self.present = [i for i, s in enumerate(net.stations) if s in set(present)]
        self.present_names = frozenset(net.stations[i] for i in self.present)
        xyz = net.station_xyz_m
        st_clk = np.array([self.clocks.get(net.stations[i], 0.0) for i in self.present])
        self.frame = GeometryFrame(self.t_tag, self.t_tag - float(np.median(st_clk)) if len(st_clk) else self.t_tag,
                                   xyz[self.present].mean(axis=0) if self.present else xyz[0], nav)
        self.station_clk = {i: self.clocks.get(net.stations[i], 0.0) for i in self.present}
        self._station_geo: dict[int, tuple] = {}  # station row -> (G, TROP, EL) over the frame's columns
        self.net_col = {s: k for k, s in enumerate(net.sats)}
        self.have_rows = [i for i in range(len(net.stations))
                          if net.stations[i] in net.present and net.stations[i] not in net.vrs_excluded]
        # per point row
        self.keys: dict = {}
        self.points = np.zeros((0, 3))
        self.master_idx = np.zeros(0, int)
        self.dist = np.zeros(0)
        Sn = len(net.sats)
        self.dI = np.zeros((0, Sn))
        self.dT = np.zeros((0, Sn))
        self.model = np.zeros((0, Sn), np.int8)
        self._geo = [np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0))]  # G, TROP, EL (rows x frame cols)

    def fits(self, net: NetworkEpoch, nav: NavigationData, t_tag: float, present, clocks) -> bool:
        return (net is self.net and nav is self.nav and float(t_tag) == self.t_tag
                and frozenset(present) == self.present_names and (clocks is None or clocks == self.clocks))

    def rows_for(self, points_ecef_m, keys=None) -> np.ndarray:
        """Row of each point (a client whose point is unchanged keeps its row; others get new ones)."""
        pts = np.atleast_2d(np.asarray(points_ecef_m, float))
        if keys is None:
            return self._add_rows(pts, [None] * len(pts))
        rows = np.array([self.keys.get(k, -1) for k in keys], dtype=int)
        known = rows >= 0
        if known.any():
            same = np.all(self.points[rows[known]] == pts[known], axis=1)
            rows[np.flatnonzero(known)[~same]] = -1
        fresh = np.flatnonzero(rows < 0)
        if fresh.size:
            rows[fresh] = self._add_rows(pts[fresh], [keys[i] for i in fresh])
        return rows

    def _add_rows(self, pts: np.ndarray, keys: list) -> np.ndarray:
        net = self.net
        T = len(pts)
        first = len(self.points)
        xyz = net.station_xyz_m
        if self.present:
            d = np.linalg.norm(pts[:, None, :] - xyz[None, self.present, :], axis=2)
            nearest = choose_masters(net, self.present, d, [self.current_masters.get(k) for k in keys])
            master_idx = np.array(self.present)[nearest]  # (T,) row in net.stations
            dist = d[np.arange(T), nearest]
        else:
            master_idx, dist = np.zeros(T, int), np.full(T, np.inf)
        # interpolated corrections relative to the network master, per point and network satellite
        Sn = len(net.sats)
        dI = np.full((T, Sn), np.nan)
        dT = np.full((T, Sn), np.nan)
        model = np.full((T, Sn), -1, np.int8)
        if Sn and self.have_rows and T:
            origin = xyz[0]
            rover_en = ecef_to_enu(pts - origin, origin)[:, :2]
            subnet_keys = _subnets(net.station_en_m, self.have_rows, rover_en)
            uniq, group = np.unique(subnet_keys, axis=0, return_inverse=True)
            group = np.asarray(group).reshape(-1)
            for g, key in enumerate(uniq):
                rows = np.array(key)
                who = np.flatnonzero(group == g)
                sub_master = int(np.argmin([np.linalg.norm(net.station_en_m[r]) for r in rows]))
                base_i = net.dd_iono_m[rows[sub_master]]
                base_t = net.dd_trop_m[rows[sub_master]]
                # ionosphere and troposphere side by side: the same stations have both, so one set of weights
                both = np.hstack([net.dd_iono_m[rows] - base_i, net.dd_trop_m[rows] - base_t])
                c_both, m_both = interpolation.interpolate(net.station_en_m[rows], rover_en[who], both,
                                                           master=sub_master)
                dI[who] = c_both[:, :Sn] + base_i
                dT[who] = c_both[:, Sn:] + base_t
                model[who] = m_both[:Sn]
        clk = np.array([self.station_clk.get(int(m), 0.0) for m in master_idx]) if T else np.zeros(0)
        G, TROP, EL = self.frame.at(pts, clk) if T else (np.zeros((0, len(self.frame.col))),) * 3
        self.points = np.vstack([self.points, pts])
        self.master_idx = np.concatenate([self.master_idx, master_idx])
        self.dist = np.concatenate([self.dist, dist])
        self.dI = np.vstack([self.dI, dI])
        self.dT = np.vstack([self.dT, dT])
        self.model = np.vstack([self.model, model])
        self._geo = [np.vstack([a, b]) if len(a) else b for a, b in zip(self._geo, (G, TROP, EL))]
        for i, k in enumerate(keys):
            if k is not None:
                self.keys[k] = first + i
        return np.arange(first, first + T)

    def add_sats(self, sats) -> None:
        """Geometry columns for satellites not yet in the plan (every row and station)."""
        n0 = len(self.frame.col)
        self.frame.extend(sats)
        n1 = len(self.frame.col)
        if n1 == n0:
            return
        cols = np.arange(n0, n1)
        if len(self.points):
            clk = np.array([self.station_clk.get(int(m), 0.0) for m in self.master_idx])
            extra = self.frame.at(self.points, clk, cols)
            self._geo = [np.hstack([a, b]) if a.size else b for a, b in zip(self._geo, extra)]
        self._station_geo = {}  # recomputed over all columns when next asked

    def geometry(self, rows: np.ndarray, cols: np.ndarray):
        return tuple(a[np.ix_(rows, cols)] for a in self._geo)

    def prepare_stations(self) -> None:
        """The geometry at every station with data (any may be a master) over the plan's satellites."""
        for row in self.present:
            self.station_geometry(row, np.zeros(0, int))

    def station_geometry(self, row: int, cols: np.ndarray):
        geo = self._station_geo.get(row)
        if geo is None or geo[0].shape[1] < len(self.frame.col):
            geo = self.frame.at(self.net.station_xyz_m[row], self.station_clk.get(row, 0.0))
            self._station_geo[row] = geo
        return tuple(a[0, cols] for a in geo)


def choose_masters(net: NetworkEpoch, present: list[int], d: np.ndarray, current: list) -> np.ndarray:
    """Each point's master, as an index into `present` (rows of net.stations with data; `d`: points x present
    distances [m]): the nearest, but a point keeps its `current` master (a station name, None for a new point)
    while it has data, unless another is nearer by MASTER_SWITCH_MARGIN_M and the network has the DD integers
    between the two for HANDOVER_MIN_SATELLITES satellites (or nearer by MASTER_FORCE_MARGIN_M)."""
    nearest = np.argmin(d, axis=1) if d.size else np.zeros(len(d), int)
    pos = {net.stations[r]: k for k, r in enumerate(present)}
    cur = np.array([pos.get(name, -1) if name is not None else -1 for name in current], dtype=int)
    idx = np.flatnonzero((cur >= 0) & (cur != nearest))
    if not idx.size:
        return nearest
    gain = d[idx, cur[idx]] - d[idx, nearest[idx]]
    keep = gain < MASTER_SWITCH_MARGIN_M
    ready: dict = {}
    for n in np.flatnonzero(~keep & (gain < MASTER_FORCE_MARGIN_M)):  # may move: only with the integers
        pair = (int(cur[idx[n]]), int(nearest[idx[n]]))
        if pair not in ready:
            ready[pair] = handover_satellites(net, net.stations[present[pair[0]]],
                                              net.stations[present[pair[1]]]) >= HANDOVER_MIN_SATELLITES
        keep[n] = not ready[pair]
    nearest[idx[keep]] = cur[idx[keep]]
    return nearest


def handover_satellites(net: NetworkEpoch, a: str, b: str) -> int:
    """How many satellites have the DD integers between stations `a` and `b` on both frequencies."""
    if net.dd_n is None or a not in net.stations or b not in net.stations:
        return 0
    ia, ib = net.stations.index(a), net.stations.index(b)
    return int(np.isfinite(net.dd_n[ia] - net.dd_n[ib]).all(axis=1).sum())


def synthesize(net: NetworkEpoch, station_epochs: dict[str, StationEpoch], points_ecef_m,
               nav: NavigationData, clocks: dict[str, float] | None = None, plan: VrsPlan | None = None,
               keys: list | None = None, masters: dict | None = None) -> VrsEpoch | None:
    """VRS observations for each point, from the network's residuals and the master stations' data.

    Receiver clocks of the masters default to the network's estimates; satellites the integrity monitor
    excluded are left out of every VRS. `plan` (made ahead for this network epoch, epoch tag and stations,
    see `VrsPlan`; ignored when it does not fit) and `keys` (one per point: the client, so that a plan's row
    is reused while its point is unchanged) only save time: the result is the same. `masters`: the current master
    of each key (hysteresis, `choose_masters`; a plan made ahead takes them when made)."""
    pts = np.atleast_2d(np.asarray(points_ecef_m, float))
    T = len(pts)
    present_names = [s for s in net.stations if station_epochs.get(s) is not None and s not in net.vrs_excluded]
    if not present_names:
        return None
    t_tag = float(station_epochs[present_names[0]].t_gpst)
    planned = plan is not None and plan.fits(net, nav, t_tag, present_names, clocks)
    if not planned:
        plan = VrsPlan(net, nav, t_tag, present_names, clocks, masters)
        keys = None if not masters else keys
    rows = plan.rows_for(pts, keys)
    master_idx = plan.master_idx[rows]
    dist = plan.dist[rows]
    masters = sorted(set(master_idx.tolist()))
    # the union of satellites the masters observe, in a fixed order
    sat_set = sorted({str(s) for i in masters for s in station_epochs[net.stations[i]].sats} - set(net.excluded))
    sats = np.array(sat_set)
    S = len(sats)
    plan.add_sats(sat_set)
    gcols = plan.frame.cols(sat_set)
    code = np.full((T, S, 2), np.nan)
    phase = np.full((T, S, 2), np.nan)
    cnr = np.full((T, S, 2), np.nan)
    lli = np.zeros((T, S, 2), np.int8)
    freq = np.full((S, 2), np.nan)
    codes = np.full((S, 2), "", dtype="<U2")
    corrected = np.zeros((T, S), bool)
    model = np.full((T, S), -1, np.int8)
    cols_in_net = np.array([plan.net_col.get(s, -1) for s in sat_set], dtype=int)
    # interpolated corrections relative to the network master, per point (T, S)
    dI = np.full((T, S), np.nan)
    dT = np.full((T, S), np.nan)
    ok = np.flatnonzero(cols_in_net >= 0)
    if ok.size:
        sel = np.ix_(rows, cols_in_net[ok])
        dI[:, ok] = plan.dI[sel]
        dT[:, ok] = plan.dT[sel]
        model[:, ok] = plan.model[sel]
    G, TROP, EL = plan.geometry(rows, gcols)
    for mrow in masters:
        name = net.stations[mrow]
        ep = station_epochs[name]
        ep = ep.subset(~np.isin(ep.sats, list(net.excluded))) if net.excluded else ep
        ant = net.antenna_correction(ep)  # the master's phase-centre correction: observations referred to its ARP
        obs_code = ep.code_m if ant is None else ep.code_m + ant
        who = np.flatnonzero(master_idx == mrow)
        col = np.searchsorted(sats, ep.sats)
        g_all, trop_all, _ = plan.station_geometry(mrow, gcols)
        g_m, trop_m = g_all[col][None], trop_all[col][None]
        g_v, trop_v, el_v = G[np.ix_(who, col)], TROP[np.ix_(who, col)], EL[np.ix_(who, col)]
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
        obs_phase = ep.phase_cyc if ant is None else ep.phase_cyc + ant / lam
        pc = obs_code[None] + shift[..., None] + mu[None] * di[..., None]
        pl = obs_phase[None] + (shift[..., None] - mu[None] * di[..., None]) / lam[None]
        u3 = use[..., None]
        code[np.ix_(who, col)] = np.where(u3, pc, np.nan)
        phase[np.ix_(who, col)] = np.where(u3, pl, np.nan)
        cnr[np.ix_(who, col)] = np.where(u3, ep.cnr_dbhz[None], np.nan)
        lli[np.ix_(who, col)] = np.where(u3, ep.lli[None], 0)
        corrected[np.ix_(who, col)] = has & use
        freq[col] = f
        codes[col] = ep.codes
    return VrsEpoch(t_gpst=t_tag, points_ecef_m=pts, master=[net.stations[i] for i in master_idx], sats=sats,
                    codes=codes, freq_hz=freq, code_m=code, phase_cyc=phase, cnr_dbhz=cnr, lli=lli,
                    corrected=corrected, model=model, distance_to_master_m=dist, flags={"planned": planned})


def _subnets(station_en: np.ndarray, rows: list[int], rover_en: np.ndarray) -> np.ndarray:
    """Each point's surrounding stations (points x k station rows, sorted): its SUBNET_STATIONS nearest
    among those with data."""
    rows_a = np.array(rows)
    d = np.linalg.norm(rover_en[:, None, :] - station_en[rows_a][None, :, :], axis=2)
    k = min(SUBNET_STATIONS, len(rows))
    return np.sort(rows_a[np.argsort(d, axis=1)[:, :k]], axis=1)
