"""When a client's GGA should move its VRS point, and which base a nearest-station client gets.

Policy from ntrip.md (one open caster's): re-evaluate at most every 10 s, always after 120 s, and
otherwise only after 10 m of movement; switch to another base only when it is 500 m nearer than the
current one. Pure functions and a tiny state object with an explicit clock: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

from .gga import GgaFix, great_circle_m
from .limits import (BASE_SWITCH_HYSTERESIS_M, REPOSITION_MAX_INTERVAL_S, REPOSITION_MIN_INTERVAL_S,
                     REPOSITION_MIN_MOVE_M)


@dataclass(slots=True)
class RepositionPolicy:
    min_interval_s: float = REPOSITION_MIN_INTERVAL_S
    max_interval_s: float = REPOSITION_MAX_INTERVAL_S
    min_move_m: float = REPOSITION_MIN_MOVE_M
    applied_at: float | None = None
    applied_fix: GgaFix | None = None

    def due(self, now: float, fix: GgaFix) -> bool:
        """True when `fix` (received at `now`) should be applied; the caller then calls `applied`."""
        if self.applied_at is None or self.applied_fix is None:
            return True
        elapsed = now - self.applied_at
        if elapsed < self.min_interval_s:
            return False
        if elapsed >= self.max_interval_s:
            return True
        return fix.distance_m(self.applied_fix) >= self.min_move_m

    def applied(self, now: float, fix: GgaFix) -> None:
        self.applied_at = now
        self.applied_fix = fix


def choose_base(fix: GgaFix, bases: dict[str, tuple[float, float]], current: str | None,
                hysteresis_m: float = BASE_SWITCH_HYSTERESIS_M) -> str | None:
    """Nearest base to `fix` among `bases` (name -> (lat, lon)), keeping `current` unless another
    base is more than `hysteresis_m` nearer. None when there is no base."""
    if not bases:
        return None
    dist = {name: great_circle_m(fix.lat_deg, fix.lon_deg, lat, lon) for name, (lat, lon) in bases.items()}
    best = min(dist, key=lambda n: (dist[n], n))
    if current in dist and dist[best] + hysteresis_m >= dist[current]:
        return current
    return best
