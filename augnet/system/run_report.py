"""The run report of `augnet up`: what `--duration` writes to `augnet-run-report.json` and what the
command prints at the end, computed from the counters the parts kept while the system ran.

Every function here reads counters and returns plain values; none touches a socket, the store or the clock.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import dataclass, field

import numpy as np

from augnet.onboard.rtk import Status

CASTER_MOUNT_COUNTERS = ("bytes_in", "bytes_out", "clients_total")  # per mountpoint, from the caster snapshot


@dataclass
class RunReport:
    """The report's fields, in the order the JSON file lists them."""

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
    sections: dict = field(default_factory=dict)  # the section register (SectionService.report)

    def to_json(self) -> str:
        return json.dumps(self.__dict__, indent=2, default=str)


def run_report(scenario: str, started_unix: float, now_unix: float, *, centre=None, trains=None,
               alarms: list[dict] = (), rbc_snapshot: dict | None = None, caster_snapshot: dict | None = None,
               store_counts: dict | None = None, atp: dict | None = None, truth_chainage_m=None) -> RunReport:
    """The report of a run that began at `started_unix` and ends at `now_unix` [s since 1970].

    `centre` is the `CentreService` (or None when it never started), `trains` maps a train id to its
    `OnboardTrain`, `alarms` is the log of raised alarms, the snapshots are the RBC link's and the caster's,
    `store_counts` the store writer's {"writes", "failures"}, `atp` each train's ATP link snapshot
    (`AtpConnection.snapshot`), `truth_chainage_m(train, t_gpst)` the simulator's true chainage [m] (the
    timer's passage errors: estimate minus truth, computed here, never onboard)."""
    out = RunReport(scenario=scenario,
                    started_utc=dt.datetime.fromtimestamp(started_unix, dt.timezone.utc).isoformat(),
                    duration_s=round(now_unix - started_unix, 1),
                    stations=sorted(centre.stations) if centre else [])
    if centre is not None:
        out.network_epochs = centre.timings.epochs
        out.centre_solve_ms_p99 = centre.solve_ms_p99()
        out.centre_latency = centre.latency_ms_p99()
        out.centre_stages_ms = centre.stages_ms()
        out.centre_errors = centre.errors
        out.centre_restarts = centre.restarts
    for tid, tr in (trains or {}).items():
        out.trains[tid] = train_entry(tr.stats, holds_fix(tr))
        if getattr(tr, "timer", None) is not None:
            out.trains[tid]["timed_balises"] = timed_balise_entry(tr.timer.sink, tid, truth_chainage_m)
        if atp and tid in atp:
            out.trains[tid]["atp"] = atp[tid]
    out.alarms = list(alarms)
    out.rbc = rbc_snapshot or {}
    if caster_snapshot is not None:
        out.caster = caster_entry(caster_snapshot)
    if store_counts is not None:
        out.store = dict(store_counts)
    return out


def train_entry(stats, holds_fix: bool) -> dict:
    """One train's line of the report from its `TrainStats`."""
    lat = np.array(stats.correction_latency_s) if stats.correction_latency_s else np.array([np.nan])
    n = max(1, stats.epochs)
    return {
        "epochs": stats.epochs, "status_counts": dict(stats.by_status),
        "fix_rate": round(stats.by_status.get("fix", 0) / n, 4),
        "time_to_first_fix_s": stats.first_fix_s, "vrs_epochs": stats.vrs_epochs,
        "correction_latency_p50_s": percentile(lat, 50), "correction_latency_p99_s": percentile(lat, 99),
        "base_moves": stats.base_moves, "base_resets": stats.base_resets,
        "balises": [b.balise_id for b in stats.balises], "errors": stats.errors,
        "holds_fix": holds_fix,
        # on the track: the map match's PLs and the 4001 bound on the along axis in them (p50 of the finite
        # ones), and the epochs whose corrections were unbounded (bounds came, this epoch's did not)
        "along_pl_p50_m": percentile(np.array(stats.along_pl_m, float), 50),
        "cross_pl_p50_m": percentile(np.array(stats.cross_pl_m, float), 50),
        "correction_along_p50_m": percentile(np.array(stats.correction_along_m, float), 50),
        "unbounded_epochs": int(np.isinf(np.array(stats.correction_along_m, float)).sum()),
    }


def timed_balise_entry(sink, train_id: str, truth_chainage_m=None) -> dict:
    """The timer's passages (predicted moment, when emitted, PL, speed and, given the truth, the passage
    error: true chainage at the predicted moment minus the group's, in the direction of travel), its misses
    and service-brake requests."""
    passages = []
    for p in getattr(sink, "passages", []):
        truth = truth_chainage_m(train_id, p.time) if truth_chainage_m is not None else None
        passages.append({"group": p.group.id, "time_gpst": round(p.time, 3), "emitted_at_gpst": round(p.emitted_at, 3),
                         "confidence_m": round(p.confidence_m, 3), "speed_mps": round(p.speed_mps, 3),
                         "error_m": None if truth is None else round((truth - p.group.along_m) * p.direction, 3)})
    errors = np.array([abs(p["error_m"]) for p in passages if p["error_m"] is not None], float)
    return {"passages": passages, "misses": [{"group": m.group.id, "time_gpst": round(m.time, 3), "reason": m.reason}
                                             for m in getattr(sink, "misses", [])],
            "service_brake_requests": [{"time_gpst": round(t, 3), "reason": r} for t, r in getattr(sink, "brakes", [])],
            "max_abs_error_m": round(float(errors.max()), 3) if errors.size else None}


def holds_fix(train) -> bool:
    """The train's last solution is an RTK fix."""
    return bool(train.last is not None and int(train.last.solution.status) == Status.FIX)


def caster_entry(snapshot: dict) -> dict:
    """The caster's port, its counters and each mountpoint's byte and client totals."""
    return {"port": snapshot["port"], "counters": snapshot["counters"],
            "mounts": {k: {kk: v.get(kk) for kk in CASTER_MOUNT_COUNTERS} for k, v in snapshot["mounts"].items()}}


def percentile(a: np.ndarray, q: float) -> float | None:
    """The q-th percentile of the finite values, to the millisecond when `a` is in seconds (None: none)."""
    a = a[np.isfinite(a)]
    return round(float(np.percentile(a, q)), 3) if a.size else None


__all__ = ["RunReport", "run_report", "train_entry", "caster_entry", "holds_fix", "timed_balise_entry"]
