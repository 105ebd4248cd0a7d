"""The simulated world: receivers (reference stations and trains) observing the truth constellation.

`World(scenario)` builds everything the scenario names -- constellation and broadcast ephemerides
(or a RINEX nav file), orbit/clock errors, ionosphere and troposphere fields, receivers with their
clocks, noise and multipath, tracking (arcs, ambiguities, cycle slips, blockages) -- and
`World.epochs()` yields blocks of consecutive epochs, every array vectorised over
(epoch, receiver, satellite, signal).

Observation equations (per receiver r, satellite s, signal k; metres unless cycles):
    P = rho + c (dt_r - dt^s + tgd_k) + T + I_k + m_k + e_k
    L = [rho + c (dt_r - dt^s) + T - I_k + mu_k + eps_k] / lambda_k + N_k      [cycles]
    D = -[d(rho)/dt + c (d(dt_r)/dt - d(dt^s)/dt)] / lambda_k                     [Hz]
rho: geometric range from the truth satellite position at transmission (broadcast + orbit error) to
the receiver antenna at the true reception time, Earth rotation during transit included; dt^s:
truth satellite clock (broadcast polynomial + relativistic term + clock error); dt_r: receiver
clock; the epoch tag is true time + dt_r.  Code also carries the broadcast satellite group delay of
its signal (TGD/BGD, as a single-frequency user applies it; zero in the nominal constellation).

Truth (positions, clocks, atmosphere per receiver and satellite, ambiguities) is returned beside the
observables and never mixed into them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.constants import (GM_BDS_M3_S2, GM_GAL_M3_S2, GM_GPS_M3_S2, OMEGA_E_BDS_RAD_S,
                                   OMEGA_E_GAL_RAD_S, OMEGA_E_GPS_RAD_S, SPEED_OF_LIGHT_M_S)
from augnet.gnss.ephemeris import Ephemeris, NavigationData, group_delay_s, satellite_state
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation, geodetic_deg_to_ecef
from augnet.gnss.signals import by_rinex
from stations import constellation as const
from stations.ionosphere import IonosphereField, delay_m
from stations.kinematics import GRID_M, STEP_S, braking_curve, drive, train_motion
from stations.layout import Layout
from stations.orbit_errors import OrbitClockErrors
from stations.receiver_errors import GRADES, NoiseAndMultipath, ReceiverClocks, cnr_dbhz, elevation_scale
from stations.scenario import RECEIVER_EVENT_FIELDS, Scenario, ScenarioError, receiver_events, resolve_ionosphere
from stations.track import TrackLine, check_on_line, cutting_mask_rad
from stations.tracking import Tracking, Unflagged
from stations.troposphere import WetResidualField, niell, zenith_delays_m

TRANSIT_ITERATIONS = 3  # each iteration shrinks the transit-time error by v_sat/c ~ 1e-5
NOMINAL_TRANSIT_S = 0.075
BLOCK_EPOCHS = 60  # epochs computed together (vectorised); results do not depend on it
DOPPLER_NOISE_HZ = 0.02
ATMO_RATE_STEP_S = 0.5  # half-step of the central difference giving the atmosphere's rate
# A train's rear antenna (Train.rear_antenna): its receiver's kind and the suffix of its id ("R1.rear"; train
# ids have no ".", so it cannot clash).
REAR_KIND = "rear"
REAR_SUFFIX = ".rear"
# The train length when the scenario gives none [m]: a CR400AF 8-car set (as augnet.onboard.position_report).
DEFAULT_TRAIN_LENGTH_M = 209.0
BURST_SEED_TAG = 0xB0257  # multipath bursts' per-satellite signs: their own stream, no other draw moves


@dataclass
class Receiver:
    id: str
    kind: str  # "station" or "train"
    rtcm_id: int  # RTCM reference station id
    grade: str
    ecef: np.ndarray  # (n_epochs, 3) antenna truth
    velocity: np.ndarray  # (n_epochs, 3)
    track_id: str = ""
    km: np.ndarray | None = None  # (n_epochs,) chainage [km] for trains
    speed_m_s: np.ndarray | None = None
    swept_mask_deg: np.ndarray | None = None  # (n_epochs,) all-sky blockage since the last epoch (90/0)
    cutting_deg: np.ndarray | None = None  # (n_epochs,) cutting wall angle since the last epoch
    heading_rad: np.ndarray | None = None  # (n_epochs,) azimuth of the direction of travel
    outage: np.ndarray | None = None  # (n_epochs,) bool: no data (station outage)
    # trains on a layout route (truth): the edge of each epoch, and the distance run along the route [m]
    edge: np.ndarray | None = None  # (n_epochs,) edge ids
    route_m: np.ndarray | None = None


@dataclass
class EpochBlock:
    """Consecutive epochs: observables and, apart, the truth.  Shapes (E, R, N, K) / (E, R, N)."""

    t_gpst: np.ndarray  # (E,) epoch tags (receiver time, GPST seconds)
    epoch_index: np.ndarray  # (E,)
    pseudorange_m: np.ndarray
    phase_cyc: np.ndarray
    doppler_hz: np.ndarray
    cnr_dbhz: np.ndarray
    lli: np.ndarray  # int8: bit 0 loss of lock, bit 1 half-cycle ambiguity
    lock_time_s: np.ndarray
    observed: np.ndarray  # (E, R, N, K) bool
    # truth
    rx_ecef: np.ndarray  # (E, R, 3)
    rx_clock_s: np.ndarray  # (E, R)
    elevation_rad: np.ndarray  # (E, R, N)
    azimuth_rad: np.ndarray
    range_m: np.ndarray  # geometric range incl. Sagnac (E, R, N)
    sat_clock_s: np.ndarray  # truth satellite clock (E, R, N)
    sat_clock_error_s: np.ndarray  # truth minus broadcast (drawn error + broadcast rounding)
    orbit_error_range_m: np.ndarray  # truth minus broadcast orbit, along the line of sight
    stec_tecu: np.ndarray  # slant TEC (E, R, N)
    tropo_m: np.ndarray  # slant troposphere delay (E, R, N)
    ambiguity_cyc: np.ndarray  # integer ambiguity (E, R, N, K), NaN when not tracked
    multipath_code_m: np.ndarray
    multipath_phase_m: np.ndarray
    extras: dict = field(default_factory=dict)


def _system_gm_omge(system: str):
    return {"G": (GM_GPS_M3_S2, OMEGA_E_GPS_RAD_S), "E": (GM_GAL_M3_S2, OMEGA_E_GAL_RAD_S),
            "C": (GM_BDS_M3_S2, OMEGA_E_BDS_RAD_S)}[system]


def route_motion(layout: Layout, tr, t_rel: np.ndarray, spacing_m: float = 0.0):
    """(route, route distance [m], speed [m/s]) of a train's head at times `t_rel` on its layout route: speed
    limited by the line speed, the scenario's restrictions (by km) and the curves (LATERAL_ACCEL_M_S2); it halts
    at each of its `stops` for the dwell and at the route's end. The head starts `spacing_m` along the route (a
    train with a rear antenna stands with its rear at start_km)."""
    route = layout.route(tr.route, tr.direction, tr.start_km)
    if spacing_m >= route.length_m:
        raise ScenarioError(f"train {tr.id}: route {route.length_m:.0f} m, not longer than the train")
    u = np.arange(0.0, route.length_m + GRID_M, GRID_M)
    limit = route.speed_limit_m_s(u, tr.speed_kmh / 3.6)
    km_grid = np.interp(u, route.u_m, route.km)
    prof = sorted(tr.speed_profile, key=lambda p: p.from_km)
    for k, p in enumerate(prof):
        lo, hi = p.from_km, prof[k + 1].from_km if k + 1 < len(prof) else np.inf
        inside = (km_grid >= lo) & (km_grid < hi)  # as train_motion: from its km to the next entry's
        limit[inside] = np.minimum(limit[inside], p.speed_kmh / 3.6)
    limit[-1] = 0.0  # stop at the end of the route
    sign = 1.0 if tr.direction > 0 else -1.0
    halts = []
    for st in tr.stops:
        if not min(route.km) <= st.km <= max(route.km):
            raise ScenarioError(f"train {tr.id}: stop at km {st.km} is not on its route")
        halts.append((float(np.interp(sign * st.km, sign * route.km, route.u_m)), st.dwell_s))
    halts.append((route.length_m, math.inf))
    um = np.full(len(t_rel), spacing_m)
    v = np.zeros(len(t_rel))
    u0, t0, v0 = spacing_m, 0.0, tr.start_speed_kmh / 3.6
    t_end = float(np.max(t_rel)) if len(t_rel) else 0.0
    for u_halt, dwell in sorted(halts):
        if u_halt <= u0 or t0 > t_end:
            continue
        lim = limit.copy()
        lim[u >= u_halt] = 0.0
        allowed = braking_curve(u, lim, tr.decel_m_s2)
        v0 = min(v0, float(np.interp(u0, u, allowed)))
        tt = np.arange(0.0, t_end - t0 + 2 * STEP_S, STEP_S)
        uu, vv, _ = drive(u - u0, allowed, u_halt - u0, v0, tr.accel_m_s2, tr.decel_m_s2, tt)
        arrived = np.flatnonzero(uu >= u_halt - u0 - 1e-6)
        t_arr = t0 + (float(tt[arrived[0]]) if len(arrived) else math.inf)
        seg = (t_rel >= t0) & (t_rel < t_arr)
        um[seg] = u0 + np.interp(t_rel[seg] - t0, tt, uu)
        v[seg] = np.interp(t_rel[seg] - t0, tt, vv)
        um[t_rel >= t_arr] = u_halt  # standing until the next leg starts (overwritten by it)
        v[t_rel >= t_arr] = 0.0
        u0, t0, v0 = u_halt, t_arr + dwell, 0.0
    return route, um, v


def rear_motion(t_rel: np.ndarray, um: np.ndarray, v: np.ndarray, spacing_m: float, split=None,
                fault_clock_offset_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The rear antenna's route distance and speed: `spacing_m` behind the head (`um`, `v`), or from a
    `train_split` fault's time on (its at_s less `fault_clock_offset_s`) slowing at its deceleration to a stand."""
    ur, vr = um - spacing_m, v.copy()
    if split is None:
        return ur, vr
    t0 = float(split.at_s) - fault_clock_offset_s
    at = t_rel >= t0
    if np.any(at):
        k0 = int(np.argmax(at))
        u0 = float(np.interp(t0, t_rel, ur))
        v0 = float(np.interp(t0, t_rel, vr))
        dt = np.minimum(t_rel[at] - t0, v0 / split.rear_decel_m_s2)  # to a stand
        ur[k0:] = u0 + v0 * dt - 0.5 * split.rear_decel_m_s2 * dt ** 2
        vr[k0:] = v0 - split.rear_decel_m_s2 * dt
    return ur, vr


