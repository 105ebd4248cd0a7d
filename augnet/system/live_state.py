"""What the operator sees of a running `augnet up`: the parts' state mapped onto the console's `LiveState`
(REST, websocket, web page) and the figures the terminal view reads.

The console package is optional: when `augnet.console` is not installed, `LivePublisher.live` stays None and
only the terminal view's figures are kept.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.system.baseline_quality import FIXED_BASELINE_FRACTION, fixed_residual_rms_m

LIVE_PUBLISH_INTERVAL_S = 0.5  # train positions to the live state at most this often per train
CORRECTION_AGES_KEPT = 3600  # epochs of correction age kept: an hour at the network's 1 Hz
CORRECTION_AGE_P99_EPOCHS = 300  # the live correction age p99 is over the last five minutes at 1 Hz
LINE_POLYLINE_POINTS = 400  # the line's drawing on the console's map has at most about this many points
KMH_PER_M_S = 3.6


def make_live_state(world, records: dict, caster_snapshot, on_station_change):
    """The console's `LiveState` with the registry's stations (`persistence.StationRecord` by code; all down
    until their data arrives) and the line drawn, or None when the console is not installed.
    `caster_snapshot()` answers the console's caster page; `on_station_change(code, fields)` carries an
    operator's change back to the system."""
    try:
        from augnet.console.live import LiveState
    except ImportError:  # console not installed: the system runs without it
        return None
    live = LiveState()
    for rec in records.values():
        live.update_station(station_live(rec, world))
    if world.track is not None:
        live.set_line(line_drawing(world))
    live.caster_snapshot = caster_snapshot
    live.on_station_change = on_station_change
    return live


def station_live(record, world):
    """The console's live row of a registered station (`persistence.StationRecord`) the network just took in:
    down until its data arrives, placed along the line when there is one."""
    from augnet.console.live import StationLive
    from augnet.system.run_config import along_line_km

    llh = ecef_to_geodetic(np.asarray(record.xyz_m, float))
    return StationLive(id=record.code, station_id=record.rtcm_station_id, lat_deg=float(np.degrees(llh[0])),
                       lon_deg=float(np.degrees(llh[1])), h_m=float(llh[2]), along_km=along_line_km(world, record.xyz_m), up=False, enabled=record.enabled, last_data_age_s=None,
                       satellites=0)


