"""Virtual balise capture: when the train's reference point passes a virtual balise on the matched
track, emit the balise's telegram as a capture event to a sink (the ATP interface; the RSSP-I link
that carries it to the train-control side is another package's and plugs in as a sink).

Passage is decided between two consecutive confirmed map matches on the same track: the balise's
chainage lies between the previous and the current along-track position of the reference point
(antenna along-track position plus the lever arm in the direction of travel).  The capture time is
interpolated linearly between the two epochs.  Matches that are not confirmed are not used: the
passage is then decided at the next confirmed epoch (late, never on the wrong track); each event
carries the along-track protection level at capture so the ATP can judge it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from augnet.onboard.trackmap import MapMatch, TrackDatabase

# Longest gap [s] between two confirmed matches across which a passage is still interpolated; a
# longer outage (tunnel) hands over to odometry and balises passed meanwhile are reported missed.
MAX_INTERPOLATION_GAP_S = 30.0


@dataclass(frozen=True)
class BaliseEvent:
    time: float  # GPST seconds of passage (interpolated)
    balise_id: str
    track: str
    km: float  # the balise's chainage
    telegram: bytes
    direction: int  # +1 passing in increasing km, -1 decreasing
    along_pl_m: float  # along-track protection level at capture
    linked: bool
    late: bool = False  # decided across epochs whose match was not confirmed (or no position)


class BaliseSink(Protocol):
    def balise_captured(self, event: BaliseEvent) -> None: ...


class ListSink:
    """Collects events in a list (tests, logging, the console's feed)."""

    def __init__(self) -> None:
        self.events: list[BaliseEvent] = []

    def balise_captured(self, event: BaliseEvent) -> None:
        self.events.append(event)


class BaliseDetector:
    def __init__(self, db: TrackDatabase, sink: BaliseSink, lever_arm_m: float = 0.0):
        """`lever_arm_m`: distance from the GNSS antenna to the train's reference point, positive
        when the reference point is ahead of the antenna in the direction of travel."""
        self.db = db
        self.sink = sink
        self.lever_arm_m = lever_arm_m
        self._prev: tuple[float, str, float, float] | None = None  # (time, track, antenna along, reference along)
        self._direction = 1
        self._skipped = False
        self._by_track: dict[str, list] = {}
        self._balise_along: dict[str, float] = {}
        for b in db.balises:
            self._by_track.setdefault(b.track, []).append(b)
            self._balise_along[b.id] = db.along_m(b.track, b.km)

    def update(self, time: float, match: MapMatch) -> list[BaliseEvent]:
        """Feed one epoch's map match; returns (and sinks) the captures decided at this epoch."""
        events: list[BaliseEvent] = []
        if not match.confirmed or match.track is None or not math.isfinite(time):
            self._skipped = True
            return events
        prev = self._prev
        same = prev is not None and prev[1] == match.track and time - prev[0] <= MAX_INTERPOLATION_GAP_S
        if same and match.along_m != prev[2]:
            self._direction = 1 if match.along_m > prev[2] else -1  # standing still keeps the last direction
        ref_along = match.along_m + self.lever_arm_m * self._direction
        if same:
            a0, a1, t0 = prev[3], ref_along, prev[0]
            for b in self._by_track.get(match.track, []):
                s = self._balise_along[b.id]
                # half-open interval so a balise exactly on an epoch is captured once
                if (a1 > a0 and a0 < s <= a1) or (a1 < a0 and a1 <= s < a0):
                    frac = (s - a0) / (a1 - a0)
                    events.append(BaliseEvent(t0 + frac * (time - t0), b.id, b.track, b.km, b.telegram,
                                              1 if a1 > a0 else -1, match.along_pl_m, b.linked, late=self._skipped))
        self._prev = (time, match.track, match.along_m, ref_along)
        self._skipped = False
        events.sort(key=lambda e: e.time)
        for ev in events:
            self.sink.balise_captured(ev)
        return events
