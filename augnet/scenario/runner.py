"""`augnet scenario run`: the whole chain in one process, faster than real time, against the truth.

    World (stations/)  --station RTCM 3 bytes-->  CentreEngine (augnet.centre)  --VRS RTCM 3 bytes per train-->
    CorrectionDecoder + OnboardUnit (augnet.onboard)  --solution, map match, balise captures-->  comparison

What travels between the parts is what travels in the live system: each reference station's RTCM stream
(`stations.rtcm_stream.RtcmStreams`), the centre's VRS stream per train (the session's sink), the
train's GGA back to the centre. The train's own receiver output goes straight into its positioning core.
Only the sockets are gone; their delays come from `latency.LatencyModel`.

The VRS session moves with the train as the live system moves it: the train sends a GGA sentence of its
own solution every `GGA_INTERVAL_S` (the onboard NTRIP client's default), and the caster's
`RepositionPolicy` decides when the session's point follows (at most every 10 s, after 10 m of
movement). The VRS inherits its master station's ambiguities, so a moved VRS is the same base at a new
point (Wanninger's semi-kinematic VRS): the onboard filter takes the new coordinates and keeps its
ambiguities (`move_base`); a new master restarts every lock time in the stream, which the rover's slip
detection sees. A new VRS station id (a new session) restarts the filter.

Warm-up: the reference stations and the centre start `warm_up_s` (default `DEFAULT_WARM_UP_S` when the scenario
has trains) before the scenario's start, its trains' time 0; the trains' receivers and onboard units are
switched on at time 0. That is how a train meets the network in service: the centre runs for months, trains
switch on and connect to it. The centre's own cold start is not hidden by it: the baselines' fix times are
measured from the centre's start (`RunLog.warm_up_s` before time 0), and a run with `warm_up_s=0` starts the
centre and the trains together (every train's first fix then waits for the network's). `WarmUpWorld` keeps
the scenario's sky, faults and train motion on the scenario's own clock (see there).

The truth is read only by `truth.py` and by the evaluation here (`_evaluate_*`), never handed to the
centre or the onboard unit.
"""

from __future__ import annotations

import collections
import dataclasses
import datetime as _dt
import math
import time as wallclock
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from augnet.centre.engine import CentreEngine, EpochReport
from augnet.centre.vrs import synthesize
from augnet.gnss import time as gtime
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData
from augnet.onboard.along_track_fusion import METHODS, AlongTrackFix, AlongTrackFusion, FusedPosition, FusionSettings
from augnet.onboard.balise import BaliseEvent, ListSink
from augnet.onboard.balise_timer import BaliseGroup, ListTimerSink, TimedBaliseDetector
from augnet.onboard.corrections import CorrectionDecoder
from augnet.onboard.ntrip_client import DEFAULT_GGA_INTERVAL_S
from augnet.onboard.observations import EpochObs
from augnet.onboard.odometer import OdometerModel
from augnet.onboard.rtk import RtkOptions, Status
from augnet.onboard.trackmap import DEFAULT_INTEGRITY_RISK, TrackDatabase, gaussian_k
from augnet.onboard.unit import OnboardUnit
from augnet.scenario.latency import LatencyModel
from augnet.scenario.observations import RoverObservations, StationObservations
from augnet.scenario.truth import TruthIndex
from augnet.track.topology import Topology
from augnet.track.train_integrity import AntennaFix, IntegrityMonitor, IntegrityState
from ntrip_caster.gga import parse_gga
from ntrip_caster.reposition import RepositionPolicy
from stations import constellation as const
from stations.odometer import OdometerStreams, simulate_odometers
from stations.rtcm_stream import RtcmStreams
from stations.scenario import Scenario, ScenarioError, load_scenario
from stations.trackmap_export import track_database
from stations.world import DEFAULT_TRAIN_LENGTH_M, REAR_KIND, REAR_SUFFIX, EpochBlock, Receiver, World

GGA_INTERVAL_S = DEFAULT_GGA_INTERVAL_S  # the onboard NTRIP client's GGA upload period
# Receivers whose id starts with this are check points (static receivers at surveyed points inside the
# network, as in network-70km): not network stations; the interpolation is evaluated at them.
CHECK_POINT_PREFIX = "check"
TRUTH_EPOCHS_KEPT = 8  # network epochs are released within a few epochs of their tag (aligner wait 1 s)
# How long the reference stations and the centre run before the trains' time 0 (scenarios with trains; see
# the module docstring): trains meet a centre in service (which runs for months), runs stay short
# (docs/decisions/0010-scenario-warm-up.md).
DEFAULT_WARM_UP_S = 300.0


