"""Timer-based virtual balise passage, with linking supervision, as ETCS expects it from a balise reader.

Each fused along-track estimate (position, speed, their variances) predicts the moment the train's
reference point reaches the next balise group ahead; the caller's clock drives `tick(now)` (the onboard
unit is stepped, nothing here reads a wall clock) and the passage is emitted when the clock reaches the
predicted moment, not at the next epoch.  At that moment the estimate must be usable: not older than
`max_estimate_age_s` and its along-track protection level (K sigma at the passage, K from the integrity
allocation) within the capture limit; otherwise the group is not read.

Linking (ERA SUBSET-026 3.4.4 in spirit): a linked group is expected at the linked distance from the
previous group, within a window of +- (linking accuracy + the protection level).  A linked group not read
by the time the dead-reckoned position leaves its window is a miss; two consecutive linked misses raise a
service-brake request to the sink.  `position_report()` gives the position relative to the last relevant
(read) group with its confidence interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from augnet.onboard.integrity_allocation import ALONG_TRACK_ALERT_LIMIT_M, DEFAULT_ALLOCATION

# Oldest fused estimate [s] a passage may be predicted from: 2 s covers a missed 1 Hz epoch and nothing
# more (at 300 km/h the speed error of 0.5 km/h grows 0.3 m in that time; railway.md odometer figure).
MAX_ESTIMATE_AGE_S = 2.0
# Linking accuracy [m] of a group's location in the map (ETCS Q_LOCACC-like; our map is surveyed to cm,
# 1 m leaves room for a lever-arm error).
LINKING_ACCURACY_M = 1.0
# Consecutive linked misses that request the service brake (railway.md: two consecutive linked VBs missed).
LINKED_MISSES_FOR_SERVICE_BRAKE = 2


@dataclass(frozen=True)
class BaliseGroup:
    id: int | str  # the track map's id (str in TrackDatabase; the ATP's numeric NID_BG via AtpLinkSink)
    track: str
    along_m: float  # arc length of the group's reference point on its track [m]
    telegram: bytes = b""
    linked: bool = True


@dataclass(frozen=True)
class Passage:
    group: BaliseGroup
    time: float  # predicted passage moment (caller's clock) [s]
    emitted_at: float  # the tick that emitted it [s]
    direction: int
    speed_mps: float
    confidence_m: float  # along-track protection level at the passage [m]


@dataclass(frozen=True)
class Miss:
    group: BaliseGroup
    time: float
    reason: str


@dataclass(frozen=True)
class PositionReport:
    last_group: int | str | None
    distance_m: float  # signed distance travelled past the last read group, in its direction [m]
    confidence_m: float  # half-width of the confidence interval [m]


class TimerSink(Protocol):
    def passage(self, p: Passage) -> None: ...
    def missed(self, m: Miss) -> None: ...
    def service_brake(self, time: float, reason: str) -> None: ...


class ListTimerSink:
    def __init__(self) -> None:
        self.passages: list[Passage] = []
        self.misses: list[Miss] = []
        self.brakes: list[tuple[float, str]] = []

    def passage(self, p: Passage) -> None:
        self.passages.append(p)

    def missed(self, m: Miss) -> None:
        self.misses.append(m)

    def service_brake(self, time: float, reason: str) -> None:
        self.brakes.append((time, reason))


@dataclass
class _Estimate:
    time: float
    track: str
    along_m: float
    speed_mps: float
    along_var_m2: float
    speed_var: float


class TimedBaliseDetector:
    def __init__(self, groups: list[BaliseGroup], sink: TimerSink, *, k: float | None = None,
                 capture_limit_m: float = ALONG_TRACK_ALERT_LIMIT_M, max_estimate_age_s: float = MAX_ESTIMATE_AGE_S,
                 linking_accuracy_m: float = LINKING_ACCURACY_M):
        self.groups = sorted(groups, key=lambda g: (g.track, g.along_m))
        self.sink = sink
        self.k = DEFAULT_ALLOCATION.k_fault_free if k is None else k
        self.capture_limit_m = capture_limit_m
        self.max_estimate_age_s = max_estimate_age_s
        self.linking_accuracy_m = linking_accuracy_m
        self._est: _Estimate | None = None
        self._done: set[int] = set()  # groups read or missed on this run past them
        self._last_read: tuple[BaliseGroup, int] | None = None  # (group, direction)
        self._consecutive_misses = 0
        self.service_brake_requested = False
        self._last_tick = -math.inf

    @property
    def track(self) -> str | None:
        """The track of the latest estimate (odometry carries it on when the map match drops out)."""
        return self._est.track if self._est is not None else None

    # -- inputs ---------------------------------------------------------------------------------
    def update(self, time: float, track: str, along_m: float, speed_mps: float, along_var_m2: float,
               speed_var: float = 0.0) -> None:
        """A fused along-track estimate of the reference point at `time` (speed signed along the track)."""
        if self._est is not None and self._est.track != track:
            self._done.clear()
        self._est = _Estimate(time, track, along_m, speed_mps, along_var_m2, speed_var)

    def _predict(self, e: _Estimate, t: float) -> tuple[float, float]:
        dt = t - e.time
        return e.along_m + e.speed_mps * dt, math.sqrt(max(e.along_var_m2 + e.speed_var * dt * dt, 0.0))

    def _next_group(self, e: _Estimate) -> BaliseGroup | None:
        d = 1 if e.speed_mps >= 0 else -1
        best = None
        for g in self.groups:
            if g.track != e.track or g.id in self._done:
                continue
            # groups behind by more than the window are out of play (passed before we had a position)
            if (g.along_m - e.along_m) * d < -(self.linking_accuracy_m + self.capture_limit_m):
                continue
            if best is None or (g.along_m - e.along_m) * d < (best.along_m - e.along_m) * d:
                best = g
        return best

    # -- the timer ------------------------------------------------------------------------------
    def due_times(self) -> list[float]:
        """The moments the timer may act on the next group (predicted passage, end of its window, the
        estimate going stale), so an event-stepped caller can set its clock to them."""
        e = self._est
        if e is None or e.speed_mps == 0.0:
            return []
        g = self._next_group(e)
        if g is None:
            return []
        t_pass = e.time + (g.along_m - e.along_m) / e.speed_mps
        _, sigma = self._predict(e, max(t_pass, e.time))
        window = self.linking_accuracy_m + min(self.k * sigma, self.capture_limit_m)
        due = {t_pass, t_pass + window / abs(e.speed_mps), e.time + self.max_estimate_age_s + 1e-6}
        return sorted(d for d in due if d > self._last_tick)

    def tick(self, now: float) -> None:
        """Advance the caller's clock: emit every passage (or miss) whose moment has come."""
        self._last_tick = max(self._last_tick, now)
        e = self._est
        while e is not None and e.speed_mps != 0.0:
            g = self._next_group(e)
            if g is None:
                return
            d = 1 if e.speed_mps > 0 else -1
            t_pass = e.time + (g.along_m - e.along_m) / e.speed_mps
            _, sigma = self._predict(e, max(t_pass, e.time))
            pl = self.k * sigma
            usable = now - e.time <= self.max_estimate_age_s and pl <= self.capture_limit_m
            if usable and now >= t_pass:
                self._read(g, Passage(g, t_pass, now, d, abs(e.speed_mps), pl))
                continue
            # not readable: a miss once the dead-reckoned position leaves the expectation window
            window = self.linking_accuracy_m + min(pl, self.capture_limit_m)
            t_out = t_pass + window / abs(e.speed_mps)
            if not usable and now >= t_out:
                reason = "estimate too old" if now - e.time > self.max_estimate_age_s else (
                    f"protection level {pl:.2f} m over {self.capture_limit_m:.2f} m")
                self._miss(g, Miss(g, t_out, reason))
                continue
            return

    def _read(self, g: BaliseGroup, p: Passage) -> None:
        self._done.add(g.id)
        self._last_read = (g, p.direction)
        if g.linked:
            self._consecutive_misses = 0
        self.sink.passage(p)

    def _miss(self, g: BaliseGroup, m: Miss) -> None:
        self._done.add(g.id)
        self.sink.missed(m)
        if not g.linked:
            return
        self._consecutive_misses += 1
        if self._consecutive_misses >= LINKED_MISSES_FOR_SERVICE_BRAKE and not self.service_brake_requested:
            self.service_brake_requested = True
            self.sink.service_brake(m.time, f"{self._consecutive_misses} consecutive linked groups missed "
                                            f"(last {g.id}: {m.reason})")

    def position_report(self, now: float) -> PositionReport | None:
        """Position relative to the last read group, with the K-sigma confidence half-width."""
        e = self._est
        if e is None:
            return None
        along, sigma = self._predict(e, now)
        if self._last_read is None or self._last_read[0].track != e.track:
            return PositionReport(None, along, self.k * sigma)
        g, d = self._last_read
        return PositionReport(g.id, (along - g.along_m) * d, self.k * sigma)
