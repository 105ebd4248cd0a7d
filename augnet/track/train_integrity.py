"""Train integrity from two antennas: the along-track distance between the head and the tail antenna on the
track map must stay the antenna spacing (train data) within a bound from the two protection levels.

    mon = IntegrityMonitor(topology, spacing_m=209.0, direction="up")
    state = mon.update(t, head, tail)       # head / tail: AntennaFix (edge, km, along PL) or None
    state.status                            # "confirmed" | "lost" | "unknown" (INTEGRITY_STATES)

Requirement (railway.md, EU GSA 2019 table): train integrity, accuracy 1-10 m (2 sigma), SIL 4, time to
alarm 10-30 s. The monitor declares "lost" when |distance - spacing| exceeds the bound in `LOSS_EPOCHS`
consecutive epochs and latches it (a split train does not re-couple by itself: `reset()` is a driver's or
dispatcher's act after the train has been checked). "unknown": either antenna without a map-matched fix, the
bound above the alert limit, or the head not reachable from the tail along the topology within two spacings
plus the bound (a wrong-edge match): the integrity is then not *confirmed*, which is what the section register
needs (a train without confirmed integrity keeps the track behind it occupied).

Bound: PL_head + PL_tail + `COUPLER_PLAY_M`. Each along-track PL bounds its own antenna's error at the
allocated risk (decision 0250), so their sum bounds the error of the difference whatever the two errors'
correlation (the two receivers share the corrections: their errors are correlated, not independent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from augnet.track.topology import Step, Topology, TopologyError

INTEGRITY_STATES = ("confirmed", "lost", "unknown")  # as augnet.system.section_register.INTEGRITY_STATES
# Alert limit on the spacing error [m]: the upper end of the train-integrity accuracy (1-10 m, 2 sigma) in the
# GSA 2019 requirement table (railway.md); a bound above it cannot confirm the integrity.
INTEGRITY_ALERT_LIMIT_M = 10.0
# Slack and draw-gear play of the train's couplings [m]: ~60 mm per coupling (buffer/draw-gear stroke, an
# assumption of the order of EN 15551's buffer strokes) over the 7 couplings of an 8-car set, rounded up.
COUPLER_PLAY_M = 0.5
# Consecutive epochs over the bound before "lost" [epochs]: 3 s at 1 Hz, inside the 10 s lower end of the
# time to alarm (railway.md), and a single outlying fix (continuity) does not raise the alarm.
LOSS_EPOCHS = 3
# The head is looked for up to this many spacings ahead of the tail along the map (a split's gap is measured,
# not taken for a wrong-edge match, until the parts are a train length apart).
SEARCH_SPACINGS = 2.0


@dataclass(frozen=True)
class AntennaFix:
    """One antenna's map-matched position: the edge (the onboard map's track), chainage, along-track PL."""

    edge: str
    km: float
    along_pl_m: float


@dataclass(frozen=True)
class IntegrityState:
    time_s: float
    status: str  # INTEGRITY_STATES
    distance_m: float  # head minus tail along the track, in the direction of travel (NaN: not measured)
    error_m: float  # distance minus the spacing (NaN: not measured)
    bound_m: float  # PL_head + PL_tail + coupler play (inf: not measured)
    reason: str = ""


class IntegrityMonitor:
    def __init__(self, topology: Topology, spacing_m: float, direction: str, *,
                 alert_limit_m: float = INTEGRITY_ALERT_LIMIT_M, loss_epochs: int = LOSS_EPOCHS,
                 coupler_play_m: float = COUPLER_PLAY_M):
        if not spacing_m > 0 or direction not in ("up", "down"):
            raise ValueError(f"spacing {spacing_m} m, direction {direction!r}")
        self.topology = topology
        self.spacing_m = float(spacing_m)
        self.direction = direction
        self.alert_limit_m = alert_limit_m
        self.loss_epochs = int(loss_epochs)
        self.coupler_play_m = coupler_play_m
        self.over = 0  # consecutive epochs over the bound
        self.lost_at_s: float | None = None
        self.last_confirmed: tuple[float, AntennaFix] | None = None  # (time, tail) of the last confirmation

    def reset(self) -> None:
        """Integrity re-established from outside (the train checked and its data entered again)."""
        self.over = 0
        self.lost_at_s = None

    def update(self, t: float, head: AntennaFix | None, tail: AntennaFix | None) -> IntegrityState:
        if head is None or tail is None or not (math.isfinite(head.along_pl_m) and math.isfinite(tail.along_pl_m)):
            return self._state(t, "unknown", math.nan, math.inf, "an antenna without a map-matched fix")
        bound = head.along_pl_m + tail.along_pl_m + self.coupler_play_m
        try:
            d = self.distance_m(tail, head, SEARCH_SPACINGS * self.spacing_m + bound)
        except TopologyError:  # a match not on its edge's chainage span: not measured
            d = None
        if d is None:
            return self._state(t, "unknown", math.nan, bound, "head not reachable from the tail on the map")
        err = d - self.spacing_m
        if abs(err) > bound:
            self.over += 1
            if self.over >= self.loss_epochs and self.lost_at_s is None:
                self.lost_at_s = t
            return self._state(t, "unknown", d, bound, f"spacing off by {err:+.2f} m > {bound:.2f} m "
                                                        f"({self.over} epoch(s))")
        self.over = 0
        if bound > self.alert_limit_m:
            return self._state(t, "unknown", d, bound, f"bound {bound:.1f} m over the alert limit")
        if self.lost_at_s is None:
            self.last_confirmed = (t, tail)
        return self._state(t, "confirmed", d, bound)

    def _state(self, t: float, status: str, d: float, bound: float, reason: str = "") -> IntegrityState:
        if self.lost_at_s is not None:  # latched
            status = "lost"
            reason = reason or f"lost at t = {self.lost_at_s:.1f} s (latched)"
        return IntegrityState(t, status, d, d - self.spacing_m if math.isfinite(d) else math.nan, bound, reason)

    def distance_m(self, tail: AntennaFix, head: AntennaFix, limit_m: float) -> float | None:
        """Along-track distance [m] from the tail forward (direction of travel) to the head over the topology
        (shortest path within `limit_m`); negative when the head is behind the tail on the same edge; None when
        the head's edge is not reachable."""
        topo = self.topology
        up = self.direction == "up"
        s_tail = topo.along_m(tail.edge, tail.km)
        if head.edge == tail.edge:
            s_head = topo.along_m(head.edge, head.km)
            return (s_head - s_tail) if up else (s_tail - s_head)
        length = topo.length_m(tail.edge)
        start = Step(tail.edge, self.direction)
        best: dict[Step, float] = {start: (length - s_tail) if up else s_tail}  # distance at the far end
        frontier = [start]
        found = math.inf
        while frontier:
            cur = frontier.pop()
            for nxt in topo.next_steps(cur):
                at_entry = best[cur]
                if at_entry > limit_m:
                    continue
                if nxt.edge == head.edge:
                    s = topo.along_m(head.edge, head.km)
                    found = min(found, at_entry + (s if nxt.direction == "up" else topo.length_m(nxt.edge) - s))
                    continue
                far = at_entry + topo.length_m(nxt.edge)
                if nxt not in best or far < best[nxt]:
                    best[nxt] = far
                    frontier.append(nxt)
        return found if math.isfinite(found) else None