def line_drawing(world) -> dict:
    """The line's id, length [km] and centre polyline (lat, lon [deg]) for the console's map."""
    poly = world.track.plane_to_geodetic(np.column_stack([world.track.centre_xy, world.track.rail_h]))
    step = max(1, len(poly) // LINE_POLYLINE_POINTS)
    return {"id": world.scenario.line.id, "length_km": world.track.length_m / 1000.0,
            "polyline": np.round(poly[::step, :2], 6).tolist()}


class LivePublisher:
    """Feeds the live state from the centre's epochs, the trains' solutions and the alarms raised, and keeps
    what the terminal view reads (the last epoch report, the correction ages)."""

    def __init__(self) -> None:
        self.live = None  # the console's `LiveState` once built (`make_live_state`); None: no console
        self.last_report = None  # the centre's last `EpochReport`
        self.correction_age_s: list[float] = []  # per network epoch: solved epoch's age when reported [s]
        self._last_train_publish: dict[str, float] = {}

    # --- the centre's epochs ------------------------------------------------------------------------------

    def record_epoch(self, r) -> None:
        """Keep the epoch report and its correction age (now minus the epoch's time)."""
        self.last_report = r
        self.correction_age_s.append(max(0.0, gtime.now_gpst() - r.t_gpst))
        del self.correction_age_s[:-CORRECTION_AGES_KEPT]

    def publish_network(self, r, centre, rbc) -> None:
        """The epoch's stations, baselines and network figures to the live state."""
        if self.live is None:
            return
        ne = r.network
        now = time.time()
        self._publish_stations(r, centre.excluded_stations)
        self.live.set_baselines(baseline_rows(ne))
        ages = (np.array(self.correction_age_s[-CORRECTION_AGE_P99_EPOCHS:]) if self.correction_age_s
                else np.array([np.nan]))
        self.live.set_network({
            "epoch_gpst": r.t_gpst, "epoch_utc": gtime.gpst_to_utc(r.t_gpst).isoformat(), "master": ne.master,
            "stations_present": len(ne.present), "stations": len(ne.stations), "satellites": int(len(ne.sats)),
            "excluded": sorted(ne.excluded), "sessions": r.sessions,
            "vrs_model": r.vrs_models, "misclosures": ne.misclosures,
            "correction_age_p99_s": float(np.nanpercentile(ages, 99)),
            "solve_ms_p99": centre.solve_ms_p99(), **centre.latency_ms_p99(),
            "rbc": rbc.snapshot() if rbc else None,
            "updated_unix": now,
        })

    def _publish_stations(self, r, excluded: set[str]) -> None:
        ne = r.network
        for code, st in list(self.live.stations.items()):
            up = code in ne.present
            self.live.update_station(dataclasses.replace(
                st, up=up, enabled=code not in excluded,
                last_data_age_s=round(max(0.0, gtime.now_gpst() - r.t_gpst), 3) if up else None,
                satellites=int(len(ne.sats)) if up else 0))

    # --- alarms and trains --------------------------------------------------------------------------------

    def publish_alarm(self, kind: str, subject: str, severity: str, cleared: bool = False) -> None:
        """An alarm raised or cleared in the store (any thread): the pages re-read the alarms."""
        if self.live is not None:
            self.live.publish({"type": "alarm", "action": "cleared" if cleared else "raised", "kind": kind,
                               "subject": subject, "severity": severity})

    def publish_train(self, train, out) -> None:
        """A train's solution (`UnitOutput`) to the live state, at most every `LIVE_PUBLISH_INTERVAL_S`."""
        if self.live is None:
            return
        now = time.time()
        if now - self._last_train_publish.get(train.id, 0.0) < LIVE_PUBLISH_INTERVAL_S:
            return
        self._last_train_publish[train.id] = now
        row = train_row(train, out, now)
        if row is not None:
            self.live.update_train(row)


def baseline_rows(ne) -> list:
    """The console's row (`BaselineLive`) per baseline of a `NetworkEpoch`: length, state, fixed fraction and
    the fixed residual RMS [cm]."""
    from augnet.console.live import BaselineLive

    rows = []
    pos = {n: ne.station_xyz_m[i] for i, n in enumerate(ne.stations)}
    for key, b in ne.baselines.items():
        a, c = key.split("-", 1)
        length = float(np.linalg.norm(pos[a] - pos[c])) / 1000.0 if a in pos and c in pos else math.nan
        if b is None:
            rows.append(BaselineLive(a, c, length, "none", 0.0, None))
            continue
        frac = float(b.fixed_fraction)
        state = "fixed" if frac >= FIXED_BASELINE_FRACTION else "float"
        rms = fixed_residual_rms_m(b)
        rows.append(BaselineLive(a, c, length, state, round(frac, 3), None if rms is None else round(rms * 100.0, 2)))
    return rows


def train_row(train, out, now_unix: float):
    """The console's row (`TrainLive`) for a train's solution: position, place on the track, fix state,
    correction age, protection levels and speed; None when the solution has no position."""
    from augnet.console.live import TrainLive

    sol, m = out.solution, out.match
    p = np.asarray(sol.position_m, float)
    if not np.all(np.isfinite(p)):
        return None
    llh = ecef_to_geodetic(p)
    hpl, vpl = train.protection_levels()
    v = np.asarray(sol.velocity_m_s, float)
    speed = float(np.linalg.norm(v) * KMH_PER_M_S) if np.all(np.isfinite(v)) else None
    on_track = m is not None and m.track
    return TrainLive(
        id=train.id, lat_deg=float(np.degrees(llh[0])), lon_deg=float(np.degrees(llh[1])), h_m=float(llh[2]),
        track_id=m.track if m is not None else None, along_km=(round(m.km, 4) if on_track else None),
        cross_track_m=(round(m.cross_m, 3) if on_track else None),
        fix_state=sol.status_name,
        correction_age_s=train.correction_age_s(), hpl_m=hpl, vpl_m=vpl, speed_kmh=speed, updated_unix=now_unix)
