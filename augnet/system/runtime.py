"""`augnet up`: the whole system in one asyncio process.

    simulated stations --NTRIP sources--> caster :2101 --taps--> centre (worker thread)
    centre --VRS per train (stream factory)--> caster VRS mountpoint --NTRIP + GGA--> onboard trains
    centre --correction model, alarms--> bus;  centre --RSSP-I over loopback UDP--> RBC simulator
    everything --> live state --> console :8000 (REST, websocket, web page) and the terminal view
    configuration, sessions, alarms, quality history --> store (SQLite file, or PostgreSQL by URL)

Start-up order follows the data (store, caster, centre, RBC link, console, trains, then the stations
that feed them all); shutdown runs it backwards so nothing writes into a closed neighbour.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import datetime as dt
import gc
import json
import logging
import math
import secrets
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from augnet.centre.engine import SUBJECT_ALARMS, EpochReport
from augnet.gnss import time as gtime
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.onboard.trackmap import TrackDatabase
from augnet.system import persistence
from augnet.system.centre_service import CentreService, CentreSpec
from augnet.system.settings import DEFAULT_LIVE_WINDOW_S, START_MARGIN_S, SystemSettings
from augnet.system.trains import OnboardTrain
from augwire.passwords import hash_password
from ntrip_caster.config import CasterConfig, MountConfig, User
from ntrip_caster.server import Caster
from stations.live import mountpoint_of, run_stations
from stations.scenario import Scenario, Train, load_scenario
from stations.trackmap_export import track_database
from stations.world import World

log = logging.getLogger(__name__)

VRS_MOUNT = "VRS"
ADMIN_NAME = "admin"
STATION_GROUP, TRAIN_GROUP = "stations", "trains"
STATION_USER, TRAIN_USER = "stations", "train"
QUALITY_INTERVAL_S = 10.0  # one quality-history row per baseline this often
LIVE_PUBLISH_INTERVAL_S = 0.5  # train positions to the live state at most this often per train
EXTRA_TRAIN_SPEEDS_KMH = (160.0, 200.0, 250.0, 300.0)


def scenario_for_run(settings: SystemSettings, now_gpst: float | None = None) -> Scenario:
    """The scenario as this run plays it: starting a moment from now, for the run's window, with the
    requested number of trains (the scenario's own first, then more spread along the line)."""
    sc = load_scenario(settings.scenario)
    now = gtime.now_gpst() if now_gpst is None else now_gpst
    start = gtime.to_datetime(float(math.ceil(now + START_MARGIN_S))).replace(microsecond=0)
    window = settings.duration_s + 10.0 if settings.duration_s else DEFAULT_LIVE_WINDOW_S
    trains = list(sc.trains)
    if settings.trains is not None:
        trains = trains[:settings.trains]
        line_km = None
        if sc.line is not None:
            from stations.track import TrackLine
            line_km = TrackLine(sc.line).length_m / 1000.0
        k = 0
        while len(trains) < settings.trains and line_km:
            k += 1
            direction = 1 if k % 2 else -1
            start_km = (k * 0.37 % 1.0) * (line_km - 20.0) + 10.0
            speed = EXTRA_TRAIN_SPEEDS_KMH[k % len(EXTRA_TRAIN_SPEEDS_KMH)]
            trains.append(Train(id=f"T{k:03d}", track=1 if direction > 0 else min(2, sc.line.tracks),
                                start_km=round(start_km, 3), direction=direction, start_speed_kmh=speed,
                                speed_kmh=speed))
    return sc.model_copy(update={"start": start, "duration_s": int(math.ceil(window)), "trains": trains})


@dataclass
class RunSummary:
    """What `--duration` writes as the run report (and `augnet up` prints at the end)."""

    scenario: str
    started_utc: str
    duration_s: float
    stations: list[str]
    network_epochs: int = 0
    centre_solve_ms_p99: float | None = None
    centre_latency: dict = field(default_factory=dict)
    centre_stages_ms: dict = field(default_factory=dict)
    centre_errors: int = 0
    centre_restarts: int = 0
    trains: dict = field(default_factory=dict)
    alarms: list = field(default_factory=list)
    rbc: dict = field(default_factory=dict)
    caster: dict = field(default_factory=dict)
    store: dict = field(default_factory=dict)

    def to_json(self) -> str:
        return json.dumps(self.__dict__, indent=2, default=str)


class System:
    def __init__(self, settings: SystemSettings):
        self.settings = settings.validate()
        self.stop_event = asyncio.Event()
        self.caster: Caster | None = None
        self.centre: CentreService | None = None
        self.trains: dict[str, OnboardTrain] = {}
        self.train_sessions: dict[str, int] = {}
        self.rbc = None
        self.console_server = None
        self.live = None
        self.writer: persistence.StoreWriter | None = None
        self.bus = None
        self.world: World | None = None
        self.admin_token: str | None = None
        self.admin_password_created: str | None = None
        self.credentials: dict[str, str] = {}
        self.started = time.time()
        self.ready = asyncio.Event()
        self._tasks: list[asyncio.Task] = []
        self._last_quality = 0.0
        self._last_train_publish: dict[str, float] = {}
        self._open_alarms: set[tuple[str, str]] = set()
        self.alarm_log: list[dict] = []
        self.station_km: dict[str, float] = {}
        self.last_report: EpochReport | None = None
        self.correction_age_s: list[float] = []

    # --- start-up --------------------------------------------------------------------------------------

    async def start(self) -> None:
        s = self.settings
        loop = asyncio.get_running_loop()
        sc = scenario_for_run(s)
        self.world = world = World(sc)
        stations = [rx for rx in world.receivers if rx.kind == "station"]
        train_rx = [rx for rx in world.receivers if rx.kind == "train"]
        station_xyz = {rx.id: rx.ecef[0] for rx in stations}
        if world.track is not None:
            for rx in stations:
                llh = ecef_to_geodetic(rx.ecef[0])
                en = world.track.geodetic_to_plane(np.degrees(llh[0]), np.degrees(llh[1]))
                d = np.linalg.norm(world.track.centre_xy - en, axis=1)
                self.station_km[rx.id] = float(world.track.s_m[int(np.argmin(d))] / 1000.0)

        # store
        from augnet.store.db import open_store
        sessions = open_store(s.db_url)
        self.sessions = sessions
        self.writer = persistence.StoreWriter(sessions)
        pw_station, pw_train = secrets.token_urlsafe(12), secrets.token_urlsafe(12)
        self.credentials = {"station_user": STATION_USER, "station_password": pw_station,
                            "train_user": TRAIN_USER, "train_password": pw_train}
        h_station, h_train = await loop.run_in_executor(None, lambda: (hash_password(pw_station),
                                                                        hash_password(pw_train)))

        def seed(db):
            enabled = {}
            for rx in stations:
                enabled[rx.id] = persistence.register_station(db, rx.id, rx.id, rx.ecef[0], rx.rtcm_id,
                                                              mountpoint_of("station", rx.id))
                persistence.register_mountpoint(db, rx.id, "source", TRAIN_GROUP, STATION_GROUP)
            for rx in train_rx:
                persistence.register_mountpoint(db, mountpoint_of("train", rx.id), "source", TRAIN_GROUP,
                                                STATION_GROUP)
            persistence.register_mountpoint(db, VRS_MOUNT, "vrs", TRAIN_GROUP)
            persistence.register_caster_user(db, STATION_USER, h_station, STATION_GROUP)
            persistence.register_caster_user(db, TRAIN_USER, h_train, TRAIN_GROUP)
            return enabled

        enabled = await asyncio.wrap_future(self.writer.submit(seed)) or {}

        # centre (its own process, started below once the caster taps are in place)
        spec = CentreSpec({k: tuple(float(x) for x in v) for k, v in station_xyz.items()}, world.t0, sc.name)
        self.centre = CentreService(spec, loop, on_epoch=self._on_epoch, on_outbox=self._on_outbox,
                                    on_alarm=self._alarm, on_written=self._on_vrs_written)
        for code, on in enabled.items():
            if not on:
                self.centre.set_station_enabled(code, False)

        # caster
        mounts = []
        for rx in stations:
            llh = np.degrees(ecef_to_geodetic(rx.ecef[0])[:2])
            mounts.append(MountConfig(rx.id, "source", frozenset({TRAIN_GROUP}), frozenset({STATION_GROUP}),
                                      {"identifier": rx.id, "latitude": round(float(llh[0]), 4),
                                       "longitude": round(float(llh[1]), 4), "network": sc.name}))
        for rx in train_rx:
            mounts.append(MountConfig(mountpoint_of("train", rx.id), "source", frozenset({TRAIN_GROUP}),
                                      frozenset({STATION_GROUP}), {"identifier": f"train {rx.id} raw"}))
        mounts.append(MountConfig(VRS_MOUNT, "vrs", frozenset({TRAIN_GROUP}), frozenset(),
                                  {"identifier": f"{sc.name} VRS", "network": sc.name}))
        users = {STATION_USER: User(STATION_USER, h_station, frozenset({STATION_GROUP})),
                 TRAIN_USER: User(TRAIN_USER, h_train, frozenset({TRAIN_GROUP}))}
        cfg = CasterConfig(host=s.host, port=s.caster_port, identifier="augnet", operator="augnet up",
                           users=users, mounts=tuple(mounts))
        self.caster = Caster(cfg, {VRS_MOUNT: self.centre})
        port = await self.caster.start()
        for rx in stations:
            self.caster.tap(rx.id, lambda data, code=rx.id: self.centre.feed(code, data))
        await self.centre.start()

        # bus
        from augnet.bus import open_bus
        self.bus = await open_bus(s.bus_url or None)

        # RSSP-I link to the RBC simulator
        if s.rbc and world.track is not None:
            from augnet.system.rbc_link import RbcConnection, SectionPlan
            plan = SectionPlan(world.track.length_m / 1000.0, self.station_km)
            self.rbc = RbcConnection(plan, {rx.id: rx.rtcm_id for rx in stations})
            await self.rbc.start(s.host)

        # live state + console
        self.live = self._make_live_state(world, stations)
        await self._start_console()

        # trains
        db_dict = track_database(sc, world.track) if world.track is not None else None
        track_db = TrackDatabase.from_dict(db_dict) if db_dict else None
        for rx in train_rx:
            tr = OnboardTrain(rx.id, lambda: world.nav, track_db, "127.0.0.1", port, VRS_MOUNT,
                              user=TRAIN_USER, password=pw_train, on_output=self._on_train_output,
                              hold=self.centre.delivering)
            self.caster.tap(mountpoint_of("train", rx.id), tr.on_rover_bytes)
            tr.start()
            self.trains[rx.id] = tr
            sid_future = self.writer.submit(lambda db, code=rx.id: persistence.open_train_session(db, code, VRS_MOUNT))
            sid_future.add_done_callback(lambda f, code=rx.id: self.train_sessions.__setitem__(code, f.result()))

        # stations last: they feed everything above
        self._tasks.append(asyncio.ensure_future(run_stations(
            sc, "127.0.0.1", port, user=STATION_USER, password=pw_station, stop=self.stop_event, world=world)))
        self._tasks.append(asyncio.ensure_future(self._housekeeping()))
        self._write_state(port)
        # what start-up built (the simulated world, the console, modules) lives as long as the run: out of
        # the cyclic garbage collector's sight, whose full passes over it stalled the loop 0.1-0.4 s
        gc.freeze()
        self.ready.set()

    def _make_live_state(self, world: World, stations):
        try:
            from augnet.console.live import LiveState, StationLive
        except ImportError:  # console not installed: the system runs without it
            return None
        live = LiveState()
        for rx in stations:
            llh = ecef_to_geodetic(rx.ecef[0])
            live.update_station(StationLive(id=rx.id, station_id=rx.rtcm_id, lat_deg=float(np.degrees(llh[0])),
                                            lon_deg=float(np.degrees(llh[1])), h_m=float(llh[2]),
                                            along_km=self.station_km.get(rx.id), up=False, enabled=True,
                                            last_data_age_s=None, satellites=0))
        if world.track is not None:
            poly = world.track.plane_to_geodetic(np.column_stack([world.track.centre_xy, world.track.rail_h]))
            step = max(1, len(poly) // 400)
            live.set_line({"id": world.scenario.line.id, "length_km": world.track.length_m / 1000.0,
                           "polyline": np.round(poly[::step, :2], 6).tolist()})
        live.caster_snapshot = lambda: self.caster.snapshot(clients=True) if self.caster else {}
        live.on_station_change = self._on_station_change
        return live

    async def _start_console(self) -> None:
        if self.live is None or not self.settings.console_port:
            return
        import uvicorn

        from augnet.console.app import create_app
        from augnet.console.security import ensure_admin, issue_operator_token

        def admin_token():
            boot = ensure_admin(self.sessions, ADMIN_NAME, self.settings.admin_password or None)
            if boot is not None:  # a new store: the first admin, its password shown once
                self.admin_password_created = boot.password
                return boot.token
            try:  # an existing store: a fresh session token for its admin, if there is one
                return issue_operator_token(self.sessions, ADMIN_NAME)
            except Exception:  # noqa: BLE001 - no operator of that name: log in with your own account
                return None

        self.admin_token = await asyncio.get_running_loop().run_in_executor(None, admin_token)
        app = create_app(self.sessions, self.live)

        class _EmbeddedServer(uvicorn.Server):
            @contextlib.contextmanager
            def capture_signals(self):  # the system owns SIGINT/SIGTERM, not uvicorn
                yield

        config = uvicorn.Config(app, host=self.settings.host, port=self.settings.console_port,
                                log_level="warning", lifespan="on", access_log=False)
        self.console_server = _EmbeddedServer(config)
        self._tasks.append(asyncio.ensure_future(self.console_server.serve()))
        for _ in range(200):  # wait until it listens (or failed)
            if self.console_server.started or self._tasks[-1].done():
                break
            await asyncio.sleep(0.05)
        if self._tasks[-1].done():
            raise RuntimeError(f"console could not start on port {self.settings.console_port}")

    def _write_state(self, caster_port: int) -> None:
        if self.settings.state_path is None:
            return
        state = {"console_url": self.console_url, "admin_token": self.admin_token,
                 "caster": {"host": "127.0.0.1", "port": caster_port, "vrs_mount": VRS_MOUNT,
                            "user": self.credentials["train_user"], "password": self.credentials["train_password"]},
                 "scenario": self.settings.scenario, "pid": __import__("os").getpid()}
        path = Path(self.settings.state_path)
        path.write_text(json.dumps(state, indent=2))
        path.chmod(0o600)  # credentials inside

    @property
    def console_url(self) -> str | None:
        if self.console_server is None:
            return None
        return f"http://{self.settings.host}:{self.settings.console_port}/"

    # --- the centre's outputs (on the loop) ------------------------------------------------------------

    def _on_outbox(self, items: list[tuple[str, bytes]]) -> None:
        if self.bus is None:
            return
        for subject, payload in items:
            asyncio.ensure_future(self._publish(subject, payload))

    async def _publish(self, subject: str, payload: bytes) -> None:
        try:
            await self.bus.publish(subject, payload)
        except Exception:  # noqa: BLE001 - a bus outage must not stop the centre; counted by the bus
            log.warning("bus publish to %s failed", subject)

    def _on_vrs_written(self, t_gpst: float) -> None:
        """Every client has the epoch's VRS: the onboard trains, held meanwhile, process theirs."""
        for tr in self.trains.values():
            tr.resume()

    def _on_epoch(self, r: EpochReport, done_at: float) -> None:
        self.last_report = r
        ne = r.network
        self.correction_age_s.append(max(0.0, gtime.now_gpst() - r.t_gpst))
        del self.correction_age_s[:-3600]
        present = set(ne.present)
        fixed = ne.fixed_fraction()
        if self.rbc is not None:
            self.rbc.on_epoch(r.t_gpst, time.monotonic(), present, fixed, ne.excluded, ne.alarms)
        for a in ne.alarms:
            self._alarm(a.kind, a.subject, a.severity, a.message, a.cleared)
        if self.live is not None:
            self._publish_network(r)
        now = time.time()
        if now - self._last_quality >= QUALITY_INTERVAL_S and self.writer is not None:
            self._last_quality = now
            at = dt.datetime.now(dt.timezone.utc).replace(microsecond=0, tzinfo=None)
            rows = []
            for key, b in ne.baselines.items():
                if b is None:
                    continue
                rows.append((key, float(b.fixed_fraction), _fixed_residual_rms_m(b), int(len(b.sats))))
            self.writer.submit(lambda db: persistence.record_quality_batch(db, at, rows))

    def _alarm(self, kind: str, subject: str, severity: str, message: str, cleared: bool) -> None:
        from augnet.store import queries
        from augnet.store.models import Severity

        key = (kind, subject)
        if cleared:
            if key in self._open_alarms:
                self._open_alarms.discard(key)
                self.writer.submit(lambda db: queries.clear_alarm(db, kind, subject))
            return
        if key in self._open_alarms:
            return
        self._open_alarms.add(key)
        self.alarm_log.append({"kind": kind, "subject": subject, "severity": severity, "message": message,
                               "at_utc": dt.datetime.now(dt.timezone.utc).isoformat()})
        sev = Severity(severity) if severity in {m.value for m in Severity} else Severity.WARNING
        self.writer.submit(lambda db: queries.raise_alarm(db, kind, subject, sev, message))
        if self.live is not None and hasattr(self.live, "publish"):
            self.live.publish({"type": "alarm", "kind": kind, "subject": subject, "severity": severity})

    def _publish_network(self, r: EpochReport) -> None:
        from augnet.console.live import BaselineLive

        ne = r.network
        now = time.time()
        for code, st in list(self.live.stations.items()):
            up = code in ne.present
            self.live.update_station(dataclasses.replace(
                st, up=up, enabled=code not in self.centre.excluded_stations,
                last_data_age_s=round(max(0.0, gtime.now_gpst() - r.t_gpst), 3) if up else None,
                satellites=int(len(ne.sats)) if up else 0))
        baselines = []
        pos = {n: ne.station_xyz_m[i] for i, n in enumerate(ne.stations)}
        for key, b in ne.baselines.items():
            a, c = key.split("-", 1)
            length = float(np.linalg.norm(pos[a] - pos[c])) / 1000.0 if a in pos and c in pos else math.nan
            if b is None:
                baselines.append(BaselineLive(a, c, length, "none", 0.0, None))
                continue
            frac = float(b.fixed_fraction)
            state = "fixed" if frac >= 0.5 else "float"
            rms = _fixed_residual_rms_m(b)
            baselines.append(BaselineLive(a, c, length, state, round(frac, 3), None if rms is None else round(rms * 100.0, 2)))
        self.live.set_baselines(baselines)
        ages = np.array(self.correction_age_s[-300:]) if self.correction_age_s else np.array([np.nan])
        self.live.set_network({
            "epoch_gpst": r.t_gpst, "epoch_utc": gtime.to_datetime(r.t_gpst).isoformat(), "master": ne.master,
            "stations_present": len(ne.present), "stations": len(ne.stations), "satellites": int(len(ne.sats)),
            "excluded": sorted(ne.excluded), "sessions": r.sessions,
            "vrs_model": r.vrs_models, "misclosures": ne.misclosures,
            "correction_age_p99_s": float(np.nanpercentile(ages, 99)),
            "solve_ms_p99": self.centre.solve_ms_p99(), **self.centre.latency_ms_p99(), "rbc": self.rbc.snapshot() if self.rbc else None,
            "updated_unix": now,
        })

    # --- trains -----------------------------------------------------------------------------------------

    def _on_train_output(self, train: OnboardTrain, out) -> None:
        if self.live is None:
            return
        now = time.time()
        if now - self._last_train_publish.get(train.id, 0.0) < LIVE_PUBLISH_INTERVAL_S:
            return
        self._last_train_publish[train.id] = now
        from augnet.console.live import TrainLive

        sol, m = out.solution, out.match
        p = np.asarray(sol.position_m, float)
        if not np.all(np.isfinite(p)):
            return
        llh = ecef_to_geodetic(p)
        hpl, vpl = train.protection_levels()
        v = np.asarray(sol.velocity_m_s, float)
        speed = float(np.linalg.norm(v) * 3.6) if np.all(np.isfinite(v)) else None
        self.live.update_train(TrainLive(
            id=train.id, lat_deg=float(np.degrees(llh[0])), lon_deg=float(np.degrees(llh[1])), h_m=float(llh[2]),
            track_id=m.track if m is not None else None, along_km=(round(m.km, 4) if m is not None and m.track else None),
            cross_track_m=(round(m.cross_m, 3) if m is not None and m.track else None),
            fix_state=sol.status_name,
            correction_age_s=train.correction_age_s(), hpl_m=hpl, vpl_m=vpl, speed_kmh=speed, updated_unix=now))

    # --- station changes from the console -----------------------------------------------------------------

    def _on_station_change(self, code: str, fields: dict) -> None:
        if self.centre is None or "enabled" not in fields:
            return
        self.centre.set_station_enabled(code, bool(fields["enabled"]))

    # --- running ------------------------------------------------------------------------------------------

    async def _housekeeping(self) -> None:
        """Re-read operator decisions the console stored (a station disabled through the API of another
        console instance, for example) every few seconds."""
        while not self.stop_event.is_set():
            try:
                await asyncio.wait_for(self.stop_event.wait(), 5.0)
            except asyncio.TimeoutError:
                pass
            fut = self.writer.submit(persistence.station_enabled_map)
            try:
                enabled = await asyncio.wrap_future(fut)
            except Exception:  # noqa: BLE001
                continue
            for code, on in (enabled or {}).items():
                if code in self.centre.stations:
                    self.centre.set_station_enabled(code, on)

    async def run(self, duration_s: float | None = None) -> RunSummary:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, self.stop_event.set)
        try:
            await self.start()
            if duration_s:
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(self.stop_event.wait(), duration_s)
            else:
                await self.stop_event.wait()
        finally:
            summary = self.summary()
            await self.shutdown()
        return summary

    async def shutdown(self) -> None:
        self.stop_event.set()
        for tr in self.trains.values():
            await tr.stop()
            sid = self.train_sessions.get(tr.id)
            if sid is not None and self.writer is not None:
                n = max(1, tr.stats.epochs)
                rate = tr.stats.by_status.get("fix", 0) / n
                self.writer.submit(lambda db, sid=sid, rate=rate, b=tr.base_dec.stats.bytes:
                                   persistence.close_train_session(db, sid, b, rate))
        if self.console_server is not None:
            self.console_server.should_exit = True
        if self.rbc is not None:
            await self.rbc.stop()
        if self.centre is not None:
            await self.centre.stop()
        if self.caster is not None:
            await self.caster.stop()
        if self.bus is not None:
            bus, self.bus = self.bus, None  # nothing more is published from here on
            with contextlib.suppress(Exception):
                await bus.close()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self.writer is not None:
            self.writer.close()

    def summary(self) -> RunSummary:
        out = RunSummary(scenario=self.settings.scenario,
                         started_utc=dt.datetime.fromtimestamp(self.started, dt.timezone.utc).isoformat(),
                         duration_s=round(time.time() - self.started, 1),
                         stations=sorted(self.centre.stations) if self.centre else [])
        if self.centre is not None:
            out.network_epochs = self.centre.timings.epochs
            out.centre_solve_ms_p99 = self.centre.solve_ms_p99()
            out.centre_latency = self.centre.latency_ms_p99()
            out.centre_stages_ms = self.centre.stages_ms()
            out.centre_errors = self.centre.errors
            out.centre_restarts = self.centre.restarts
        for tid, tr in self.trains.items():
            lat = np.array(tr.stats.correction_latency_s) if tr.stats.correction_latency_s else np.array([np.nan])
            n = max(1, tr.stats.epochs)
            out.trains[tid] = {
                "epochs": tr.stats.epochs, "status_counts": dict(tr.stats.by_status),
                "fix_rate": round(tr.stats.by_status.get("fix", 0) / n, 4),
                "time_to_first_fix_s": tr.stats.first_fix_s, "vrs_epochs": tr.stats.vrs_epochs,
                "correction_latency_p50_s": _pct(lat, 50), "correction_latency_p99_s": _pct(lat, 99),
                "base_moves": tr.stats.base_moves, "base_resets": tr.stats.base_resets,
                "balises": [b.balise_id for b in tr.stats.balises], "errors": tr.stats.errors,
                "holds_fix": bool(tr.last is not None and int(tr.last.solution.status) == 1),
            }
        out.alarms = list(self.alarm_log)
        out.rbc = self.rbc.snapshot() if self.rbc else {}
        if self.caster is not None:
            snap = self.caster.snapshot(clients=False)
            out.caster = {"port": snap["port"], "counters": snap["counters"],
                          "mounts": {k: {kk: v.get(kk) for kk in ("bytes_in", "bytes_out", "clients_total")}
                                     for k, v in snap["mounts"].items()}}
        if self.writer is not None:
            out.store = {"writes": self.writer.writes, "failures": self.writer.failures}
        return out


def _fixed_residual_rms_m(b) -> float | None:
    """RMS of a baseline's non-dispersive DD residuals over its fixed satellites [m] (None when none fixed)."""
    return float(np.sqrt(np.nanmean(b.dd_trop_m[b.fixed] ** 2))) if b.fixed.any() else None


def _pct(a: np.ndarray, q: float) -> float | None:
    a = a[np.isfinite(a)]
    return round(float(np.percentile(a, q)), 3) if a.size else None


__all__ = ["System", "SystemSettings", "RunSummary", "scenario_for_run", "SUBJECT_ALARMS"]