class World:
    def __init__(self, scenario: Scenario, nav_ephemerides: list[Ephemeris] | None = None):
        sc = scenario
        self.scenario = sc
        self.t0 = float(gtime.from_datetime(sc.start))
        self.n_epochs = sc.n_epochs
        self.dt = sc.interval_s
        self.t_tags = self.t0 + np.arange(self.n_epochs) * self.dt
        self.track = TrackLine(sc.line) if sc.line is not None else None
        if self.track is not None:
            check_on_line(sc, self.track)
        self.layout = Layout.load(sc.layout.file) if sc.layout is not None else None
        self.routes = {}  # train id -> stations.layout.Route
        # constellation: our nominal one, or the satellites of a given nav file
        t_end = self.t_tags[-1]
        if nav_ephemerides is None:
            self.orbits = const.nominal_orbits(sc.constellations, self.t0, sc.seed)
            self.ephemerides = const.broadcast_ephemerides(self.orbits, self.t0, t_end)
            # truth: the same orbits at full precision, continuous across set changes (a satellite
            # does not jump when a new set is uploaded; only its broadcast description does)
            truth_sets = const.broadcast_ephemerides(self.orbits, self.t0, t_end, quantised=False)
            self.nominal = True
        else:
            self.orbits = []
            self.ephemerides = [e for e in nav_ephemerides if e.system in sc.constellations]
            truth_sets = self.ephemerides  # a real file: truth follows its sets (jumps at changes)
            self.nominal = False
        self.nav = NavigationData(self.ephemerides)
        self.truth_nav = NavigationData(truth_sets)
        sats = [s for s in self.nav.satellites if s[0] in sc.constellations]
        self.sats = sats
        n = len(sats)
        self.sat_system = np.array([s[0] for s in sats])
        # signals (N, K)
        self.K = max(len(sc.signals[s]) for s in sc.constellations)
        self.codes = np.full((n, self.K), "", dtype="<U2")
        self.freq_hz = np.full((n, self.K), np.nan)
        for j, s in enumerate(sats):
            for k, code in enumerate(sc.signals[s[0]]):
                self.codes[j, k] = code
                self.freq_hz[j, k] = by_rinex(s[0], code).freq_hz
        self.wavelength_m = SPEED_OF_LIGHT_M_S / self.freq_hz
        self.signal_exists = ~np.isnan(self.freq_hz)
        self.omge = np.array([_system_gm_omge(s)[1] for s in self.sat_system])
        # truth error models
        errs = sc.errors
        rows0 = self.nav.select(sats, self.t0)
        sqrt_a = np.where(rows0 >= 0, self.nav.table.sqrt_a[np.maximum(rows0, 0)], 5150.0)
        gm = np.array([_system_gm_omge(s)[0] for s in self.sat_system])
        period = 2 * np.pi * np.sqrt(sqrt_a**6 / gm)
        steps = [(f.satellite, self.t0 + f.at_s, f.step_ns * 1e-9) for f in sc.faults
                 if f.kind == "satellite_clock_step"]
        ramps = [(f.satellite, self.t0 + f.at_s, self.t0 + (f.until_s if f.until_s is not None else sc.duration_s),
                  f.ramp_ns_per_s * 1e-9) for f in sc.faults if f.kind == "satellite_clock_ramp"]
        oc = errs.orbit_clock
        self.orbit_errors = OrbitClockErrors(sats, oc.orbit_error_m if oc.enabled else 0.0,
                                             oc.clock_error_ns if oc.enabled else 0.0, sc.seed, period, steps, ramps)
        self.receivers = self._build_receivers()
        # multipath bursts: (receiver row, from, to [GPST s], code [m], phase [m], per-satellite sign (N,))
        rx_row = {r.id: i for i, r in enumerate(self.receivers)}
        rng_burst = np.random.default_rng([sc.seed, BURST_SEED_TAG])
        self.bursts = []
        for f in sc.faults:
            if f.kind != "multipath_burst":
                continue
            sign = np.zeros(n) if f.satellite is not None else rng_burst.choice([-1.0, 1.0], n)
            if f.satellite is not None and f.satellite in sats:
                sign[sats.index(f.satellite)] = 1.0
            self.bursts.append((rx_row[f.receiver], self.t0 + f.at_s, self.t0 + f.until_s, f.code_m, f.phase_m, sign))
        lat_c, lon_c = self._region_centre()
        self.iono_params = resolve_ionosphere(errs.ionosphere)
        self.iono = IonosphereField(self.iono_params, lat_c, lon_c, sc.seed)
        tr = errs.troposphere
        self.tropo_enabled = tr.enabled
        self.wet = WetResidualField(tr.wet_residual_m if tr.enabled else 0.0, tr.wet_residual_scale_km,
                                    lat_c, lon_c, sc.seed)
        self.doy = sc.start.timetuple().tm_yday
        R = len(self.receivers)
        # per-receiver noise levels (zenith): columns code, phase
        nz = errs.noise
        self.sigma_code = np.array([nz.geodetic_code_m if r.grade == "geodetic" else nz.train_code_m
                                    for r in self.receivers])
        self.sigma_phase = np.array([nz.geodetic_phase_m if r.grade == "geodetic" else nz.train_phase_m
                                     for r in self.receivers])
        if not nz.enabled:
            self.sigma_code[:] = 0.0
            self.sigma_phase[:] = 0.0
        self.cnr_zenith = np.array([GRADES[r.grade]["cnr_zenith"] for r in self.receivers])
        # random streams, one per purpose, each drawn in fixed shapes per epoch (block-size free)
        ss = np.random.SeedSequence([sc.seed, 0x51A7])
        rng_noise, rng_track, rng_clock = [np.random.default_rng(s) for s in ss.spawn(3)]
        rng_init = np.random.default_rng([sc.seed, 0x1217])
        grades = [r.grade for r in self.receivers]
        self.clocks = ReceiverClocks(grades, self.dt, errs.receiver_clock, rng_clock, rng_init)
        shape = (R, n, self.K)
        code_factor = None
        if nz.second_signal_code_factor != 1.0:
            code_factor = np.r_[1.0, np.full(self.K - 1, nz.second_signal_code_factor)]
        self.noise = NoiseAndMultipath(shape, self.dt, self.sigma_code, self.sigma_phase,
                                       [GRADES[g]["mp_tau_s"] for g in grades], nz.enabled and nz.multipath,
                                       rng_noise, rng_init, code_factor)
        # each receiver's events: errors' own unless errors.by_receiver gives it (or its class) its own (0273)
        self.receiver_events = receiver_events(errs, [(r.id, r.kind) for r in self.receivers])
        ev = {f: np.array([getattr(x, f) for x in self.receiver_events]) for f in RECEIVER_EVENT_FIELDS}
        unflagged = Unflagged(ev["phase_resets_per_hour"], ev["unflagged_slips_per_hour"], ev["data_gaps_per_hour"],
                              self.wavelength_m, np.array([x.announced for x in self.receiver_events], bool))
        # their own stream: a scenario without them draws exactly what it drew before
        rng_unflagged = np.random.default_rng([sc.seed, 0x0F1A]) if unflagged.any else None
        self.tracking = Tracking(shape, self.dt, ev["cycle_slips_per_hour"], errs.half_cycle, rng_track,
                                 unflagged, rng_unflagged)
        self._next_epoch = 0

    # -- set-up ---------------------------------------------------------------------------------
    def _build_receivers(self) -> list[Receiver]:
        sc = self.scenario
        out = []
        t_rel = self.t_tags - self.t0
        outage_faults = {}
        for f in sc.faults:
            if f.kind == "station_outage":
                until = f.until_s if f.until_s is not None else sc.duration_s
                outage_faults.setdefault(f.station, []).append((f.at_s, until))
        for i, st in enumerate(sc.stations):
            if st.km is not None:
                enu = self.track.station_point(st.km, st.offset_m, st.mast_m)
                ecef = self.track.plane_to_ecef(enu)
            else:
                ecef = geodetic_deg_to_ecef(st.lat_deg, st.lon_deg, st.h_m)
            out_mask = np.zeros(self.n_epochs, bool)
            for a, b in list(st.outages) + outage_faults.get(st.id, []):
                out_mask |= (t_rel >= a) & (t_rel < b)
            out.append(Receiver(st.id, "station", st.station_id if st.station_id is not None else i + 1,
                                st.grade, np.broadcast_to(ecef, (self.n_epochs, 3)).copy(),
                                np.zeros((self.n_epochs, 3)), outage=out_mask))
        for j, tr in enumerate(sc.trains):
            if tr.route:
                out.extend(self._route_receivers(tr, j, t_rel))
                continue
            m = train_motion(tr, self.track.length_m, t_rel)
            off = self.track.track_offset_m(tr.track)
            enu = self.track.point(m.s_m, off, tr.antenna_height_m)
            ecef = self.track.plane_to_ecef(enu)
            step = 0.5  # m, for the direction of motion
            ahead = self.track.plane_to_ecef(self.track.point(m.s_m + tr.direction * step, off,
                                                              tr.antenna_height_m))
            unit = ahead - ecef
            unit /= np.maximum(np.linalg.norm(unit, axis=1, keepdims=True), 1e-12)
            vel = unit * m.speed_m_s[:, None]
            prev = np.concatenate([[m.s_m[0]], m.s_m[:-1]])
            swept, wall = self.track.blockage_mask_deg(prev, m.s_m)
            llh0 = ecef_to_geodetic(ecef)
            v_enu = np.einsum("eij,ej->ei", enu_rotation(llh0[:, 0], llh0[:, 1]), unit)
            heading = np.arctan2(v_enu[:, 0], v_enu[:, 1])
            out.append(Receiver(tr.id, "train", 3000 + j, tr.grade, ecef, vel,
                                track_id=self.track.track_id(tr.track), km=m.s_m / 1e3,
                                speed_m_s=m.speed_m_s, swept_mask_deg=swept, cutting_deg=wall,
                                heading_rad=heading,
                                outage=np.zeros(self.n_epochs, bool)))
        return out

    def _route_receivers(self, tr, j: int, t_rel: np.ndarray) -> list[Receiver]:
        """A train running its route over the layout: speed limited by the line speed, the scenario's
        restrictions (by km) and the curves (stations.layout.LATERAL_ACCEL_M_S2); it stops at the route's end.
        With a rear antenna the train stands with its rear at start_km (the head `length_m` ahead) and a second
        receiver `<id>.rear` (kind REAR_KIND) runs `length_m` behind the head, or, after a `train_split`, slows
        at the fault's deceleration to a stand."""
        spacing = float(tr.length_m or DEFAULT_TRAIN_LENGTH_M) if tr.rear_antenna else 0.0
        route, um, v = route_motion(self.layout, tr, t_rel, spacing)
        self.routes[tr.id] = route
        out = [self._on_route(tr, tr.id, "train", 3000 + j, route, um, v)]
        if tr.rear_antenna:
            split = next((f for f in self.scenario.faults if f.kind == "train_split" and f.train == tr.id), None)
            # the motion is on the scenario's clock (WarmUpWorld delays it), the faults on the world's
            ur, vr = rear_motion(t_rel, um, v, spacing, split, getattr(self, "warm_up_s", 0.0))
            out.append(self._on_route(tr, f"{tr.id}{REAR_SUFFIX}", REAR_KIND, 4000 + j, route, ur, vr))
        return out

    def _on_route(self, tr, rid: str, kind: str, rtcm_id: int, route, um: np.ndarray, v: np.ndarray) -> Receiver:
        xy, z, km, ei, _ = route.at(um)
        ecef = self.layout.plane_to_ecef(xy, z + tr.antenna_height_m)
        xy2, z2, *_ = route.at(um + 0.5)  # 0.5 m ahead: the direction of motion
        ahead = self.layout.plane_to_ecef(xy2, z2 + tr.antenna_height_m)
        unit = ahead - ecef
        unit /= np.maximum(np.linalg.norm(unit, axis=1, keepdims=True), 1e-12)
        llh0 = ecef_to_geodetic(ecef)
        v_enu = np.einsum("eij,ej->ei", enu_rotation(llh0[:, 0], llh0[:, 1]), unit)
        zeros = np.zeros(self.n_epochs)
        edges = np.array(route.edges, dtype=object)[ei]
        return Receiver(rid, kind, rtcm_id, tr.grade, ecef, unit * v[:, None],
                        track_id=self.layout.edges[route.edges[0]].track, km=km, speed_m_s=v,
                        swept_mask_deg=zeros.copy(), cutting_deg=zeros.copy(),
                        heading_rad=np.arctan2(v_enu[:, 0], v_enu[:, 1]), outage=np.zeros(self.n_epochs, bool),
                        edge=edges, route_m=um)

    def _region_centre(self):
        pts = np.concatenate([r.ecef[:1] for r in self.receivers])
        llh = ecef_to_geodetic(pts)
        return float(np.degrees(llh[:, 0].mean())), float(np.degrees(llh[:, 1].mean()))

    def published_position(self, receiver_id: str) -> np.ndarray:
        """The coordinates a station publishes (RTCM 1005, the centre's station list) [ECEF m]: its true antenna
        position, unless a `station_coordinates` fault puts them `offset_enu_m` off (a survey or datum error)."""
        r = self.receivers[self.receiver_ids.index(receiver_id)]
        p = r.ecef[0].copy()
        for f in self.scenario.faults:
            if f.kind == "station_coordinates" and f.station == receiver_id:
                llh = ecef_to_geodetic(p)
                p = p + enu_rotation(llh[0], llh[1]).T @ np.asarray(f.offset_enu_m, float)
        return p

    @property
    def receiver_ids(self) -> list[str]:
        return [r.id for r in self.receivers]

    # -- simulation -----------------------------------------------------------------------------
    def epochs(self, block: int = BLOCK_EPOCHS):
        """Yield EpochBlocks from the current epoch to the end of the scenario."""
        while self._next_epoch < self.n_epochs:
            e0 = self._next_epoch
            e1 = min(e0 + block, self.n_epochs)
            yield self._block(e0, e1)
            self._next_epoch = e1

    def run(self, block: int = BLOCK_EPOCHS) -> list[EpochBlock]:
        return list(self.epochs(block))

    def _block(self, e0: int, e1: int) -> EpochBlock:
        E = e1 - e0
        R = len(self.receivers)
        N = len(self.sats)
        K = self.K
        c = SPEED_OF_LIGHT_M_S
        t_tag = self.t_tags[e0:e1]
        rx = np.stack([r.ecef[e0:e1] for r in self.receivers], axis=1)  # (E, R, 3)
        rx_vel = np.stack([r.velocity[e0:e1] for r in self.receivers], axis=1)
        dtr, dtr_dot = self.clocks.block(E)
        t_rx = t_tag[:, None] - dtr  # true reception time (E, R)

        # satellites: truth = full-precision orbit and clock + error (the broadcast sets are these
        # rounded to the ICD resolution); valid where a broadcast set exists
        idx = self.truth_nav.select(self.sats, t_tag)  # (E, N)
        valid = np.broadcast_to(((idx >= 0) & (self.nav.select(self.sats, t_tag) >= 0))[:, None, :], (E, R, N))
        rows = self.truth_nav.table.take(np.broadcast_to(np.maximum(idx, 0)[:, None, :], (E, R, N)))
        sat_idx = np.broadcast_to(np.arange(N), (E, R, N))
        tau = np.full((E, R, N), NOMINAL_TRANSIT_S)
        t_rx3 = np.broadcast_to(t_rx[:, :, None], (E, R, N))
        err_t = t_rx3 - NOMINAL_TRANSIT_S
        for it in range(TRANSIT_ITERATIONS + 1):
            st = satellite_state(rows, t_rx3, -tau)
            if it == 0:
                d_orbit = self.orbit_errors.ecef_m(sat_idx, err_t, st.position_m, st.velocity_m_s)
            pos = st.position_m + d_orbit
            ang = self.omge * tau
            ca, sa = np.cos(ang), np.sin(ang)
            rot = np.stack([pos[..., 0] * ca + pos[..., 1] * sa, -pos[..., 0] * sa + pos[..., 1] * ca,
                            pos[..., 2]], axis=-1)
            los = rot - rx[:, :, None, :]
            rng = np.linalg.norm(los, axis=-1)
            tau = rng / c
        u = los / rng[..., None]
        # Range rate in the receive-time frame: the satellite velocity turned like its position,
        # and the transmit time moving with the range, d(t - tau)/dt = 1 - d(tau)/dt.
        v = st.velocity_m_s
        v_rot = np.stack([v[..., 0] * ca + v[..., 1] * sa, -v[..., 0] * sa + v[..., 1] * ca, v[..., 2]], axis=-1)
        d_rot = np.stack([rot[..., 1], -rot[..., 0], np.zeros_like(rng)], axis=-1)  # d(rot)/d(angle)
        tau_dot = np.einsum("erni,erni->ern", u, v_rot - rx_vel[:, :, None, :]) / c
        vel = v_rot * (1.0 - tau_dot)[..., None] + (self.omge * tau_dot)[..., None] * d_rot
        range_rate = np.einsum("erni,erni->ern", u, vel - rx_vel[:, :, None, :])
        dts = st.clock_bias_s + self.orbit_errors.clock_s(sat_idx, err_t)
        dts_dot = st.clock_drift_s_s
        # truth minus broadcast, as a user of the broadcast sets meets it: the drawn error plus the
        # rounding of the broadcast parameters (cm, a fraction of a ns)
        b_idx = self.nav.select(self.sats, t_tag)
        b_rows = self.nav.table.take(np.broadcast_to(np.maximum(b_idx, 0)[:, None, :], (E, R, N)))
        st_b = satellite_state(b_rows, t_rx3, -tau)
        # satellite group delays as broadcast (TGD/BGD; zero in the nominal constellation): the code
        # of signal k is late by them, exactly as a single-frequency user corrects it
        group = np.zeros((E, R, N, K))
        for sysl in np.unique(self.sat_system):
            cols = self.sat_system == sysl
            for k, code in enumerate(self.scenario.signals[sysl]):
                gd = group_delay_s(b_rows, code)
                group[..., k] = np.where(cols & ~np.isnan(gd), gd * c, group[..., k])
        dclk_err = dts - st_b.clock_bias_s
        orbit_err_range = np.einsum("erni,erni->ern", u, pos - st_b.position_m)

        # receiver geodetic, ENU, azimuth/elevation
        llh = ecef_to_geodetic(rx)  # (E, R, 3)
        rot_enu = enu_rotation(llh[..., 0], llh[..., 1])  # (E, R, 3, 3)
        enu = np.einsum("erij,ernj->erni", rot_enu, u)
        el = np.arcsin(np.clip(enu[..., 2], -1, 1))
        az = np.mod(np.arctan2(enu[..., 0], enu[..., 1]), 2 * np.pi)
        el_safe = np.maximum(el, np.radians(1.0))

        # atmosphere, and its rate (the Doppler is the whole phase rate, atmosphere included):
        # evaluated again +-ATMO_RATE_STEP_S along the satellite's apparent motion in the sky
        lat = np.broadcast_to(llh[..., 0][..., None], (E, R, N))
        lon = np.broadcast_to(llh[..., 1][..., None], (E, R, N))
        v_rel = vel - rx_vel[:, :, None, :]
        u_dot = (v_rel - u * np.einsum("erni,erni->ern", u, v_rel)[..., None]) / rng[..., None]
        enu_dot = np.einsum("erij,ernj->erni", rot_enu, u_dot)
        el_dot = enu_dot[..., 2] / np.maximum(np.cos(el), 1e-6)
        horiz = np.maximum(np.hypot(enu[..., 0], enu[..., 1]), 1e-9)
        az_dot = (enu[..., 1] * enu_dot[..., 0] - enu[..., 0] * enu_dot[..., 1]) / horiz**2

        def atmosphere(el_a, az_a, dt_s):
            el_a = np.maximum(el_a, np.radians(1.0))
            stec_a = self.iono.slant_tec_tecu(lat, lon, az_a, el_a, t_rx3 + dt_s)
            if not self.tropo_enabled:
                return stec_a, np.zeros((E, R, N))
            zhd, zwd = zenith_delays_m(llh[..., 0], llh[..., 2])
            zwd = zwd + self.wet.zwd_residual_m(llh[..., 0], llh[..., 1], llh[..., 2], t_rx + dt_s)
            mh, mw = niell(el_a, lat, llh[..., 2][..., None], self.doy)
            return stec_a, zhd[..., None] * mh + zwd[..., None] * mw

        stec, tropo = atmosphere(el, az, 0.0)
        h = ATMO_RATE_STEP_S
        stec_p, tropo_p = atmosphere(el + el_dot * h, az + az_dot * h, h)
        stec_m, tropo_m = atmosphere(el - el_dot * h, az - az_dot * h, -h)
        stec_rate = (stec_p - stec_m) / (2 * h)
        tropo_rate = (tropo_p - tropo_m) / (2 * h)
        iono = delay_m(stec[..., None], self.freq_hz[None, None])  # (E, R, N, K)
        iono_rate = delay_m(stec_rate[..., None], self.freq_hz[None, None])

        el_scale = elevation_scale(el_safe)  # (E, R, N)
        cnr = cnr_dbhz(self.cnr_zenith[None, :, None], el_safe, K)

        # visibility: mask, ephemeris, blockage, outage
        mask = np.radians(self.scenario.elevation_mask_deg)
        hidden = np.zeros((E, R, N), bool)
        outage = np.zeros((E, R), bool)
        for i, r in enumerate(self.receivers):
            if r.swept_mask_deg is not None:
                wall = cutting_mask_rad(r.cutting_deg[e0:e1, None], az[:, i], r.heading_rad[e0:e1, None])
                hidden[:, i] = (r.swept_mask_deg[e0:e1, None] >= 90.0) | (el[:, i] < wall)
            outage[:, i] = r.outage[e0:e1]
        visible = valid & (el >= mask) & ~hidden & ~outage[:, :, None]

        # sequential part: tracking (arcs, slips), AR(1) multipath, white noise
        P = np.full((E, R, N, K), np.nan)
        L = np.full((E, R, N, K), np.nan)
        D = np.full((E, R, N, K), np.nan)
        S = np.full((E, R, N, K), np.nan)
        lli = np.zeros((E, R, N, K), np.int8)
        lock = np.full((E, R, N, K), np.nan)
        amb = np.full((E, R, N, K), np.nan)
        mpc_out = np.zeros((E, R, N, K))
        mpp_out = np.zeros((E, R, N, K))
        lam = self.wavelength_m
        geo = rng + c * (dtr[:, :, None] - dts) + tropo  # non-dispersive part (E, R, N)
        phase_rate = (range_rate + c * (dtr_dot[:, :, None] - dts_dot) + tropo_rate)[..., None] - iono_rate
        doppler_noise = DOPPLER_NOISE_HZ * (self.sigma_phase > 0)[:, None, None]
        for e in range(E):
            mp_c, mp_p, n_c, n_p, z_dop = self.noise.step(el_scale[e])
            trk = self.tracking.step(visible[e])
            obs = visible[e][..., None] & self.signal_exists[None]
            if trk.dropped is not None:
                obs = obs & ~trk.dropped[..., None]
            ge = geo[e][..., None]
            for row, a, b, code_m, phase_m, sign in self.bursts:  # injected multipath bursts (truth side)
                if a <= t_tag[e] < b:
                    mp_c = mp_c.copy()
                    mp_p = mp_p.copy()
                    mp_c[row] += code_m * sign[:, None]
                    mp_p[row] += phase_m * sign[:, None]
            P[e] = np.where(obs, ge + iono[e] + group[e] + mp_c + n_c, np.nan)
            L[e] = np.where(obs, (ge - iono[e] + mp_p + n_p) / lam + trk.ambiguity_cyc + trk.half_cycle, np.nan)
            D[e] = np.where(obs, -phase_rate[e] / lam + doppler_noise * z_dop, np.nan)
            S[e] = np.where(obs, cnr[e], np.nan)
            lli[e] = np.where(obs, trk.lli, 0)
            lock[e] = np.where(obs, trk.lock_time_s, np.nan)
            amb[e] = np.where(obs, trk.ambiguity_cyc, np.nan)
            mpc_out[e] = np.where(obs, mp_c, 0.0)
            mpp_out[e] = np.where(obs, mp_p, 0.0)
        observed = ~np.isnan(P)
        if not self.scenario.errors.noise.enabled:
            S = np.round(S)  # keep C/N0 deterministic and on the RINEX/RTCM grid
        return EpochBlock(
            t_gpst=t_tag, epoch_index=np.arange(e0, e1), pseudorange_m=P, phase_cyc=L, doppler_hz=D,
            cnr_dbhz=S, lli=lli, lock_time_s=lock, observed=observed, rx_ecef=rx, rx_clock_s=dtr,
            elevation_rad=el, azimuth_rad=az, range_m=rng, sat_clock_s=dts, sat_clock_error_s=dclk_err,
            orbit_error_range_m=orbit_err_range, stec_tecu=stec, tropo_m=tropo, ambiguity_cyc=amb,
            multipath_code_m=mpc_out, multipath_phase_m=mpp_out)

