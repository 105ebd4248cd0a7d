"""The section register through a simulated run: each train's map-matched positions (the estimate) as
position reports, encoded and decoded as on the radio link, into the centre's `SectionService`; the
register's order judged against the truth chainage at every epoch.

    log = runner.simulate(sc)           # the whole chain, faster than real time
    rep = replay(log)                   # rep.order_mismatches == [] is "order preserved"

The truth (`TrainLog.truth_km`) is read only to judge: the service sees the reports alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from augnet.onboard.position_report import DEFAULT_TRAIN_LENGTH_M, ReportBuilder, encode
from augnet.system.section_service import SectionEvent, SectionService, StationArea, stations_of


@dataclass
class SectionReplay:
    service: SectionService
    epochs: int = 0
    queues_checked: int = 0  # (epoch, section, direction) with two or more trains compared with the truth
    order_mismatches: list[tuple[float, int, str, tuple[str, ...], tuple[str, ...]]] = field(default_factory=list)
    # each transition with how far past its boundary (truth chainage) the train was when it happened [m]
    transitions: list[tuple[SectionEvent, float]] = field(default_factory=list)


def layout_stations(topology) -> tuple[list[StationArea], float]:
    """The station areas of a track topology and the line's length [km]: a station's area is the stretch between
    the section boundaries (or the line's ends) that holds its tracks (its edges' `station`)."""
    lo = min(e.km_begin for e in topology.edges.values())
    hi = max(e.km_end for e in topology.edges.values())
    cuts = sorted({lo, hi, *(b.km for b in topology.sections.values())})
    areas: dict[str, list[float]] = {}
    for e in topology.edges.values():
        if not e.station:
            continue
        mid = 0.5 * (e.km_begin + e.km_end)
        k = max(i for i, c in enumerate(cuts[:-1]) if c <= mid)
        a = areas.setdefault(e.station, [cuts[k], cuts[k + 1]])
        a[0], a[1] = min(a[0], cuts[k]), max(a[1], cuts[k + 1])
    return [StationArea(n, a, b) for n, (a, b) in sorted(areas.items(), key=lambda x: x[1][0])], hi


def replay(log, length_m: float | None = None, stations: list[StationArea] | None = None,
           line_length_km: float | None = None) -> SectionReplay:
    """`stations` / `line_length_km`: the station areas and the line's length (default: the scenario line's).
    A train's length and, with a rear antenna, its integrity state per epoch come from its log."""
    sc = log.scenario
    service = SectionService(stations_of(sc) if stations is None else stations,
                             log.line_length_m / 1000.0 if line_length_km is None else line_length_km)
    rep = SectionReplay(service)
    builders = {tid: ReportBuilder(tid, length_m or (tl.length_m if math.isfinite(tl.length_m)
                                                       else DEFAULT_TRAIN_LENGTH_M))
                for tid, tl in log.trains.items()}
    index = {tid: {round(t, 3): i for i, t in enumerate(tl.t_s)} for tid, tl in log.trains.items()}
    times = sorted({round(t, 3) for tl in log.trains.values() for t in tl.t_s})
    for t in times:
        truth_now: dict[str, float] = {}
        for tid, tl in log.trains.items():
            i = index[tid].get(t)
            if i is None:
                continue
            truth_now[tid] = tl.truth_km[i]
            if not tl.track[i] or not math.isfinite(tl.km[i]):
                continue
            age = tl.age_s[i]
            if tl.integrity:
                builders[tid].integrity = tl.integrity[i].status
            r = builders[tid].build(sc_time(log, t), tl.track[i], tl.km[i],
                                    correction_age_s=age if math.isfinite(age) else None,
                                    along_pl_m=_finite(tl.along_pl_m[i]), cross_pl_m=_finite(tl.cross_pl_m[i]),
                                    hpl_m=None, vpl_m=None, track_confirmed=tl.confirmed[i])
            seen = len(service.events)
            service.on_datagram(encode(r))
            for ev in list(service.events)[seen:]:
                rep.transitions.append((ev, _past_boundary_m(service, ev, tl.truth_km[i])))
        rep.epochs += 1
        for (sid, d), q in service.register.queues.items():
            ids = q.ids()
            if len(ids) < 2 or not all(x in truth_now for x in ids):
                continue
            rep.queues_checked += 1
            truth_order = tuple(sorted(ids, key=lambda x: -truth_now[x] if d == "up" else truth_now[x]))
            if truth_order != ids:
                rep.order_mismatches.append((t, sid, d, ids, truth_order))
    return rep


def sc_time(log, t_rel: float) -> float:
    """GPS time of an epoch `t_rel` seconds after the scenario's start."""
    return float(log.t0) + t_rel


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _past_boundary_m(service: SectionService, ev: SectionEvent, truth_km: float) -> float:
    """How far past the boundary the event stands for the train truly was (negative: before it) [m]."""
    s = service.sections[ev.section_id]
    up = ev.direction == "up"
    if ev.action == "remove":
        boundary = s.exit_km(ev.direction)
    elif ev.action == "insert":
        boundary = s.entry_km(ev.direction)
    else:
        return math.nan  # an admission has no boundary
    return (truth_km - boundary) * 1e3 * (1 if up else -1)


__all__ = ["SectionReplay", "layout_stations", "replay"]