def load(scenario: str | Path | Scenario, duration_s: float | None = None) -> Scenario:
    """A scenario by built-in name, YAML path or object, optionally shortened (ScenarioError naming it)."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if duration_s is not None:
        if not duration_s > 0:
            raise ScenarioError(f"scenario {sc.name}: duration must be positive, got {duration_s}")
        sc = sc.model_copy(update={"duration_s": float(duration_s)})
    return sc


def warm_up_s_for(sc: Scenario, warm_up_s: float | None) -> float:
    """The warm-up a run of `sc` uses: `warm_up_s`, or by default `DEFAULT_WARM_UP_S` when the scenario has trains
    (nothing connects to the centre otherwise: a run without trains is the centre's own cold start), in whole
    epochs."""
    if warm_up_s is None:
        warm_up_s = DEFAULT_WARM_UP_S if sc.trains else 0.0
    if not (math.isfinite(warm_up_s) and warm_up_s >= 0.0):
        raise ScenarioError(f"scenario {sc.name}: warm-up must be zero or positive seconds, got {warm_up_s}")
    return round(warm_up_s * sc.rate_hz) * sc.interval_s


def _on_world_clock(sc: Scenario, warm_up_s: float) -> Scenario:
    """`sc` begun `warm_up_s` earlier: faults and station outages keep their times since the scenario's start."""
    if not warm_up_s:
        return sc
    faults = [f.model_copy(update={"at_s": f.at_s + warm_up_s,
                                   "until_s": None if f.until_s is None else f.until_s + warm_up_s})
              for f in sc.faults]
    stations = [st.model_copy(update={"outages": [(a + warm_up_s, b + warm_up_s) for a, b in st.outages]})
                for st in sc.stations]
    return sc.model_copy(update={"start": sc.start - _dt.timedelta(seconds=warm_up_s),
                                 "duration_s": sc.duration_s + warm_up_s, "faults": faults, "stations": stations})


class WarmUpWorld(World):
    """The scenario's world begun `warm_up_s` before the scenario's start (`start_gpst`), the reference stations
    observing throughout; everything the scenario times keeps the scenario's clock:

    - the trains' receivers are switched off during the warm-up (no observation; they acquire at time 0 as in a
      cold world) and stand at their start point; from time 0 they move exactly as the scenario says;
    - the nominal constellation stays placed at the scenario's start, so the sky at every scenario epoch is the
      one a world begun at the start has (orbits, broadcast sets and truth are propagated back over the
      warm-up);
    - faults and station outages keep their times since the scenario's start.

    Random draws (noise, multipath, clocks, slips, new-arc ambiguities) come from the same seeded streams, now
    also drawn during the warm-up, so their realisation after time 0 is another one than without warm-up.
    With `warm_up_s == 0` it is the plain `World`."""

    def __init__(self, scenario: Scenario, warm_up_s: float = 0.0):
        self.warm_up_epochs = int(round(warm_up_s * scenario.rate_hz))
        self.warm_up_s = self.warm_up_epochs * scenario.interval_s
        self.start_gpst = float(gtime.from_datetime(scenario.start))
        super().__init__(_on_world_clock(scenario, self.warm_up_s))
        if self.warm_up_epochs and self.nominal:
            t_end = float(self.t_tags[-1])
            self.orbits = const.nominal_orbits(scenario.constellations, self.start_gpst, scenario.seed)
            self.ephemerides = const.broadcast_ephemerides(self.orbits, self.t0, t_end)
            self.nav = NavigationData(self.ephemerides)
            self.truth_nav = NavigationData(const.broadcast_ephemerides(self.orbits, self.t0, t_end, quantised=False))
            if [s for s in self.nav.satellites if s[0] in scenario.constellations] != self.sats:
                raise RuntimeError("the constellation placed at the scenario's start has other satellites")

    def _build_receivers(self) -> list[Receiver]:
        out = super()._build_receivers()
        n = self.warm_up_epochs
        if not n:
            return out

        def later(a: np.ndarray, standing=None) -> np.ndarray:
            """`a` (per epoch, from the world's start) delayed by the warm-up; `standing` (or a[0]) before."""
            b = np.empty_like(a)
            b[n:] = a[:len(a) - n]
            b[:n] = a[0] if standing is None else standing
            return b

        for r in out:
            if r.kind not in ("train", REAR_KIND):
                continue
            # super() moved the train from the world's start; move it from the scenario's start instead
            r.ecef = later(r.ecef)
            r.velocity = later(r.velocity, 0.0)
            r.km = later(r.km)
            r.speed_m_s = later(r.speed_m_s, 0.0)
            r.swept_mask_deg = later(r.swept_mask_deg)
            r.cutting_deg = later(r.cutting_deg)
            r.heading_rad = later(r.heading_rad)
            r.outage = later(r.outage, True)  # switched off until time 0
            if r.edge is not None:  # a layout route: the train stands at its start during the warm-up
                r.edge = later(r.edge)
                r.route_m = later(r.route_m)
        return out


def move_base(unit: OnboardUnit, position_m: np.ndarray) -> bool:
    """The same VRS at a new point: new base coordinates, ambiguities kept (see the module docstring).
    Returns True if the position changed."""
    p = np.asarray(position_m, float)
    if np.allclose(p, unit.rtk.base_position_m, atol=1e-3):
        return False
    unit.rtk.base_position_m = p
    return True


def vrs_ionosphere_m(vrs_phase_cyc: np.ndarray, master_phase_cyc: np.ndarray, freq_hz: np.ndarray) -> np.ndarray:
    """The ionosphere on f1 [m] a VRS carries relative to its master station, per satellite, read from the two
    stations' dual-frequency phases (S, 2): in the geometry-free combination GF = lambda1 L1 - lambda2 L2 the
    geometric shift, the troposphere, clocks and the (inherited) ambiguities cancel, leaving
    GF_vrs - GF_master = (mu_2 - 1) dI with mu_2 = (f1 / f2)^2 (augnet.centre.vrs's VRS equation)."""
    f = np.asarray(freq_hz, float)
    lam = SPEED_OF_LIGHT_M_S / f
    d = np.asarray(vrs_phase_cyc, float) - np.asarray(master_phase_cyc, float)
    return (lam[:, 0] * d[:, 0] - lam[:, 1] * d[:, 1]) / ((f[:, 0] / f[:, 1]) ** 2 - 1.0)


@dataclass
class TrainLog:
    """One train, epoch by epoch: the unit's outputs beside the truth (kept in separate fields)."""

    id: str
    truth_track: str
    t_s: list[float] = field(default_factory=list)  # since the scenario start
    status: list[int] = field(default_factory=list)
    n_tracked: list[int] = field(default_factory=list)  # satellites the train receiver tracked (0: tunnel)
    position: list[np.ndarray] = field(default_factory=list)  # estimate, ECEF (NaN when none)
    covariance: list[np.ndarray] = field(default_factory=list)
    age_s: list[float] = field(default_factory=list)  # correction age at the rover (NaN: none)
    base_sats: list[int] = field(default_factory=list)  # satellites in the VRS epoch used
    vrs_master: list[str] = field(default_factory=list)  # the master station of the VRS epoch used
    track: list[str] = field(default_factory=list)  # matched track ('' when none)
    km: list[float] = field(default_factory=list)  # matched chainage [km] (NaN when none)
    confirmed: list[bool] = field(default_factory=list)
    along_pl_m: list[float] = field(default_factory=list)
    cross_pl_m: list[float] = field(default_factory=list)
    # the centre's 4001 correction-error sigma on each axis in those PLs [m] (0: none received, inf: unbounded)
    correction_along_m: list[float] = field(default_factory=list)
    correction_cross_m: list[float] = field(default_factory=list)
    along_sigma_m: list[float] = field(default_factory=list)  # the 1-sigma each PL was made from [m]
    cross_sigma_m: list[float] = field(default_factory=list)
    message: list[str] = field(default_factory=list)
    truth_position: list[np.ndarray] = field(default_factory=list)  # truth, ECEF
    truth_km: list[float] = field(default_factory=list)  # truth chainage of the antenna
    truth_edge: list[str] = field(default_factory=list)  # layout scenarios: the true edge of each epoch
    truth_route_m: list[float] = field(default_factory=list)  # layout scenarios: distance along the route [m]
    events: list[BaliseEvent] = field(default_factory=list)
    # along-track fusion of the GNSS fixes with the odometer, per method (augnet.onboard.along_track_fusion)
    fused: dict[str, list[FusedPosition]] = field(default_factory=dict)
    # timer-based virtual balise passages from the weighted median (augnet.onboard.balise_timer)
    timed_balises: ListTimerSink = field(default_factory=ListTimerSink)
    # train integrity (Train.rear_antenna): the rear antenna's map match and the monitor's state per epoch
    length_m: float = math.nan  # train data: the antenna spacing the monitor checks
    rear_track: list[str] = field(default_factory=list)
    rear_km: list[float] = field(default_factory=list)
    rear_status: list[int] = field(default_factory=list)
    rear_along_pl_m: list[float] = field(default_factory=list)
    integrity: list[IntegrityState] = field(default_factory=list)
    truth_rear_route_m: list[float] = field(default_factory=list)  # truth: the rear antenna's route distance
    session_opened_s: float = math.nan
    vrs_moves: int = 0
    gga_sent: int = 0


@dataclass
class BaselineLog:
    name: str
    station_a: str
    station_b: str
    length_m: float
    t_s: list[float] = field(default_factory=list)
    fixed_fraction: list[float] = field(default_factory=list)
    checked: int = 0  # fixed DD ambiguity-epochs compared with the truth
    wrong: int = 0
    wrong_examples: list[tuple[float, str]] = field(default_factory=list)
    arc_start: dict[str, float] = field(default_factory=dict)  # satellite -> first epoch seen [s]
    time_to_fix: dict[str, float] = field(default_factory=dict)  # satellite -> first fixed minus arc start


@dataclass
class RunLog:
    scenario: Scenario
    trains: dict[str, TrainLog]
    baselines: dict[str, BaselineLog]
    interpolation: dict[str, list[float]]  # point -> DD ionosphere errors [m] (predicted minus truth)
    interpolation_floor: dict[str, list[float]]  # the same from the truth's station residuals
    stations: dict[str, np.ndarray]
    check_points: dict[str, np.ndarray]
    track_db: TrackDatabase
    latency: dict
    line_llh: np.ndarray | None
    blockages: list[dict]
    network_epochs: int = 0  # from the centre's start (the warm-up's included)
    epochs: int = 0  # the scenario's
    warm_up_s: float = 0.0  # the stations and the centre started this long before the scenario (t0)
    world_epochs: int = 0  # simulated, the warm-up's included
    wall_s: float = 0.0
    age_limit_s: float = 0.0
    integrity_risk: float = DEFAULT_INTEGRITY_RISK
    min_rtk_satellites: int = 5
    t0: float = 0.0  # the scenario's start [GPST s]: the trains' time 0
    line_length_m: float = math.nan
    series: dict = field(default_factory=dict)  # per-epoch figures, filled by report.build


@dataclass
class _Train:
    log: TrainLog
    row: int  # receiver row in the world
    unit: OnboardUnit
    decoder: CorrectionDecoder
    inbox: collections.deque  # (arrival time, bytes), in arrival order (one TCP stream)
    policy: RepositionPolicy
    fusions: dict[str, AlongTrackFusion] = field(default_factory=dict)
    timer: TimedBaliseDetector | None = None
    rear_row: int | None = None  # the rear antenna's receiver row (Train.rear_antenna)
    rear_unit: OnboardUnit | None = None  # its positioning, on the same corrections as the head's
    integrity: IntegrityMonitor | None = None
    base: EpochObs | None = None
    base_station_id: int | None = None
    last_gga_t: float = -math.inf
    last_arrival: float = -math.inf
    session: bool = False


class Chain:
    """The system under test wired in-process, fed one simulator block at a time."""

    def __init__(self, world: WarmUpWorld, scenario: Scenario, options: RtkOptions | None = None,
                 correction_bound: bool = False, fusion: dict | None = None):
        self.world = world
        self.scenario = sc = scenario
        self.t0 = world.start_gpst  # the scenario's start: the trains' time 0
        self.warm_up_s = world.warm_up_s  # the centre starts this long before it (world.t0)
        self.latency = LatencyModel(sc.seed)
        self.options = options or RtkOptions()
        self.truth = TruthIndex(world)
        self.rover_obs = RoverObservations(world)
        self.station_obs = StationObservations(world)
        self.streams = RtcmStreams(world)
        self.streams.keep_epochs = True
        rx = world.receivers
        self.station_names = [r.id for r in rx if r.kind == "station" and not r.id.startswith(CHECK_POINT_PREFIX)]
        if len(self.station_names) < 1:
            raise ScenarioError(f"scenario {sc.name}: no reference stations")
        # the coordinates the stations publish (a station_coordinates fault puts them off the truth)
        self.stations = {r.id: world.published_position(r.id) for r in rx if r.id in self.station_names}
        self.check_points = {r.id: r.ecef[0].copy() for r in rx
                             if r.kind == "station" and r.id.startswith(CHECK_POINT_PREFIX)}
        # correction_bound: the VRS carry the centre's 4001 bound, which the trains take into their PLs (0281)
        self.engine = CentreEngine(self.stations, world.t0, network_name=sc.name, correction_bound=correction_bound)
        self.track_db = None
        self.topology = None
        if world.layout is not None:
            # the as-built layout exported from the simulator's truth (as track_database does for a line)
            self.topology = Topology.from_dict(world.layout.truth_topology_dict())
            self.track_db = TrackDatabase.from_dict(self.topology.to_track_database_dict())
        elif sc.line is not None:
            self.track_db = TrackDatabase.from_dict(track_database(sc))
        self.trains: dict[str, _Train] = {}
        # the simulated odometers (world clock, so an odometer_slide keeps its scenario time); truth kept inside
        trains_rx = [r for r in rx if r.kind == "train"]
        self.odometers: OdometerStreams | None = None
        if trains_rx:
            self.odometers = simulate_odometers(world.scenario, world.t_tags - world.t0,
                                                np.array([r.km for r in trains_rx]),
                                                np.array([r.speed_m_s for r in trains_rx]))
        train_cfg = {t.id: t for t in sc.trains}
        for i, r in enumerate(rx):
            if r.kind != "train":
                continue
            unit = OnboardUnit(world.nav, np.zeros(3), self.track_db, ListSink(), dataclasses.replace(self.options))
            # the base is the centre's VRS (the train connects to the VRS mountpoint): a computed station whose
            # residual atmosphere the filter models (RtkFilter's ionosphere-weighted mode)
            unit.rtk.base_is_vrs = True
            log = TrainLog(r.id, r.track_id)
            log.events = unit.sink.events
            cfg = train_cfg[r.id]
            # the onboard knows its tachometer and its orientation on the journey, not the wheel's true radius
            odo_model = OdometerModel(pulses_per_rev=cfg.odometer_pulses_per_rev, sample_interval_s=sc.interval_s)
            # `fusion`: FusionSettings fields to override (a campaign's detection-disabled control run)
            settings = FusionSettings(**{"direction": cfg.direction, "integrity_risk": unit.integrity_risk,
                                         **(fusion or {})})
            fusions = {m: AlongTrackFusion(m, odo_model, settings) for m in METHODS}
            log.fused = {m: [] for m in METHODS}
            self.trains[r.id] = _Train(log, i, unit, CorrectionDecoder(), collections.deque(), RepositionPolicy(),
                                       fusions)
            if self.track_db is not None:
                # chainage [m] is the fused axis, so the groups are placed by chainage too
                groups = [BaliseGroup(b.id, b.track, b.km * 1000.0, b.telegram, b.linked) for b in self.track_db.balises]
                self.trains[r.id].timer = TimedBaliseDetector(groups, log.timed_balises,
                                                              k=gaussian_k(unit.integrity_risk))
        rows = {r.id: i for i, r in enumerate(rx)}
        for tid, tr in self.trains.items():
            i = rows.get(tid + REAR_SUFFIX)
            if i is None:
                continue
            cfg = train_cfg[tid]
            tr.rear_row = i
            tr.rear_unit = OnboardUnit(world.nav, np.zeros(3), self.track_db, ListSink(),
                                       dataclasses.replace(self.options))
            tr.rear_unit.rtk.base_is_vrs = True
            tr.log.length_m = float(cfg.length_m or DEFAULT_TRAIN_LENGTH_M)
            # the onboard map as a topology (the monitor walks its edges through the switches)
            tr.integrity = IntegrityMonitor(self.topology, tr.log.length_m, "up" if cfg.direction > 0 else "down")
        self.baselines = {s.name: BaselineLog(s.name, s.name_a, s.name_b, s.length_m)
                          for s in self.engine.network.solvers.values()}
        self.interpolation: dict[str, list[float]] = {p: [] for p in [*self.trains, *self.check_points]}
        self.interpolation_floor: dict[str, list[float]] = {p: [] for p in self.interpolation}
        self._truth_epochs: dict[float, tuple[EpochBlock, int]] = {}
        self._vrs_master: dict[float, dict[str, str]] = {}  # VRS epoch -> train -> its master station
        self._now = world.t0
        self.network_epochs = 0
        self.epochs = 0  # the scenario's (the trains') epochs
        self.world_epochs = 0  # with the warm-up's

    # --- one block ----------------------------------------------------------------------------------

    def add_block(self, blk: EpochBlock, on_epoch: Callable[[], None] | None = None) -> None:
        self.streams.add(blk)
        # the truth of the phases as streamed: MSM re-aligns a phase reset by kilometres (stations/rtcm_stream.py)
        truth_blk = dataclasses.replace(blk, ambiguity_cyc=self.streams.sent_ambiguity(blk))
        station_bytes = {}
        for name in self.station_names:
            station_bytes[name] = dict(self.streams.epoch_bytes[name])
        for buf in self.streams.epoch_bytes.values():
            buf.clear()
        for name in self.streams.buffers:
            self.streams.buffers[name] = bytearray()  # the runner does not write .rtcm3 files
        for e in range(len(blk.t_gpst)):
            t = float(blk.t_gpst[e])
            self._truth_epochs[round(t, 3)] = (truth_blk, e)
            while len(self._truth_epochs) > TRUTH_EPOCHS_KEPT:
                self._truth_epochs.pop(next(iter(self._truth_epochs)))
            # stations -> centre
            self._now = self.latency.station_arrival(t)
            for name in self.station_names:
                data = station_bytes[name].get(t)
                if data:
                    self.engine.feed(name, data, self._now)
            for rep in self.engine.tick(self._now):
                self._network_epoch(rep)
            self.world_epochs += 1
            if t < self.t0 - 1e-6:
                if on_epoch is not None:
                    on_epoch()
                continue  # the warm-up: the trains are switched off
            # trains: solve epoch t with what has arrived by t, then report the position upstream
            for tr in self.trains.values():
                self._train_epoch(tr, blk, e, t)
            self.epochs += 1
            if on_epoch is not None:
                on_epoch()

    # --- centre side --------------------------------------------------------------------------------

    def _sink(self, tr: _Train) -> Callable[[bytes], None]:
        def deliver(data: bytes) -> None:
            arrival = self._now + self.latency.processing_s + float(self.latency.downlink(1)[0])
            arrival = max(arrival, tr.last_arrival)  # one TCP stream: bytes arrive in order
            tr.last_arrival = arrival
            tr.inbox.append((arrival, data))
        return deliver

    def _network_epoch(self, rep: EpochReport) -> None:
        self.network_epochs += 1
        if rep.vrs is not None:
            self._vrs_master[round(rep.t_gpst, 3)] = dict(zip(self.engine.sessions, rep.vrs.master))
            while len(self._vrs_master) > 4 * TRUTH_EPOCHS_KEPT:
                self._vrs_master.pop(next(iter(self._vrs_master)))
        got = self._truth_epochs.get(round(rep.t_gpst, 3))
        if got is None:
            return
        blk, e = got
        t_s = rep.t_gpst - self.t0
        self._evaluate_baselines(rep, blk, e, t_s)
        self._evaluate_interpolation(rep, blk, e)

    def _evaluate_baselines(self, rep: EpochReport, blk: EpochBlock, e: int, t_s: float) -> None:
        amb = blk.ambiguity_cyc[e]
        for name, res in rep.network.baselines.items():
            log = self.baselines[name]
            if res is None:
                continue
            log.t_s.append(t_s)
            log.fixed_fraction.append(res.fixed_fraction)
            sats = res.sats.astype(str)
            seen = set(sats.tolist())
            for s in list(log.arc_start):
                if s not in seen and s not in log.time_to_fix:
                    del log.arc_start[s]  # the arc broke before it was fixed: a new arc starts later
            for s in sats:
                log.arc_start.setdefault(s, t_s)
            check = res.fixed & ~res.is_reference()
            if not check.any():
                continue
            truth = self.truth.dd_ambiguity(amb, log.station_a, log.station_b, sats[check], res.refs,
                                            res.freq_hz[check])
            est = res.dd_n[check]
            cells = np.isfinite(est) & np.isfinite(truth)
            wrong_sat = np.any(cells & (est != truth), axis=1)
            log.checked += int(check.sum())
            log.wrong += int(wrong_sat.sum())
            for s in sats[check][wrong_sat][:3]:
                if len(log.wrong_examples) < 20:
                    log.wrong_examples.append((t_s, str(s)))
            for s in sats[check]:
                if s not in log.time_to_fix:
                    log.time_to_fix[s] = t_s - log.arc_start[s]

    def _evaluate_interpolation(self, rep: EpochReport, blk: EpochBlock, e: int) -> None:
        """Interpolated DD ionosphere at each train's and check point's true position, against the truth;
        and the same interpolation fed the truth's station residuals (the model's own error floor)."""
        names = [n for n in self.interpolation if blk.observed[e, self.truth.rx_row[n]].any()]  # not in a tunnel
        ne = rep.network
        if not names or not len(ne.sats):
            return
        station_eps = {}
        for s in rep.stations:
            ep = self.station_obs.epoch(blk, e, self.truth.rx_row[s])
            if ep is not None:
                station_eps[s] = ep
        if not station_eps:
            return
        points = blk.rx_ecef[e, [self.truth.rx_row[n] for n in names]]
        for name, err in self._interpolation_errors(ne, station_eps, points, names, blk, e).items():
            self.interpolation[name].extend(err)
        f1 = self.world.freq_hz[np.maximum(self.truth.sat_cols(ne.sats), 0), 0]
        truth = np.array([self.truth.iono_f1_m(blk.stec_tecu[e], s, ne.sats, f1) for s in ne.stations])
        truth -= truth[0]  # against the network master (row 0)
        ref = np.array([list(ne.sats).index(ne.refs[x[0]]) if ne.refs.get(x[0]) in ne.sats else -1 for x in ne.sats])
        dd = np.where(ref >= 0, truth - truth[:, np.maximum(ref, 0)], np.nan)
        perfect = dataclasses.replace(ne, dd_iono_m=np.where(np.isfinite(ne.dd_iono_m), dd, np.nan))
        for name, err in self._interpolation_errors(perfect, station_eps, points, names, blk, e).items():
            self.interpolation_floor[name].extend(err)

    def _interpolation_errors(self, ne, station_eps, points, names, blk: EpochBlock, e: int) -> dict[str, list]:
        """DD ionosphere errors [m] (predicted minus truth, per system against its highest satellite) of a VRS
        synthesised for `points` (for this comparison only: the trains get theirs at their reported positions).
        The VRS's ionosphere relative to its master comes back out of the geometry-free combination, in which
        geometry, clocks and ambiguities cancel: GF_vrs - GF_master = (mu_2 - 1) dI, mu_2 = (f1/f2)^2."""
        out: dict[str, list] = {}
        vrs = synthesize(ne, station_eps, points, self.engine.nav)
        if vrs is None:
            return out
        f = vrs.freq_hz
        stec = blk.stec_tecu[e]
        for i, name in enumerate(names):
            master = vrs.master[i]
            m_ep = station_eps[master]
            cols = np.minimum(np.searchsorted(vrs.sats, m_ep.sats), len(vrs.sats) - 1)
            ok = (vrs.sats[cols] == m_ep.sats) & vrs.corrected[i, cols] & np.isfinite(m_ep.phase_cyc).all(axis=1)
            ok &= np.isfinite(vrs.phase_cyc[i, cols]).all(axis=1)
            if ok.sum() < 2:
                continue
            c = cols[ok]
            pred = vrs_ionosphere_m(vrs.phase_cyc[i, c], m_ep.phase_cyc[ok], f[c])
            sats = vrs.sats[c]
            truth = self.truth.iono_f1_m(stec, name, sats, f[c, 0]) - self.truth.iono_f1_m(stec, master, sats, f[c, 0])
            el = blk.elevation_rad[e, self.truth.rx_row[name], self.truth.sat_cols(sats)]
            systems = np.array([s[0] for s in sats])
            errs = []
            for system in np.unique(systems):
                g = np.flatnonzero(systems == system)
                if len(g) < 2:
                    continue
                ref = g[np.argmax(el[g])]
                others = g[g != ref]
                err = (pred[others] - pred[ref]) - (truth[others] - truth[ref])
                errs.extend(float(x) for x in err if np.isfinite(x))
            out[name] = errs
        return out

    # --- train side ---------------------------------------------------------------------------------

    def _train_epoch(self, tr: _Train, blk: EpochBlock, e: int, t: float) -> None:
        log = tr.log
        # corrections that have arrived by t
        while tr.inbox and tr.inbox[0][0] <= t:
            _, data = tr.inbox.popleft()
            for ep in tr.decoder.feed(data, t):
                if tr.decoder.base_position_m is None:
                    continue
                if tr.decoder.station_id != tr.base_station_id:
                    tr.unit.set_base_position(tr.decoder.base_position_m)  # a new session: a new base
                    if tr.rear_unit is not None:
                        tr.rear_unit.set_base_position(tr.decoder.base_position_m)
                    tr.base_station_id = tr.decoder.station_id
                elif move_base(tr.unit, tr.decoder.base_position_m):
                    log.vrs_moves += 1
                    if tr.rear_unit is not None:
                        move_base(tr.rear_unit, tr.decoder.base_position_m)
                tr.base = ep
        rover = self.rover_obs.epoch(blk, e, tr.row)
        out = tr.unit.step(rover, tr.base, tr.decoder.bounds)
        sol, m = out.solution, out.match
        log.t_s.append(t - self.t0)
        log.status.append(int(sol.status))
        log.n_tracked.append(len(rover.sats))
        log.position.append(np.asarray(sol.position_m, float))
        log.covariance.append(np.asarray(sol.covariance_m2, float))
        log.age_s.append(float(t - tr.base.time) if tr.base is not None else math.nan)
        log.base_sats.append(len(tr.base.sats) if tr.base is not None else 0)
        log.vrs_master.append(self._vrs_master.get(round(tr.base.time, 3), {}).get(log.id, "")
                              if tr.base is not None else "")
        log.track.append(m.track if (m is not None and m.track) else "")
        log.km.append(float(m.km) if (m is not None and m.track) else math.nan)
        log.confirmed.append(bool(m is not None and m.confirmed))
        log.along_pl_m.append(m.along_pl_m if m is not None else math.inf)
        log.cross_pl_m.append(m.cross_pl_m if m is not None else math.inf)
        log.correction_along_m.append(m.correction_along_m if m is not None else 0.0)
        log.correction_cross_m.append(m.correction_cross_m if m is not None else 0.0)
        log.along_sigma_m.append(m.along_sigma_m if m is not None else math.inf)
        log.cross_sigma_m.append(m.cross_sigma_m if m is not None else math.inf)
        log.message.append(sol.message)
        log.truth_position.append(blk.rx_ecef[e, tr.row].copy())
        rx = self.world.receivers[tr.row]
        log.truth_km.append(float(rx.km[int(blk.epoch_index[e])]))
        if rx.edge is not None:
            log.truth_edge.append(str(rx.edge[int(blk.epoch_index[e])]))
            log.truth_route_m.append(float(rx.route_m[int(blk.epoch_index[e])]))
        self._fuse(tr, t, int(blk.epoch_index[e]), sol, m)
        if tr.rear_unit is not None:
            self._rear_epoch(tr, blk, e, t, m)
        # GGA upstream: open the VRS session, and let the caster's policy move it
        if sol.status == Status.NONE or t - tr.last_gga_t < GGA_INTERVAL_S:
            return
        fix = parse_gga(out.gga.encode("ascii"))
        if fix is None:
            return
        tr.last_gga_t = t
        log.gga_sent += 1
        if not tr.session:
            self.engine.open_session(log.id, fix.lat_deg, fix.lon_deg, fix.height_m, self._sink(tr))
            tr.policy.applied(t, fix)
            tr.session = True
            log.session_opened_s = t - self.t0
        elif tr.policy.due(t, fix):
            self.engine.move_session(log.id, fix.lat_deg, fix.lon_deg, fix.height_m)
            tr.policy.applied(t, fix)

    def _rear_epoch(self, tr: _Train, blk: EpochBlock, e: int, t: float, head_match) -> None:
        """The rear antenna's solution on the head's corrections (one radio, two receivers), and the integrity
        monitor on the two map matches."""
        log = tr.log
        rout = tr.rear_unit.step(self.rover_obs.epoch(blk, e, tr.rear_row), tr.base, tr.decoder.bounds)
        rm = rout.match
        log.rear_status.append(int(rout.solution.status))
        log.rear_track.append(rm.track if (rm is not None and rm.track) else "")
        log.rear_km.append(float(rm.km) if (rm is not None and rm.track) else math.nan)
        log.rear_along_pl_m.append(rm.along_pl_m if rm is not None else math.inf)
        rrx = self.world.receivers[tr.rear_row]
        log.truth_rear_route_m.append(float(rrx.route_m[int(blk.epoch_index[e])]))
        log.integrity.append(tr.integrity.update(t - self.t0, antenna_fix(head_match), antenna_fix(rm)))

    def _fuse(self, tr: _Train, t: float, epoch: int, sol, m) -> None:
        """Every method's along-track position at t from this epoch's map-matched fix and odometer reading."""
        fix = None
        if (m is not None and sol.status != Status.NONE and np.all(np.isfinite(sol.position_m))
                and math.isfinite(m.along_sigma_m) and m.along_sigma_m > 0):
            fix = AlongTrackFix(t, m.km * 1000.0, m.along_sigma_m)
        odo = self.odometers.sample(tr.log.id, epoch, t)
        for method, fusion in tr.fusions.items():
            tr.log.fused[method].append(fusion.step(t, odo, fix))
        if tr.timer is not None:
            # without a map match (tunnel) the fused position carries on by odometry on the last track
            self._balise_timer(tr, t, m.track if m is not None and m.track else tr.timer.track)

    def _balise_timer(self, tr: _Train, t: float, track: str | None) -> None:
        """Step the balise timer to each due moment up to t on the previous estimate, then feed this epoch's."""
        for _ in range(8):  # a few groups per epoch at most
            due = [d for d in tr.timer.due_times() if d <= t]
            if not due:
                break
            tr.timer.tick(min(due))
        tr.timer.tick(t)
        fused = tr.log.fused["weighted_median"]
        now = fused[-1]
        if not track or len(fused) < 2 or not np.isfinite(now.position_m) or not np.isfinite(fused[-2].position_m):
            return
        prev = fused[-2]
        dt = now.time - prev.time
        sigma = now.sigma_m
        if dt <= 0 or not math.isfinite(sigma):
            return
        speed = (now.position_m - prev.position_m) / dt
        # chainage increases with km; speed from two fused positions, variance of the difference
        tr.timer.update(t, track, now.position_m, speed, sigma ** 2, 2.0 * sigma ** 2 / dt ** 2)
        tr.timer.tick(t)  # a moment this estimate puts at or before t (missed by the last one) is now

    # --- the record ---------------------------------------------------------------------------------

    def log(self) -> RunLog:
        sc = self.scenario
        line_llh = None
        blockages = []
        if self.world.track is not None:
            tl = self.world.track
            line_llh = tl.plane_to_geodetic(tl.point(np.linspace(0.0, tl.length_m, 400), 0.0))
            blockages = [{"kind": b.kind, "start_km": b.start_km, "end_km": b.end_km,
                          "llh": tl.plane_to_geodetic(tl.point(np.linspace(b.start_km, b.end_km, 20) * 1e3, 0.0))}
                         for b in sc.line.blockages]
        opt = self.options
        return RunLog(sc, {k: v.log for k, v in self.trains.items()}, self.baselines, self.interpolation,
                      self.interpolation_floor,
                      self.stations, self.check_points, self.track_db, self.latency.describe(), line_llh,
                      blockages, self.network_epochs, self.epochs, warm_up_s=self.warm_up_s,
                      world_epochs=self.world_epochs, age_limit_s=opt.max_age_s,
                      min_rtk_satellites=opt.min_fix_ambiguities + 1, t0=self.t0,
                      line_length_m=self.world.track.length_m if self.world.track is not None else math.nan)


def antenna_fix(m) -> AntennaFix | None:
    """A map match as the integrity monitor's input (None without a track or a finite along-track PL)."""
    if m is None or not m.track or not math.isfinite(m.km) or not math.isfinite(m.along_pl_m):
        return None
    return AntennaFix(m.track, float(m.km), float(m.along_pl_m))


def simulate(scenario: str | Path | Scenario, *, duration_s: float | None = None,
             on_epoch: Callable[[], None] | None = None, options: RtkOptions | None = None,
             warm_up_s: float | None = None, correction_bound: bool = False,
             fusion: dict | None = None) -> RunLog:
    """Run the chain over the warm-up and the whole scenario and return the per-epoch record (no files
    written). `warm_up_s`: see `warm_up_s_for`; `fusion`: FusionSettings fields overridden in every train."""
    sc = load(scenario, duration_s)
    warm = warm_up_s_for(sc, warm_up_s)
    start = wallclock.perf_counter()
    world = WarmUpWorld(sc, warm)
    chain = Chain(world, sc, options, correction_bound=correction_bound, fusion=fusion)
    for blk in world.epochs():
        chain.add_block(blk, on_epoch)
    log = chain.log()
    log.wall_s = wallclock.perf_counter() - start
    return log


def run(scenario: str | Path | Scenario, out_dir: str | Path, *, duration_s: float | None = None,
        progress: bool = True, plots: bool = True, alert_limit_m: float | None = None,
        warm_up_s: float | None = None):
    """The scenario end to end: `report.json` (and per-epoch CSV, PNG plots) in `out_dir`; returns the Report.
    `warm_up_s`: how long the stations and the centre run before the trains' time 0 (`warm_up_s_for`)."""
    from augnet.scenario import report as report_mod

    sc = load(scenario, duration_s)
    warm = warm_up_s_for(sc, warm_up_s)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if progress:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        with Progress(TextColumn(f"[bold]{sc.name}[/bold] simulated s"), BarColumn(), MofNCompleteColumn(),
                      TimeRemainingColumn()) as bar:
            task = bar.add_task("run", total=sc.n_epochs + round(warm * sc.rate_hz))
            log = simulate(sc, on_epoch=lambda: bar.advance(task), warm_up_s=warm)
    else:
        log = simulate(sc, warm_up_s=warm)
    rep = report_mod.build(log, alert_limit_m=alert_limit_m or report_mod.DEFAULT_ALERT_LIMIT_M)
    report_mod.write_epochs_csv(log, out / report_mod.EPOCHS_CSV)
    rep.files.append(report_mod.EPOCHS_CSV)
    if plots:
        from augnet.scenario import plots as plots_mod

        rep.files.extend(plots_mod.write_all(log, rep, out))
    rep.files.insert(0, report_mod.REPORT_JSON)
    rep.write(out / report_mod.REPORT_JSON)
    return rep
