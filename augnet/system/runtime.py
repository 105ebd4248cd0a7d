"""`augnet up`: the whole system run by one asyncio process (the centre in a child process of its own),
wired in the order the data flows.

    simulated stations --NTRIP sources--> caster :2101 --taps--> centre (its own process: centre_service.py)
    centre --VRS per train (stream factory)--> caster VRS mountpoint --NTRIP + GGA--> onboard trains
    centre --correction model, alarms--> bus;  centre --RSSP-I over loopback UDP--> RBC simulator
    trains --position reports (UDP)--> section register --SECTION_TRAINS (RSSP-I)--> RBC, and --> store
    everything --> live state --> console :8000 (REST, websocket, web page) and the terminal view
    configuration, sessions, alarms, quality history --> store (SQLite file, or PostgreSQL by URL)

`System.start` takes one step per part: store, centre (created), caster (then the centre's process starts
behind its taps), bus, RBC link, section register, live state and console, trains, then the stations that
feed them all.
`shutdown` stops the stations' feed first and the rest backwards, so nothing writes into a closed neighbour.

This module only wires and routes; each subject lives in its own module: the run's configuration (scenario,
caster mountpoints and users, store records) in `run_config.py`, what the operator sees in `live_state.py`,
what the store keeps in `persistence.py`, the run report in `run_report.py`.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import os
import secrets
import signal
import time
from dataclasses import replace

import numpy as np

from augnet.centre.engine import SUBJECT_ALARMS, EpochReport
from augnet.gnss import time as gtime
from augnet.onboard.trackmap import TrackDatabase
from augnet.store import queries as store_queries
from augnet.system import persistence
from augnet.system.centre_service import CentreService, CentreSpec
from augnet.system.history_series import series_values
from augnet.system.live_state import LivePublisher, make_live_state, station_live
from augnet.system.run_config import (STATION_USER, TRAIN_USER, VRS_MOUNT, caster_config, register_run,
                                      scenario_for_run, station_along_km)
from augnet.system.run_report import RunReport, run_report
from augnet.system.settings import SystemSettings
from augnet.system.train_alarms import TrainCorrectionWatch
from augnet.system.trains import OnboardTrain
from augwire.passwords import hash_password
from ntrip_caster.server import Caster
from stations.live import mountpoint_of, run_stations
from stations.scenario import Scenario
from stations.trackmap_export import track_database
from stations.world import World

log = logging.getLogger(__name__)

ADMIN_NAME = "admin"
LOCALHOST = "127.0.0.1"  # the in-process stations and trains reach the caster here
CONSOLE_START_POLLS, CONSOLE_START_POLL_S = 200, 0.05  # the console must listen within 10 s


class System:
    """The running parts of `augnet up` and the routes between them (see the module's docstring)."""

    def __init__(self, settings: SystemSettings):
        self.settings = settings.validate()
        self.stop_event = asyncio.Event()
        self.ready = asyncio.Event()
        self.started = time.time()
        self.world: World | None = None
        self.station_km: dict[str, float] = {}  # each station's place along the line [km]
        self.sessions = None  # the store's session factory
        self.writer: persistence.StoreWriter | None = None
        self.alarms: persistence.AlarmRecorder | None = None
        self.quality: persistence.QualityHistory | None = None
        self.credentials: dict[str, str] = {}
        self.centre: CentreService | None = None
        self.caster: Caster | None = None
        self.caster_access = None  # CasterAccessSync: the caster's tables follow the store
        self.station_sync = None  # StationSync: the network's stations follow the store's registry
        self.bus = None
        self.rbc = None
        self.publisher = LivePublisher()
        self.console_server = None
        self.admin_token: str | None = None
        self.admin_name = ADMIN_NAME
        self.admin_password: str | None = None  # into the state file, never to stdout
        self.admin_password_created = False
        self.trains: dict[str, OnboardTrain] = {}
        self.atp: dict = {}  # train id -> AtpConnection: its RSSP-I link and ATP simulator
        self.train_watch = TrainCorrectionWatch()  # a train's stale corrections are an operator's alarm
        self.train_sessions: dict[str, int] = {}
        self.sections = None  # SectionService: the trains per line section, from their position reports
        self._section_rx = None  # its UDP endpoint (the trains' radio link)
        self.reporters: dict = {}  # train id -> TrainReporter
        self._senders: list = []
        self._section_address = None
        self._tasks: list[asyncio.Task] = []

    # --- start-up, one step per part in the order the data flows ----------------------------------------

    async def start(self) -> None:
        sc = scenario_for_run(self.settings)
        self.world = world = World(sc)
        stations = [rx for rx in world.receivers if rx.kind == "station"]
        train_rx = [rx for rx in world.receivers if rx.kind == "train"]
        self.station_km = station_along_km(world, stations)
        self._open_store()
        accounts = await self._make_credentials()
        seed = caster_config(self.settings, sc, stations, train_rx, {n: h for n, (_k, _p, h) in accounts.items()})
        records = await self._register_run(stations, seed, accounts)
        self._make_centre(sc, records)
        port = await self._start_caster(seed, records)
        await self.centre.start()  # its process starts once the caster's taps are in place
        await self._start_bus()
        await self.caster_access.start()  # from here on the console's changes reach the caster
        await self.station_sync.start()  # ... and the registry's reach the network
        await self._start_rbc(stations)
        await self._start_sections(sc)
        await self._start_console(records)
        await self._start_trains(sc, train_rx, port)
        self._start_stations(sc, port)  # last: they feed everything above
        self._write_state(port)
        # what start-up built (the simulated world, the console, modules) lives as long as the run: out of
        # the cyclic garbage collector's sight, whose full passes over it stall the loop (decision 0071)
        gc.freeze()
        self.ready.set()

    def _open_store(self) -> None:
        from augnet.store.db import open_store

        self.sessions = open_store(self.settings.db_url)
        self.writer = persistence.StoreWriter(self.sessions)
        self.alarms = persistence.AlarmRecorder(self.writer)
        self.quality = persistence.QualityHistory(self.writer)

    async def _make_credentials(self) -> dict[str, tuple[str | None, str, str]]:
        """For the stations' and the trains' caster accounts: the password of the last state file (None
        without one), a fresh random one and its hash (hashed off the loop: scrypt takes tens of ms)."""
        from augnet.console.statefile import read_state

        last = read_state(self.settings.state_path).get("caster") or {}
        last = last if isinstance(last, dict) else {}
        known = {STATION_USER: last.get("station_password") if last.get("station_user") == STATION_USER else None,
                 TRAIN_USER: last.get("password") if last.get("user") == TRAIN_USER else None}
        fresh = {name: secrets.token_urlsafe(12) for name in known}
        hashes = await asyncio.get_running_loop().run_in_executor(
            None, lambda: {name: hash_password(pw) for name, pw in fresh.items()})
        return {name: (k if isinstance(k, str) else None, fresh[name], hashes[name]) for name, k in known.items()}

    async def _register_run(self, stations, seed, accounts) -> dict[str, persistence.StationRecord]:
        """The run's stations, caster users and mountpoints into an empty store; the password each of the
        run's own accounts logs in with. Returns the store's station registry (the network is built from it:
        an operator's earlier decisions stand)."""
        fut = self.writer.submit(lambda db: register_run(db, stations, seed, accounts))
        records, passwords = await asyncio.wrap_future(fut) or ({}, {})
        if not records:
            raise RuntimeError("the store registers no reference station: the network has nothing to solve "
                               "(start on a fresh store, or add a station to this one's registry)")
        for name in accounts:
            if passwords.get(name) is None:
                log.warning("caster user %s is missing or was changed by an operator: the run's own %s cannot "
                            "log in to the caster until an operator restores it", name,
                            "stations" if name == STATION_USER else "trains")
        use = {name: passwords.get(name) or accounts[name][1] for name in accounts}
        self.credentials = {"station_user": STATION_USER, "station_password": use[STATION_USER],
                            "train_user": TRAIN_USER, "train_password": use[TRAIN_USER]}
        return records

    def _make_centre(self, sc: Scenario, records: dict[str, persistence.StationRecord]) -> None:
        """The centre service on the registry's stations (its process starts later; the disabled ones' data is
        left out once the caster's taps are set: `_start_caster`)."""
        xyz = {code: rec.xyz_m for code, rec in records.items()}
        spec = CentreSpec(xyz, self.world.t0, sc.name, area=self.settings.area(), admission=self.settings.admission)
        self.centre = CentreService(spec, asyncio.get_running_loop(), on_epoch=self._on_epoch,
                                    on_outbox=self._on_outbox, on_alarm=self._alarm,
                                    on_written=self._on_vrs_written)

    async def _start_caster(self, seed, records: dict[str, persistence.StationRecord]) -> int:
        """The caster with the store's users and mountpoints (the scenario's `seed` completes their STR
        records) and the centre as its VRS stream factory, each registered station's stream tapped into the
        centre; returns its port. Its tables follow the store from then on (`caster_access.py`), and the
        network's stations the registry (`station_membership.py`)."""
        from augnet.system.caster_access import CasterAccessSync, bound_mounts, caster_tables
        from augnet.system.station_membership import StationSync

        described = {m.name: m for m in seed.mounts}
        fut = self.writer.submit(lambda db: (*caster_tables(db, described), bound_mounts(db)))
        users, mounts, bound = await asyncio.wrap_future(fut) or ({}, [], frozenset())
        self.centre.set_bound_mounts(bound)  # the 4001 opt-in per mountpoint (decision 0281), then live
        self.caster = Caster(replace(seed, users=users, mounts=tuple(mounts)), {VRS_MOUNT: self.centre})
        self.caster.on_alarm = self._alarm  # a bad-password flood is an operator's alarm (issue 19)
        self.caster_access = CasterAccessSync(self.caster, self.sessions, described,
                                              on_bound_mounts=self.centre.set_bound_mounts)
        port = await self.caster.start()
        self.station_sync = StationSync(self.centre, self.caster, self.sessions, on_applied=self._on_membership)
        self.station_sync.adopt(records)
        return port

    async def _start_bus(self) -> None:
        from augnet.bus import open_bus

        self.bus = await open_bus(self.settings.bus_url or None)
        self.caster_access.bus = self.bus
        self.station_sync.bus = self.bus

    async def _start_rbc(self, stations) -> None:
        """The RSSP-I link to the RBC simulator (a line is needed: its sections are stretches of it)."""
        if not self.settings.rbc or self.world.track is None:
            return
        from augnet.system.rbc_link import RbcConnection, SectionPlan

        plan = SectionPlan(self.world.track.length_m / 1000.0, self.station_km)
        self.rbc = RbcConnection(plan, {rx.id: rx.rtcm_id for rx in stations}, on_alarm=self._alarm)
        await self.rbc.start(self.settings.host)

    async def _start_sections(self, sc: Scenario) -> None:
        """The section register (decision 0292): the trains' position reports in over UDP, its picture to
        the store and the RBC every `SECTION_FLUSH_S`."""
        if self.world.track is None:
            return
        from augnet.system.section_service import SectionService, open_receiver, stations_of

        self.sections = SectionService(stations_of(sc), self.world.track.length_m / 1000.0,
                                       on_audit=self._section_audit, on_alarm=self._alarm)
        self._section_rx, self._section_address = await open_receiver(self.sections, LOCALHOST)
        self._tasks.append(asyncio.ensure_future(self._flush_sections()))

    def _section_audit(self, a) -> None:
        self.writer.submit(lambda db: store_queries.audit(
            db, a.actor, a.action, a.target, reason=a.reason, before=list(a.before), after=list(a.after)))

    async def _flush_sections(self) -> None:
        from augnet.system.section_service import SECTION_FLUSH_S

        while not self.stop_event.is_set():
            await asyncio.sleep(SECTION_FLUSH_S)
            try:
                self.flush_sections()
            except Exception:  # noqa: BLE001 - the store's or the link's trouble must not stop the register
                log.exception("section register flush failed")

    def flush_sections(self) -> None:
        """The sections changed since the last flush: to the RBC (SECTION_TRAINS) and to the store."""
        epoch_ms = int(round(gtime.now_gpst() * 1000))
        for sid, d in self.sections.take_dirty():
            if self.rbc is not None:
                try:
                    self.rbc.centre.set_section_trains(self.sections.telegram(sid, d, epoch_ms))
                except ValueError:  # more trains than one RSD carries: the RBC keeps the last picture that fit
                    self.sections.stats["rbc_picture_too_large"] += 1
                    log.warning("section %s %s: too many trains for one SECTION_TRAINS telegram", sid, d)
            recs = self.sections.records(sid, d)
            self.writer.submit(lambda db, sid=sid, d=d, recs=recs:
                               store_queries.replace_section_trains(db, sid, d, recs))

    async def _start_reporter(self, tr: OnboardTrain) -> None:
        """The train's radio link to the centre's section register."""
        from augnet.system.section_service import TrainReporter, open_sender

        sender = await open_sender(self._section_address)
        self.reporters[tr.id] = TrainReporter(tr, sender.send)
        self._senders.append(sender)

    async def _start_console(self, records) -> None:
        """The live state (whenever the console package is installed), then the console serving it."""
        self.publisher.live = make_live_state(
            self.world, records,
            caster_snapshot=lambda: self.caster.snapshot(clients=True) if self.caster else {},
            on_station_change=self._on_station_change)
        if self.publisher.live is None or not self.settings.console_port:
            return
        import uvicorn

        from augnet.console.app import create_app

        self.admin_token = await asyncio.get_running_loop().run_in_executor(None, self._console_admin_token)
        app = create_app(self.sessions, self.publisher.live, bus=self.bus, sections=self.sections)

        class _EmbeddedServer(uvicorn.Server):
            @contextlib.contextmanager
            def capture_signals(self):  # the system owns SIGINT/SIGTERM, not uvicorn
                yield

        config = uvicorn.Config(app, host=self.settings.host, port=self.settings.console_port,
                                log_level="warning", lifespan="on", access_log=False)
        self.console_server = _EmbeddedServer(config)
        serving = asyncio.ensure_future(self.console_server.serve())
        self._tasks.append(serving)
        for _ in range(CONSOLE_START_POLLS):  # wait until it listens (or failed)
            if self.console_server.started or serving.done():
                break
            await asyncio.sleep(CONSOLE_START_POLL_S)
        if serving.done():
            raise RuntimeError(f"console could not start on port {self.settings.console_port}")

    def _console_admin_token(self) -> str | None:
        """The store's bootstrap token for the console's admin: the one in the last state file while it is
        still valid, else rotated (a new store: the first admin, its password kept in the state file)."""
        from augnet.console.security import bootstrap_admin
        from augnet.console.statefile import read_state

        boot = bootstrap_admin(self.sessions, ADMIN_NAME, self.settings.admin_password or None,
                               read_state(self.settings.state_path))
        if boot is None:  # no enabled admin of that name: log in with your own account
            return None
        self.admin_name, self.admin_password, self.admin_password_created = boot.name, boot.password, boot.created
        return boot.token

    async def _start_trains(self, sc: Scenario, train_rx, port: int) -> None:
        """One onboard train per simulated train receiver: its raw stream tapped from the caster, its VRS
        over NTRIP, a train session in the store, and (on a line with balises) its RSSP-I link to an ATP
        simulator that receives its timer-based virtual balise telegrams (`atp_link.py`)."""
        from augnet.system.atp_link import AtpConnection, balise_groups

        world = self.world
        db_dict = track_database(sc, world.track) if world.track is not None else None
        track_db = TrackDatabase.from_dict(db_dict) if db_dict else None
        groups = balise_groups(track_db) if track_db is not None else []
        for number, rx in enumerate(train_rx, start=1):
            atp = None
            if groups:
                atp = AtpConnection(number, groups)
                await atp.start(self.settings.host)
                self.atp[rx.id] = atp
            tr = OnboardTrain(rx.id, lambda: world.nav, track_db, LOCALHOST, port, VRS_MOUNT,
                              user=TRAIN_USER, password=self.credentials["train_password"],
                              on_output=self._on_train_output, hold=self.centre.delivering,
                              balise_groups=groups, timer_sink=atp.sink if atp is not None else None)
            try:
                self.caster.tap(mountpoint_of("train", rx.id), tr.on_rover_bytes)
            except ValueError:  # not in the store: the train runs without its raw stream
                log.warning("train %s: no source mountpoint %s in the store", rx.id, mountpoint_of("train", rx.id))
            tr.start()
            self.trains[rx.id] = tr
            if self.sections is not None:
                self._tasks.append(asyncio.ensure_future(self._start_reporter(tr)))
            sid_future = self.writer.submit(lambda db, code=rx.id: persistence.open_train_session(db, code, VRS_MOUNT))
            sid_future.add_done_callback(lambda f, code=rx.id: self.train_sessions.__setitem__(code, f.result()))

    def _start_stations(self, sc: Scenario, port: int) -> None:
        self._tasks.append(asyncio.ensure_future(run_stations(
            sc, LOCALHOST, port, user=STATION_USER, password=self.credentials["station_password"],
            stop=self.stop_event, world=self.world)))

    def _write_state(self, caster_port: int) -> None:
        """Where tools find this run: the console's URL, the admin token, the caster and its train account."""
        if self.settings.state_path is None:
            return
        from augnet.console.statefile import write_private

        state = {"console_url": self.console_url, "admin_token": self.admin_token,
                 "caster": {"host": LOCALHOST, "port": caster_port, "vrs_mount": VRS_MOUNT,
                            "user": self.credentials["train_user"], "password": self.credentials["train_password"],
                            # kept for the next run over the same store (its own account's password)
                            "station_user": self.credentials["station_user"],
                            "station_password": self.credentials["station_password"]},
                 "scenario": self.settings.scenario, "pid": os.getpid()}
        if self.admin_password:
            state.update(admin_name=self.admin_name, admin_password=self.admin_password)
        write_private(self.settings.state_path, state)  # 0600 from the first byte: credentials inside

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
        """A solved network epoch: to the RBC link, the alarms, the live state and the quality history."""
        self.publisher.record_epoch(r)
        ne = r.network
        if self.rbc is not None:
            self.rbc.on_epoch(r.t_gpst, time.monotonic(), set(ne.present), ne.fixed_fraction(), ne.excluded,
                              ne.alarms)
        for a in ne.alarms:
            self._alarm(a.kind, a.subject, a.severity, a.message, a.cleared)
        self.publisher.publish_network(r, self.centre, self.rbc)
        if self.quality is not None:
            self.quality.on_epoch(ne, time.time(), lambda: self._history_series(r))

    def _history_series(self, r: EpochReport) -> dict[str, float]:
        """The quality history's network series at this epoch (correction age p99, trains fixed, station
        data age as the console shows it: now minus the epoch for a delivering station)."""
        ne = r.network
        age = max(0.0, gtime.now_gpst() - r.t_gpst)
        states = [t.last.solution.status_name for t in self.trains.values() if t.last is not None]
        return series_values(self.publisher.correction_age_s, states,
                             {code: (age if code in ne.present else None) for code in ne.stations})

    def _alarm(self, kind: str, subject: str, severity: str, message: str, cleared: bool) -> None:
        """Every alarm (centre, caster, RBC, trains) into the store; the pages are told once it is committed."""
        self.alarms.record(kind, subject, severity, message, cleared,
                           on_stored=lambda: self.publisher.publish_alarm(kind, subject, severity, cleared))

    def _on_train_output(self, train: OnboardTrain, out) -> None:
        self.publisher.publish_train(train, out)
        reporter = self.reporters.get(train.id)
        if reporter is not None:
            reporter.on_output(out)
        newest = train.last_base.time if train.last_base is not None else None
        for event in self.train_watch.check(train.id, newest, gtime.now_gpst()):
            self._alarm(*event)

    def _truth_chainage_m(self, train_id: str, t_gpst: float) -> float | None:
        """The simulator's true chainage [m] of a train at `t_gpst`: for the run report's passage errors only
        (truth kept apart: the onboard never reads it)."""
        from stations.kinematics import train_motion

        cfg = next((t for t in self.world.scenario.trains if t.id == train_id), None)
        if cfg is None or self.world.track is None:
            return None
        return float(train_motion(cfg, self.world.track.length_m, np.array([t_gpst - self.world.t0])).s_m[0])

    def _on_station_change(self, code: str, fields: dict) -> None:
        """An operator changed the station registry in this process's console (called on its thread pool):
        the network follows it at once rather than at the next reconcile."""
        if self.station_sync is not None:
            self.station_sync.poke()

    def _on_membership(self, step) -> None:
        """The network took a registry change: the console's station list follows (a station that joined is
        down until its data arrives)."""
        live = self.publisher.live
        if live is None:
            return
        if step.action == "remove":
            live.remove_station(step.code)
            return
        if step.action in ("add", "move"):
            live.update_station(station_live(step.record, self.world))

    # --- running ------------------------------------------------------------------------------------------

    async def run(self, duration_s: float | None = None) -> RunReport:
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
        """The stations stop sending (`stop_event`), then trains, console, RBC link, centre, caster, bus;
        the store writer last, once every part's final write is queued."""
        self.stop_event.set()
        await self._stop_trains()
        for sender in self._senders:
            sender.close()
        if self._section_rx is not None:
            self._section_rx.close()
        if self.sections is not None and self.writer is not None:
            self.flush_sections()  # the register's last picture into the store
        if self.console_server is not None:
            self.console_server.should_exit = True
        if self.rbc is not None:
            await self.rbc.stop()
        if self.station_sync is not None:  # before the centre: no membership step into a stopped one
            await self.station_sync.stop()
        if self.centre is not None:
            await self.centre.stop()
        if self.caster_access is not None:
            await self.caster_access.stop()
        if self.caster is not None:
            await self.caster.stop()
        if self.bus is not None:
            bus, self.bus = self.bus, None  # nothing more is published from here on
            with contextlib.suppress(Exception):
                await bus.close()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self.writer is not None:
            self.writer.close()

    async def _stop_trains(self) -> None:
        """Each train stops (then its ATP link); its store session is closed with the bytes it received and
        its fix rate."""
        for tr in self.trains.values():
            await tr.stop()
            atp = self.atp.get(tr.id)
            if atp is not None:
                await atp.stop()
            sid = self.train_sessions.get(tr.id)
            if sid is not None and self.writer is not None:
                n = max(1, tr.stats.epochs)
                rate = tr.stats.by_status.get("fix", 0) / n
                self.writer.submit(lambda db, sid=sid, rate=rate, b=tr.base_dec.stats.bytes:
                                   persistence.close_train_session(db, sid, b, rate))

    def summary(self) -> RunReport:
        """The run report as of now (`run_report.py`)."""
        rep = run_report(
            self.settings.scenario, self.started, time.time(), centre=self.centre, trains=self.trains,
            atp={k: v.snapshot() for k, v in self.atp.items()}, truth_chainage_m=self._truth_chainage_m,
            alarms=self.alarms.log if self.alarms is not None else [],
            rbc_snapshot=self.rbc.snapshot() if self.rbc else None,
            caster_snapshot=self.caster.snapshot(clients=False) if self.caster is not None else None,
            store_counts=({"writes": self.writer.writes, "failures": self.writer.failures}
                          if self.writer is not None else None))
        if self.sections is not None:
            rep.sections = self.sections.report()
            rep.sections["reports_sent"] = {tid: r.sent for tid, r in self.reporters.items()}
        return rep


__all__ = ["System", "SystemSettings", "RunReport", "SUBJECT_ALARMS"]
