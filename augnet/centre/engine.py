"""The control centre's processing core: station bytes in, VRS bytes and correction models out.

Sans-IO: the service feeds it station stream bytes with `feed(station, data, now)` and calls `tick(now)`
(once or more per second); `tick` solves every epoch the aligner releases, writes each VRS session's RTCM to
its sink, and queues the correction model and alarms in `outbox` for the service to publish on the bus.
`CentreStreamFactory` adapts it to the NTRIP caster's stream-factory interface (a VRS mountpoint's client
gets a session once its GGA is known; `update_position` moves its virtual station).

Antennas: with an ANTEX file (`antex=`), each station's antenna is modelled from the type its RTCM 1033
descriptor gives (or `antenna_types`, which take precedence: a station that sends no 1033), so the network's
residuals refer to the antenna reference points and the VRS is for a null antenna, as its 1033
(`ADVNULLANTENNA`, vrs_stream.py) says. Without one nothing is modelled.

Admission (`admission=`, vrs_admission.py, the policy and settings of `augnet vrs`): each session's network
VRS takes satellites the network newly corrects only at its admission moments; until then they are left out of
it (as `augnet vrs` leaves them out of a network epoch), and at a moment every satellite it carries is flagged
loss-of-lock, so the stream restarts their locks (MSM lock-time indicator 0). Each session has its own
admission state. While the policy finds too few corrected satellites for a network VRS (the network's start),
the session gets what the synthesis gives, its fallback (`augnet vrs` writes the nearest station shifted). `AdmissionConfig(admission=False)`: the VRS as synthesised, byte for byte what the stream
sent before admission existed. Satellites a point within vrs.UNCORRECTED_MAX_DISTANCE_M of its master gets
without corrections are not the policy's: they stay as synthesised.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import logging
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.coordinate_monitor import StationCoordinateMonitor
from augnet.centre.correction_bound import (K_CORRECTION_BOUND, CorrectionBound, correction_residuals,
                                            ionosphere_level_ppm)
from augnet.centre.ingest import EpochAligner, StationDecoder
from augnet.centre.integrity import Alarm
from augnet.centre.network import MEMBERSHIP_KIND, MembershipChange, NetworkEpoch, NetworkSolver
from augnet.centre.service_area import AreaAlarm, AreaAnswer, AreaConfig, ServiceArea, refusal_message
from augnet.centre.vrs import VrsEpoch, VrsPlan, synthesize
from augnet.centre.vrs_admission import AdmissionBatch, AdmissionConfig, fixed_somewhere
from augnet.centre.vrs_handover import MasterHandover
from augnet.centre.vrs_stream import VrsStreamEncoder
from augnet.gnss.antex import AntexFile, read_antex
from augnet.gnss.geometry import ecef_to_enu, ecef_to_geodetic, enu_rotation
from augnet.gnss.ephemeris import Ephemeris, NavigationData, transit
from augwire.errors import StreamRefused

log = logging.getLogger(__name__)

# RTCM station ids of VRS sessions: 2000.. (real stations use low ids; DF003 holds 0..4095)
FIRST_VRS_STATION_ID = 2000
MAX_STATION_ID = 4095
SUBJECT_CORRECTIONS = "augnet.corrections.{network}"
SUBJECT_ALARMS = "augnet.alarms.{network}"
MAX_CORRECTION_LAG_S = 5.0  # older network corrections are not applied to a new epoch's VRS (network-rtk.md)
LLI_LOSS_OF_LOCK = 1  # RINEX LLI bit 0, what the stream encoder restarts a lock on


@dataclass
class Session:
    client_id: str
    sink: Callable[[bytes], None]
    point_ecef: np.ndarray
    station_id: int
    opened_t: float | None = None
    bytes_sent: int = 0
    epochs_sent: int = 0
    area_reason: str = ""  # why it is served elsewhere than its position (outside the service area)


@dataclass
class EpochReport:
    """What one solved epoch produced (for the console, tests and the run report)."""

    t_gpst: float
    network: NetworkEpoch
    vrs: VrsEpoch | None
    sessions: int
    stations: list[str] = field(default_factory=list)
    # wall time (host clock, Unix s) the epoch's first and last station data reached the engine
    arrival: tuple[float, float] | None = None
    # interpolation model name -> satellite-point cells of this epoch's VRS that used it (what the
    # console shows of `vrs`, which a report crossing a process boundary leaves behind)
    vrs_models: dict[str, int] = field(default_factory=dict)


def vrs_model_counts(vrs: VrsEpoch | None) -> dict[str, int]:
    if vrs is None or not vrs.model.size:
        return {}
    from augnet.centre.interpolation import MODEL_NAMES
    counts = np.bincount(vrs.model.ravel().astype(np.int64) + 1)
    return {MODEL_NAMES.get(k - 1, str(k - 1)): int(c) for k, c in enumerate(counts) if c}


class CentreEngine:
    def __init__(self, stations: dict[str, np.ndarray], t_ref_gpst: float, network_name: str = "line",
                 master: str | None = None, config: BaselineConfig | None = None,
                 ephemerides: list[Ephemeris] | None = None, msm_level: int = 7,
                 vrs_before_network: bool = True, antex: AntexFile | str | None = None,
                 antenna_types: dict[str, str] | None = None, area: AreaConfig | None = None,
                 admission: AdmissionConfig | None = None, correction_bound: bool = False,
                 estimate_correction_bound: bool | None = None):
        self.network_name = network_name
        self.antex = read_antex(antex) if isinstance(antex, (str, bytes)) or hasattr(antex, "__fspath__") else antex
        self.antenna_types: dict[str, str] = {}  # station -> antenna type in use (1033 or configured)
        self.antenna_notes: list[str] = []
        self.stations = {k: np.asarray(v, float) for k, v in stations.items()}
        self.area = ServiceArea(self.stations, area)  # where sessions may open (service_area.py)
        self.area_alarm = AreaAlarm(network_name)
        self._now = 0.0  # the latest `now` fed or ticked (the area alarm's clock)
        self.t_ref_gpst = t_ref_gpst
        self.decoders = {name: StationDecoder(name, t_ref_gpst) for name in stations}
        self.aligner = EpochAligner(list(stations))
        self.network = NetworkSolver(self.stations, master=master, config=config)
        self._ephemerides: dict[tuple, Ephemeris] = {}
        self.nav = NavigationData([])
        if ephemerides:
            self._add_ephemerides(ephemerides)
        self.encoder = VrsStreamEncoder(msm_level, send_correction_bound=correction_bound)
        # the centre's bound on its correction error, sent as 4001 after each VRS epoch: opt-in (default off,
        # docs/correction-bound-message.md), so a stream without it is byte for byte what it was
        # `estimate_correction_bound` alone (`augnet up`): the bound is estimated, but sent only to the sessions
        # of a mountpoint that opted in (`set_session_bound`, decision 0281)
        estimate = correction_bound if estimate_correction_bound is None else estimate_correction_bound
        self.correction_bound = CorrectionBound() if estimate or correction_bound else None
        # published station coordinates checked against the fixed network; a flagged station leaves VRS synthesis
        # (coordinate_monitor.py, decision 0254)
        self.coordinates = StationCoordinateMonitor()
        self.admission = AdmissionBatch(admission)  # per session: when newly corrected satellites enter its VRS
        self.handover = MasterHandover()  # per session: its phase kept continuous across master changes (0223)
        self.sessions: dict[str, Session] = {}
        self._station_ids = itertools.count(FIRST_VRS_STATION_ID)
        self.outbox: list[tuple[str, bytes]] = []  # (bus subject, payload) for the service to publish
        self.last: EpochReport | None = None
        self.epochs_solved = 0
        # Latency: the VRS of epoch t is synthesised from t's master observations and the corrections of
        # the latest solved network epoch (t - 1 s), then the network solves t. Corrections are smooth
        # (DD ionosphere changes by well under a mm per second in quiet conditions, network-rtk.md), so
        # nothing is lost but the solve time on the critical path; a satellite new at t is corrected from
        # t + 1, and an exclusion decided at t applies from t + 1 (within the 2-epoch requirement).
        self.vrs_before_network = vrs_before_network
        self._prev: NetworkEpoch | None = None
        self.serving_t = np.nan  # epoch whose VRS are being produced (GPST s)
        self.serving_arrival: tuple[float, float] | None = None  # its stations' data arrival (Unix s)
        # synthesis, encoding (wall), their CPU [s], 1.0 when the VRS plan made ahead was used
        self.serve_cost_s: tuple[float, float, float, float] | None = None
        # called after each group of `serve_group` sessions' epoch is in their sinks: after_serve(last), last
        # True once every session's is
        self.after_serve: Callable[[bool], None] | None = None
        self.serve_group: int | None = None
        self._plan: VrsPlan | None = None  # the next epoch's VRS, all but the observations (prepare_next)
        self._unplanned: dict[str, None] = {}  # sessions opened or moved since the plan was made
        self._last_eps: dict = {}
        self._interval_s = 1.0
        self._configured_antennas = dict(antenna_types or {})
        for name, t in self._configured_antennas.items():
            self._use_antenna(name, t)

    # --- inputs ---------------------------------------------------------------------------------

    def feed(self, station: str, data: bytes, now: float) -> None:
        self._now = max(self._now, now)
        dec = self.decoders.get(station)
        if dec is None:
            return
        epochs = dec.feed(data)
        if (dec.antenna_descriptor is not None and station not in self._configured_antennas
                and self.antenna_types.get(station) != dec.antenna_descriptor):
            self._use_antenna(station, dec.antenna_descriptor)
        new = dec.take_ephemerides()
        if new:
            self._add_ephemerides(new)
        for ep in epochs:
            self.aligner.add(ep, now)

    def _use_antenna(self, station: str, antenna_type: str) -> None:
        """Model the station's antenna of this type from the next epoch (nothing without an ANTEX file)."""
        self.antenna_types[station] = antenna_type
        if self.antex is None or station not in self.stations:
            return
        ant = self.antex.receiver(antenna_type, warn=False)
        if ant is None:
            self.antenna_notes.append(f"{station}: antenna {antenna_type.strip()!r} not in the ANTEX file: "
                                      "not modelled")
        elif ant.radome_fallback:
            self.antenna_notes.append(f"{station}: {antenna_type.strip()!r}: radome NONE's calibration")
        if self.epochs_solved:
            log.warning("%s: antenna %r from epoch %d on", station, antenna_type, self.epochs_solved)
        self.network.set_antenna(station, ant)

    def _add_ephemerides(self, ephs: list[Ephemeris]) -> None:
        changed = False
        for e in ephs:
            key = (e.sat, e.week, e.toe, e.iode, e.data_sources)
            if key not in self._ephemerides:
                self._ephemerides[key] = e
                changed = True
        if changed:
            self.nav = NavigationData(list(self._ephemerides.values()))

    # --- membership: stations join and leave while the engine runs ----------------------------------

    def add_station(self, name: str, xyz, antenna_type: str | None = None) -> MembershipChange:
        """`name` (ECEF `xyz` [m]) joins: its data is decoded and aligned from now on, baselines to its nearest
        stations are added (`NetworkSolver.add_station`; the others keep their ambiguities) and the service
        area grows. ValueError (saying why) for a duplicate or a position off the Earth."""
        change = self.network.add_station(name, xyz)
        self.stations[name] = np.asarray(xyz, float).reshape(3)
        self.decoders[name] = StationDecoder(name, self.t_ref_gpst)
        self.aligner.add_station(name)
        self.area = ServiceArea(self.stations, self.area.config)
        self._plan = None  # planned for the old station set
        if antenna_type is not None:
            self._configured_antennas[name] = antenna_type
            self._use_antenna(name, antenna_type)
        self._note(change, Alarm(MEMBERSHIP_KIND, name, "info", f"station {name} joined the network: baselines "
                                 f"{', '.join(change.added) or 'none'}", self._last_t(), cleared=True))
        return change

    def remove_station(self, name: str) -> MembershipChange:
        """`name` leaves: its data is no longer read, its baselines are dropped, a master that leaves is replaced,
        sessions it served as their VRS master are served from another station from the next epoch, and a
        `station-left` alarm is raised (cleared when it joins again). ValueError for a station not in the
        network or its last one."""
        homed = self._sessions_mastered_by(name)
        change = self.network.remove_station(name)
        self._forget(name)
        self.area = ServiceArea(self.stations, self.area.config)
        self._note(change, Alarm(MEMBERSHIP_KIND, name, "warning",
                                 f"station {name} left the network: baselines {', '.join(change.dropped) or 'none'} "
                                 f"dropped" + (f", {', '.join(change.added)} added" if change.added else "")
                                 + (f"; master {change.master_before} -> {change.master_after}"
                                    if change.master_before != change.master_after else "")
                                 + f"; {homed} VRS session(s) re-homed", self._last_t()))
        return change

    def move_station(self, name: str, xyz) -> MembershipChange:
        """New coordinates: leave and join (`NetworkSolver.move_station`); its decoder is kept (its stream goes
        on), its pending epochs are dropped (observed at the old coordinates' solution)."""
        homed = self._sessions_mastered_by(name)
        change = self.network.move_station(name, xyz)
        self.coordinates.forget(name)
        self.stations[name] = np.asarray(xyz, float).reshape(3)
        self.aligner.remove_station(name)
        self.aligner.add_station(name)
        self.area = ServiceArea(self.stations, self.area.config)
        self._plan = None
        self._prev = None
        self._note(change, None)
        log.warning("station %s moved: baselines %s restarted; %d VRS session(s) re-homed meanwhile", name,
                    ", ".join(change.added) or "none", homed)
        return change

    def _forget(self, name: str) -> None:
        self.stations.pop(name, None)
        self.coordinates.forget(name)
        self.decoders.pop(name, None)
        self.aligner.remove_station(name)
        self._configured_antennas.pop(name, None)
        self.antenna_types.pop(name, None)
        self._last_eps.pop(name, None)
        self._plan = None  # its VRS plan may name the station as a master
        self._prev = None  # the next epoch's VRS are made from its own network epoch, without the station

    def _sessions_mastered_by(self, name: str) -> int:
        vrs = self.last.vrs if self.last is not None else None
        return 0 if vrs is None else sum(1 for m in vrs.master if m == name)

    def _last_t(self) -> float:
        return float(self.last.t_gpst) if self.last is not None else float("nan")

    def _note(self, change: MembershipChange, alarm: Alarm | None) -> None:
        log.info("network membership: %s", change)
        if alarm is not None:
            self.network.integrity.note(alarm)

    # --- sessions (one per VRS client) ----------------------------------------------------------

    def open_session(self, client_id: str, lat_deg: float, lon_deg: float, h_m: float,
                     sink: Callable[[bytes], None]) -> Session | AreaAnswer:
        """A VRS session at the position; one that is no place on Earth or outside the service area opens
        none: its refusal (`AreaAnswer.reason`) is returned and an alarm queued (`service_area.py`)."""
        answer = self._check_area(client_id, lat_deg, lon_deg, h_m)
        if answer.refused:
            return answer
        sid = next(self._station_ids)
        if sid > MAX_STATION_ID:
            self._station_ids = itertools.count(FIRST_VRS_STATION_ID)
            sid = next(self._station_ids)
        point = answer.point_ecef
        s = Session(client_id, sink, point, sid, area_reason=answer.reason)
        self.sessions[client_id] = s
        self.encoder.add(client_id, sid, point)
        self._unplanned[client_id] = None
        return s

    def move_session(self, client_id: str, lat_deg: float, lon_deg: float, h_m: float) -> AreaAnswer | None:
        """Move a session's virtual station; a position it may not be served at closes it (returned)."""
        s = self.sessions.get(client_id)
        if s is None:
            return None
        answer = self._check_area(client_id, lat_deg, lon_deg, h_m)
        if answer.refused:
            self.close_session(client_id)
            return answer
        s.point_ecef, s.area_reason = answer.point_ecef, answer.reason
        self.encoder.move(client_id, s.point_ecef)
        self._unplanned[client_id] = None
        return None

    def _check_area(self, client_id: str, lat_deg: float, lon_deg: float, h_m: float) -> AreaAnswer:
        answer = self.area.check(lat_deg, lon_deg, h_m)
        if answer.kind != "inside":
            log.info("VRS session %s: %s", client_id, answer.reason)
            self._queue_alarm(self.area_alarm.refused(self._now, client_id, answer))
        return answer

    def _queue_alarm(self, event: tuple | None) -> None:
        if event is not None:
            kind, subject, severity, message, cleared = event
            self.outbox.append((SUBJECT_ALARMS.format(network=self.network_name), json.dumps({
                "kind": kind, "subject": subject, "severity": severity, "message": message,
                "t_gpst": None, "cleared": cleared}).encode()))

    def set_session_bound(self, client_id: str, send: bool) -> None:
        """The session's VRS carry the 4001 correction-error bound from its next epoch (`send`) or not."""
        if client_id in self.sessions:
            self.encoder.set_send_bound(client_id, bool(send))

    def close_session(self, client_id: str) -> None:
        self.sessions.pop(client_id, None)
        self.encoder.remove(client_id)
        self.admission.remove(client_id)
        self.handover.remove(client_id)

    # --- processing -----------------------------------------------------------------------------

    def tick(self, now: float) -> list[EpochReport]:
        self._now = max(self._now, now)
        self._queue_alarm(self.area_alarm.poll(now))
        reports = []
        for t, got in self.aligner.ready(now):
            if len(self.nav) == 0:
                continue  # no broadcast ephemerides yet: nothing can be solved
            self.serving_arrival = self.aligner.arrivals.get(t)
            reports.append(self._solve(t, got))
        return reports

    def _solve(self, t: float, epochs) -> EpochReport:
        eps = {name: epochs.get(name) for name in self.stations}
        vrs = None
        ids = list(self.sessions)
        prev = self._prev if self.vrs_before_network and self._prev is not None and t - self._prev.t_gpst <= MAX_CORRECTION_LAG_S else None
        self.serving_t = t
        if prev is not None and ids:
            vrs = self._serve(ids, prev, eps)
        ne = self.network.update(eps, self.nav)
        try:
            ne.alarms.extend(self.coordinates.update(ne, self.nav))
        except Exception:  # noqa: BLE001 - the monitor failing must not stop the network: logged, no verdict
            log.exception("station coordinates not checked at %s", t)
        # flagged stations are neither masters nor interpolation nodes of the VRS made from this epoch
        ne.vrs_excluded = self.coordinates.excluded & set(ne.stations)
        if self.correction_bound is not None and len(ne.stations):
            try:
                self.correction_bound.update(ne.station_en_m, correction_residuals(ne.dd_iono_m, ne.dd_trop_m),
                                             ne.sats, 0, ionosphere_level_ppm(ne.station_en_m, ne.dd_iono_m, 0))
                if self.encoder.sends_bound():  # the overbounds now, not while the next epoch's VRS wait for them
                    self.correction_bound.warm()
            except Exception:  # noqa: BLE001 - the bound failing must not stop the VRS: its receivers get "none"
                log.exception("correction bound not updated at %s", t)
        if self._prev is not None and 0.0 < t - self._prev.t_gpst <= MAX_CORRECTION_LAG_S:
            self._interval_s = t - self._prev.t_gpst
        self._prev = ne
        self._last_eps = eps
        self.epochs_solved += 1
        if prev is None and ids:
            vrs = self._serve(ids, ne, eps)
        self.outbox.append((SUBJECT_CORRECTIONS.format(network=self.network_name), correction_model_json(ne)))
        for alarm in ne.alarms:
            self.outbox.append((SUBJECT_ALARMS.format(network=self.network_name), json.dumps({
                "kind": alarm.kind, "subject": alarm.subject, "severity": alarm.severity,
                "message": alarm.message, "t_gpst": alarm.t_gpst, "cleared": alarm.cleared}).encode()))
        report = EpochReport(t, ne, vrs, len(ids), sorted(k for k, v in eps.items() if v is not None),
                             self.serving_arrival, vrs_model_counts(vrs))
        self.last = report
        return report

    def _serve(self, ids: list[str], ne: NetworkEpoch, eps) -> VrsEpoch | None:
        """Synthesise and encode every session's VRS epoch from `ne`'s corrections and write it to its sink.

        With `serve_group` set, the sessions are encoded that many at a time and `after_serve` runs after
        each group (their bytes can leave while the next group is encoded); `serve_cost_s` then covers
        the synthesis (for all) and the encoding up to the group just written."""
        vrs = None
        if ids:
            t0, c0 = time.perf_counter(), time.process_time()
            points = np.array([self.sessions[c].point_ecef for c in ids])
            vrs = synthesize(ne, {k: v for k, v in eps.items() if v is not None}, points, self.nav,
                             plan=self._plan, keys=ids, masters=self.handover.masters)
            self._plan = None
            if vrs is not None:
                self.handover.apply(ids, vrs, ne)
            if vrs is not None and self.admission.config.admission:
                self._admit(ids, ne, vrs)
            t1 = time.perf_counter()
            if vrs is not None:
                sigma, level = self._bound_sigma(ne, vrs)
                group = self.serve_group or len(ids)
                for a in range(0, len(ids), group):
                    sub = ids[a:a + group]
                    out = self.encoder.encode(sub, vrs.rows(slice(a, a + group)) if group < len(ids) else vrs,
                                              self.nav, None if sigma is None else sigma[a:a + group], level)
                    self.serve_cost_s = (t1 - t0, time.perf_counter() - t1, time.process_time() - c0,
                                         float(bool(vrs.flags.get("planned"))))
                    for cid in sub:
                        s = self.sessions[cid]
                        data = out.get(cid, b"")
                        if not data:
                            continue
                        try:
                            s.sink(data)
                        except Exception:  # a sink that fails must not stop the others  # noqa: BLE001
                            log.exception("VRS sink of %s failed", cid)
                        s.bytes_sent += len(data)
                        s.epochs_sent += 1
                    if self.after_serve is not None and a + group < len(ids):
                        self.after_serve(False)
        if self.after_serve is not None:
            self.after_serve(True)
        return vrs

    def _bound_sigma(self, ne: NetworkEpoch, vrs: VrsEpoch) -> tuple[np.ndarray | None, float]:
        """Overbound sigma [m] of the correction error per session and VRS satellite (None when not sent)."""
        if self.correction_bound is None or not len(ne.stations) or not self.encoder.sends_bound():
            return None, float("nan")
        try:
            origin = ne.station_xyz_m[0]
            rover_en = ecef_to_enu(vrs.points_ecef_m - origin, origin)[:, :2]
            level = ionosphere_level_ppm(ne.station_en_m, ne.dd_iono_m, 0)
            sigma = self.correction_bound.sigma(ne.station_en_m, rover_en, vrs.sats, level)
        except Exception:  # noqa: BLE001 - sent as "none" (16383): the rover treats the corrections as unbounded
            log.exception("correction bound not computed at %s", vrs.t_gpst)
            return np.full((len(vrs.points_ecef_m), len(vrs.sats)), np.nan), float("nan")
        try:
            # satellites sent without network corrections (near the master) carry the whole DD atmosphere
            # between the point and its master, not an interpolation error: the field's gradient bounds them
            plain = self.correction_bound.uncorrected_sigma(vrs.distance_to_master_m, vrs.sats, level)
        except Exception:  # noqa: BLE001 - as above
            log.exception("correction bound of uncorrected satellites not computed at %s", vrs.t_gpst)
            plain = np.full(sigma.shape, np.nan)
        sigma = np.where(vrs.corrected, sigma, plain)
        try:
            sigma = self._with_station_offsets(ne, vrs, sigma)
        except Exception:  # noqa: BLE001 - as above: those sessions' satellites are sent as "none"
            log.exception("station offsets not added to the correction bound at %s", vrs.t_gpst)
            sigma = np.full(sigma.shape, np.nan)
        return sigma, level

    def _with_station_offsets(self, ne: NetworkEpoch, vrs: VrsEpoch, sigma: np.ndarray) -> np.ndarray:
        """The bound of sessions served by a suspect, not yet excluded station widened by its estimated offset.

        A master published off by d puts u_j . d into satellite j's VRS observations (u: unit vector master ->
        satellite); a bias b under sigma is overbounded by sigma + |b| / K, so each satellite's sigma grows by
        (|u_j . d| + K sqrt(u_j' C u_j)) / K (decision 0254)."""
        masters = np.asarray(vrs.master)
        for s in set(masters.tolist()):
            got = self.coordinates.unmodelled_offset(s)
            if got is None or s not in self.stations:
                continue
            d, cov = got
            xyz = self.stations[s]
            llh = ecef_to_geodetic(xyz)
            u = transit(self.nav, list(vrs.sats.astype(str)), xyz, vrs.t_gpst).line_of_sight @ enu_rotation(llh[0], llh[1]).T
            extra = (np.abs(u @ d) + K_CORRECTION_BOUND * np.sqrt(np.einsum("si,ij,sj->s", u, cov, u))) / K_CORRECTION_BOUND
            rows = masters == s
            sigma[rows] = sigma[rows] + np.where(np.isfinite(extra), extra, np.nan)[None, :]
        return sigma

    def _admit(self, ids: list[str], ne: NetworkEpoch, vrs: VrsEpoch) -> None:
        """Each session's admission decision on its VRS epoch, in place: in a network VRS the corrected satellites
        it does not carry (yet) are left out, and at its moments every satellite it carries is flagged
        loss-of-lock."""
        corrected = vrs.corrected & np.isin(vrs.sats.astype(str), list(fixed_somewhere(ne)))[None, :]
        carried, moment = self.admission.step(vrs.t_gpst, ids, vrs.sats, corrected, vrs.master, vrs.handed_over)
        # not a network VRS (too few corrected): the session gets its fallback as synthesised, as `augnet vrs`
        # writes its single-base epoch then
        out = vrs.corrected & ~carried & carried.any(axis=1)[:, None]
        if out.any():
            vrs.code_m[out] = np.nan
            vrs.phase_cyc[out] = np.nan
            vrs.cnr_dbhz[out] = np.nan
            vrs.lli[out] = 0
            vrs.corrected[out] = False
            vrs.model[out] = -1
        if moment.any():
            vrs.lli |= ((moment[:, None] & carried)[..., None] * LLI_LOSS_OF_LOCK).astype(vrs.lli.dtype)

    def prepare_next(self) -> None:
        """Build the next epoch's VRS plan now (the sessions' masters, interpolated corrections and
        geometry from the latest network epoch; `VrsPlan`), while the centre waits for that epoch's data:
        then only the observations are added when it arrives. It assumes the next epoch one interval on,
        with the same stations; if not, the VRS are planned then. Sessions opened or moved after it are
        added by `update_plan`."""
        self._unplanned.clear()
        ne = self._prev
        if ne is None or not self.sessions or not self.vrs_before_network:
            self._plan = None
            return
        eps = {k: v for k, v in self._last_eps.items() if v is not None}
        plan = VrsPlan(ne, self.nav, ne.t_gpst + self._interval_s, list(eps), masters=self.handover.masters)
        ids = list(self.sessions)
        plan.rows_for(np.array([self.sessions[c].point_ecef for c in ids]), ids)
        plan.add_sats(sorted({str(s) for e in eps.values() for s in e.sats} - set(ne.excluded)))
        plan.prepare_stations()
        self._plan = plan

    def update_plan(self) -> None:
        """Plan the sessions opened or moved since `prepare_next` (their masters, corrections and geometry
        at the new points), in one batch, while the centre still waits for the epoch: otherwise the epoch's
        synthesis does it, on the correction age's path (the load test's trains report their GGA together,
        so hundreds of them move between two epochs)."""
        plan, ids = self._plan, [c for c in self._unplanned if c in self.sessions]
        self._unplanned.clear()
        if plan is not None and ids:
            plan.rows_for(np.array([self.sessions[c].point_ecef for c in ids]), ids)

    def drain_outbox(self) -> list[tuple[str, bytes]]:
        out, self.outbox = self.outbox, []
        return out


