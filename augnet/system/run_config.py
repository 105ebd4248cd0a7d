"""The configuration of one `augnet up` run, computed before anything starts: the scenario as the run
plays it, where the stations sit along the line, the caster's mountpoints and users (the seed of an empty
store: decision 0180), and what the store records of them. Pure functions (the store one runs in the store writer's session)."""

from __future__ import annotations

import math

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.system import persistence
from augnet.system.settings import DEFAULT_LIVE_WINDOW_S, START_MARGIN_S, SystemSettings
from ntrip_caster.config import CasterConfig, MountConfig, User
from stations.live import mountpoint_of
from stations.scenario import Scenario, Train, load_scenario
from stations.world import World

VRS_MOUNT = "VRS"
STATION_GROUP, TRAIN_GROUP = "stations", "trains"
STATION_USER, TRAIN_USER = "stations", "train"
RUN_END_MARGIN_S = 10.0  # with --duration, the simulated world runs this much longer than the run
# Trains beyond the scenario's own: the k-th starts at fraction (k * EXTRA_TRAIN_STEP mod 1) of the line
# between its end margins (a step that does not divide 1 spreads them without repeats), in alternating
# directions, at these speeds in turn.
EXTRA_TRAIN_STEP = 0.37
LINE_END_MARGIN_KM = 10.0
EXTRA_TRAIN_SPEEDS_KMH = (160.0, 200.0, 250.0, 300.0)
# The sourcetable's names of the systems a stream carries (STR field 7, NTRIP 2.0: "GPS+GLO+GAL+BDS")
NAV_SYSTEM_NAMES = {"G": "GPS", "R": "GLO", "E": "GAL", "C": "BDS", "J": "QZS"}


def scenario_for_run(settings: SystemSettings, now_gpst: float | None = None) -> Scenario:
    """The scenario as this run plays it: starting a moment from now, for the run's window, with the
    requested number of trains (the scenario's own first, then more spread along the line)."""
    sc = load_scenario(settings.scenario)
    now = gtime.now_gpst() if now_gpst is None else now_gpst
    start = gtime.to_datetime(float(math.ceil(now + START_MARGIN_S))).replace(microsecond=0)
    window = settings.duration_s + RUN_END_MARGIN_S if settings.duration_s else DEFAULT_LIVE_WINDOW_S
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
            start_km = (k * EXTRA_TRAIN_STEP % 1.0) * (line_km - 2 * LINE_END_MARGIN_KM) + LINE_END_MARGIN_KM
            speed = EXTRA_TRAIN_SPEEDS_KMH[k % len(EXTRA_TRAIN_SPEEDS_KMH)]
            trains.append(Train(id=f"T{k:03d}", track=1 if direction > 0 else min(2, sc.line.tracks),
                                start_km=round(start_km, 3), direction=direction, start_speed_kmh=speed,
                                speed_kmh=speed))
    return sc.model_copy(update={"start": start, "duration_s": int(math.ceil(window)), "trains": trains})


def station_along_km(world: World, stations) -> dict[str, float]:
    """Each station's place along the line [km] (none without a line)."""
    if world.track is None:
        return {}
    return {rx.id: along_line_km(world, rx.ecef[0]) for rx in stations}


def along_line_km(world: World, xyz_m) -> float | None:
    """The place along the line [km] of ECEF `xyz_m`: the nearest point of the track's centre line (None
    without a line)."""
    if world is None or world.track is None:
        return None
    llh = ecef_to_geodetic(np.asarray(xyz_m, float))
    en = world.track.geodetic_to_plane(np.degrees(llh[0]), np.degrees(llh[1]))
    d = np.linalg.norm(world.track.centre_xy - en, axis=1)
    return float(world.track.s_m[int(np.argmin(d))] / 1000.0)


def register_run(db, stations, cfg: CasterConfig, accounts: dict[str, tuple[str | None, str, str]]
                 ) -> tuple[dict[str, persistence.StationRecord], dict[str, str | None]]:
    """Store the run's configuration (in the store writer's session `db`): the scenario's stations into a store
    that never had any, its caster users and mountpoints `cfg` into one that has none yet (decision 0180: after that
    the store alone decides, so a station or user an operator deleted stays deleted). `accounts`: for each of
    the run's own caster users, the password of the last state file (or None), a fresh one and its hash (`cfg`
    holds that hash). Returns the store's stations (what the network is built from) and the password each own
    account logs in with (None: it cannot)."""
    persistence.seed_stations(db, stations)
    records = persistence.station_records(db)
    if persistence.seed_caster(db, cfg):
        return records, {name: fresh for name, (_known, fresh, _h) in accounts.items()}
    return records, {name: persistence.own_account_password(db, name, known, fresh, fresh_hash)
                     for name, (known, fresh, fresh_hash) in accounts.items()}


def nav_system(sc: Scenario) -> str:
    """What the run's streams carry: the scenario's constellations (stations, train receivers and the VRS
    encode those and no other)."""
    return "+".join(NAV_SYSTEM_NAMES[s] for s in sc.constellations)


def caster_config(settings: SystemSettings, sc: Scenario, stations, train_rx, hashes: dict[str, str]) -> CasterConfig:
    """The scenario's caster mountpoints (a source per station and per train's raw stream, the VRS) and users:
    what an empty store is seeded with, and the STR fields the store does not keep."""
    mounts = []
    nav = nav_system(sc)
    for rx in stations:
        llh = np.degrees(ecef_to_geodetic(rx.ecef[0])[:2])
        mounts.append(MountConfig(rx.id, "source", frozenset({TRAIN_GROUP}), frozenset({STATION_GROUP}),
                                  {"identifier": rx.id, "latitude": round(float(llh[0]), 4),
                                   "longitude": round(float(llh[1]), 4), "network": sc.name, "nav_system": nav}))
    for rx in train_rx:
        mounts.append(MountConfig(mountpoint_of("train", rx.id), "source", frozenset({TRAIN_GROUP}),
                                  frozenset({STATION_GROUP}), {"identifier": f"train {rx.id} raw", "nav_system": nav}))
    mounts.append(MountConfig(VRS_MOUNT, "vrs", frozenset({TRAIN_GROUP}), frozenset(),
                              {"identifier": f"{sc.name} VRS", "network": sc.name, "nav_system": nav}))
    users = {STATION_USER: User(STATION_USER, hashes[STATION_USER], frozenset({STATION_GROUP})),
             TRAIN_USER: User(TRAIN_USER, hashes[TRAIN_USER], frozenset({TRAIN_GROUP}))}
    return CasterConfig(host=settings.host, port=settings.caster_port, identifier="augnet", operator="augnet up",
                        users=users, mounts=tuple(mounts))
