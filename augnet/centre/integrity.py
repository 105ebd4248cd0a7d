"""Integrity monitoring of the reference network: satellite faults, station faults, alarms.

Satellite clock and orbit faults cancel in the between-station differences the network works with, so they
are watched on each station's own data, where the broadcast model must explain the observations:

- per station and epoch, the time-differenced carrier phase on f1 minus the time-differenced geometric
  term (range minus broadcast satellite clock) leaves the receiver clock change (common to all satellites,
  removed by a median) plus atmosphere and orbit-error changes of a few millimetres per second;
- a satellite whose residual jumps by more than `SAT_STEP_THRESHOLD_M` at two or more stations in the same
  epoch, without a loss-of-lock flag, has a fault in space (a clock step, an orbit manoeuvre): it is
  excluded at once, and an alarm is raised. A jump at a single station is that station's cycle slip,
  which the ambiguity engine handles.
- the code is checked the same way against a looser bound, so a fault larger than the phase can follow
  (a jump that is also a slip) is still caught.

An excluded satellite stays out for `EXCLUSION_HOLD_S` and until its broadcast ephemeris changes (a new
issue of data is the system's own correction of the fault); the operator can clear it earlier.

Stations: a station silent for `STATION_TIMEOUT_S` is reported down (its alarm clears when data returns).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from augnet.centre.observations import StationEpoch
from augnet.centre.satellite_geometry import SatelliteGeometry

C = 299_792_458.0
# A 1 m jump in the time-differenced phase residual is far beyond the atmosphere's second-to-second change
# (mm) and beyond any multipath change (cm); it is 3.3 ns of satellite clock.
SAT_STEP_THRESHOLD_M = 1.0
# Code: its noise is decimetres; 30 m (100 ns) catches gross faults the phase test could miss.
SAT_CODE_STEP_THRESHOLD_M = 30.0
MIN_STATIONS_FOR_SAT_FAULT = 2
EXCLUSION_HOLD_S = 300.0
STATION_TIMEOUT_S = 5.0
MAX_DIFFERENCING_GAP_S = 5.0


@dataclass
class Alarm:
    kind: str  # satellite-fault, station-down, ...
    subject: str  # "G05", "NORTH"
    severity: str  # info / warning / critical
    message: str
    t_gpst: float
    cleared: bool = False


@dataclass
class _StationMemory:
    t: float = -np.inf
    phase_res: dict = field(default_factory=dict)  # sat -> residual [m]
    code_res: dict = field(default_factory=dict)


class IntegrityMonitor:
    def __init__(self, stations: list[str]):
        self.stations = list(stations)
        self.memory = {s: _StationMemory() for s in stations}
        self.excluded: dict[str, tuple[float, int]] = {}  # sat -> (excluded at, ephemeris row then)
        self.last_seen = {s: -np.inf for s in stations}
        self.down: set[str] = set()
        self.alarms: list[Alarm] = []  # every alarm raised, in order (the sink drains `new_alarms`)
        self.new_alarms: list[Alarm] = []

    def _raise(self, alarm: Alarm) -> None:
        self.alarms.append(alarm)
        self.new_alarms.append(alarm)

    def observe(self, t: float, epochs: dict[str, StationEpoch | None],
                geometry: dict[str, SatelliteGeometry], eph_rows: dict[str, int] | None = None) -> set[str]:
        """Check one epoch; returns the satellites excluded now (new and held)."""
        jumps_phase: dict[str, int] = {}
        jumps_code: dict[str, int] = {}
        for name, ep in epochs.items():
            if ep is None or name not in geometry:
                continue
            self.last_seen[name] = t
            g = geometry[name]
            mem = self.memory[name]
            lam1 = C / ep.freq_hz[:, 0]
            res_p = ep.phase_cyc[:, 0] * lam1 - g.g_m
            res_c = ep.code_m[:, 0] - g.g_m
            ok = np.isfinite(res_p) & np.isfinite(res_c) & g.valid
            cur_p = {str(s): float(r) for s, r, o in zip(ep.sats, res_p, ok) if o}
            cur_c = {str(s): float(r) for s, r, o in zip(ep.sats, res_c, ok) if o}
            lli = {str(s): bool(v) for s, v in zip(ep.sats, (ep.lli[:, 0] & 1) != 0)}
            if t - mem.t <= MAX_DIFFERENCING_GAP_S:
                common = [s for s in cur_p if s in mem.phase_res and not lli.get(s, False)]
                if len(common) >= 4:
                    dp = np.array([cur_p[s] - mem.phase_res[s] for s in common])
                    dc = np.array([cur_c[s] - mem.code_res[s] for s in common])
                    dp -= np.median(dp)  # receiver clock change, common to all satellites
                    dc -= np.median(dc)
                    for s, a, b in zip(common, dp, dc):
                        if abs(a) > SAT_STEP_THRESHOLD_M:
                            jumps_phase[s] = jumps_phase.get(s, 0) + 1
                        if abs(b) > SAT_CODE_STEP_THRESHOLD_M:
                            jumps_code[s] = jumps_code.get(s, 0) + 1
            mem.t = t
            mem.phase_res = cur_p
            mem.code_res = cur_c
        for sat in sorted(set(jumps_phase) | set(jumps_code)):
            n = max(jumps_phase.get(sat, 0), jumps_code.get(sat, 0))
            if n >= MIN_STATIONS_FOR_SAT_FAULT and sat not in self.excluded:
                row = (eph_rows or {}).get(sat, -1)
                self.excluded[sat] = (t, row)
                self._raise(Alarm("satellite-fault", sat, "critical",
                                  f"{sat}: its range jumped at {n} stations at once (satellite clock or orbit "
                                  f"fault); excluded from the corrections", t))
        # release exclusions after the hold time once a new ephemeris is in use
        for sat, (t_ex, row) in list(self.excluded.items()):
            new_row = (eph_rows or {}).get(sat, row)
            if t - t_ex >= EXCLUSION_HOLD_S and new_row != row:
                del self.excluded[sat]
                self._raise(Alarm("satellite-fault", sat, "info", f"{sat}: new ephemeris, back in use", t,
                                  cleared=True))
        # stations
        for name in self.stations:
            silent = t - self.last_seen[name] > STATION_TIMEOUT_S
            if silent and name not in self.down:
                self.down.add(name)
                self._raise(Alarm("station-down", name, "warning",
                                  f"station {name}: no data for {STATION_TIMEOUT_S:.0f} s; network re-solved without it", t))
            elif not silent and name in self.down:
                self.down.discard(name)
                self._raise(Alarm("station-down", name, "info", f"station {name}: data again", t, cleared=True))
        return set(self.excluded)

    def clear_exclusion(self, sat: str, t: float, by: str) -> bool:
        if sat in self.excluded:
            del self.excluded[sat]
            self._raise(Alarm("satellite-fault", sat, "info", f"{sat}: cleared by {by}", t, cleared=True))
            return True
        return False

    def add_station(self, name: str) -> None:
        """A station joins: judged silent only `STATION_TIMEOUT_S` after the latest epoch seen (it has not
        had a chance to deliver yet)."""
        if name not in self.memory:
            self.stations.append(name)
            self.memory[name] = _StationMemory()
        seen = [t for t in self.last_seen.values() if np.isfinite(t)]
        self.last_seen[name] = max(seen) if seen else -np.inf

    def remove_station(self, name: str) -> None:
        """A station leaves: forgotten; a station-down alarm of it is cleared (it is not down: it is gone)."""
        if name in self.memory:
            self.stations.remove(name)
            del self.memory[name]
        t = self.last_seen.pop(name, -np.inf)
        if name in self.down:
            self.down.discard(name)
            self._raise(Alarm("station-down", name, "info", f"station {name}: left the network",
                              t if np.isfinite(t) else float("nan"), cleared=True))

    def note(self, alarm: Alarm) -> None:
        """An alarm of the caller's (a membership change), delivered with this monitor's next epoch."""
        self._raise(alarm)

    def drain(self) -> list[Alarm]:
        out, self.new_alarms = self.new_alarms, []
        return out