def _nan_to_none(a: np.ndarray) -> list:
    return [[None if not np.isfinite(v) else round(float(v), 5) for v in row] for row in np.atleast_2d(a)]


def correction_model_json(ne: NetworkEpoch) -> bytes:
    """The epoch's correction model as published on the bus: master, stations (east/north from the
    master), reference satellites, DD residuals (ionosphere on f1 and non-dispersive) of every station
    against the master, exclusions and per-baseline quality. Enough for a caster node elsewhere to
    interpolate for its own clients."""
    # stations left out of VRS synthesis, named only when there are some (the model is otherwise as before)
    out = {"vrs_excluded": sorted(ne.vrs_excluded)} if ne.vrs_excluded else {}
    return json.dumps({
        "t_gpst": ne.t_gpst, "master": ne.master, "stations": ne.stations,
        "station_en_m": [[round(float(v), 3) for v in row] for row in ne.station_en_m],
        "refs": ne.refs, "sats": [str(s) for s in ne.sats],
        "dd_iono_m": _nan_to_none(ne.dd_iono_m), "dd_trop_m": _nan_to_none(ne.dd_trop_m),
        "excluded": sorted(ne.excluded), "present": ne.present,
        "fixed_fraction": {k: round(v, 3) for k, v in ne.fixed_fraction().items()},
        "misclosures": ne.misclosures, **out,
    }, separators=(",", ":")).encode()


class _Handle:
    def __init__(self, engine: CentreEngine, client_id: str):
        self.engine = engine
        self.client_id = client_id

    def update_position(self, fix) -> None:
        refused = self.engine.move_session(self.client_id, fix.lat_deg, fix.lon_deg, fix.height_m)
        if refused is not None:
            raise StreamRefused(refused.reason, refusal_message(refused.reason))

    def close(self) -> None:
        self.engine.close_session(self.client_id)


class CentreStreamFactory:
    """The NTRIP caster's VRS stream factory, backed by a `CentreEngine` in the same process."""

    def __init__(self, engine: CentreEngine):
        self.engine = engine

    def open(self, client_id: str, mount: str, fix, sink) -> _Handle:
        opened = self.engine.open_session(client_id, fix.lat_deg, fix.lon_deg, fix.height_m, sink)
        if isinstance(opened, AreaAnswer):
            raise StreamRefused(opened.reason, refusal_message(opened.reason))
        if opened.area_reason:  # served at the nearest station: the client is told so
            sink(refusal_message(opened.area_reason))
        return _Handle(self.engine, client_id)
