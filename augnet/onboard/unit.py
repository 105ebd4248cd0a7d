"""The onboard positioning unit: one epoch in, everything the train and the console need out.

    rover epoch + latest base epoch -> RTK solution -> map match (track, km, protection levels)
    -> virtual balise captures (to the sink) -> NMEA GGA/RMC -> the console's solution record

Corrections may come from a file (post-processing) or from `CorrectionDecoder` fed by the NTRIP
client; the unit only needs the latest base epoch and its coordinates.  Nothing here raises on data.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from augnet.gnss.ephemeris import NavigationData
from augnet.onboard.balise import BaliseDetector, BaliseEvent, BaliseSink, ListSink
from augnet.onboard.nmea import gga, rmc
from augnet.onboard.observations import EpochObs
from augnet.onboard.correction_bound import CorrectionBounds, dd_position_gain
from augnet.onboard.rtk import RtkFilter, RtkOptions, RtkSolution, Status
from augnet.onboard.solution import SolutionRecord
from augnet.onboard.trackmap import DEFAULT_INTEGRITY_RISK, MapMatch, TrackDatabase


@dataclass
class UnitOutput:
    solution: RtkSolution
    match: MapMatch | None
    balises: list[BaliseEvent] = field(default_factory=list)
    gga: str = ""
    rmc: str = ""

    def record(self) -> dict:
        """A flat JSON-friendly dict for the console (solution record plus track position)."""
        d = asdict(SolutionRecord.from_solution(self.solution))
        m = self.match
        d.update({
            "track": m.track if m else None, "km": m.km if m else None,
            "cross_track_m": m.cross_m if m else None, "along_pl_m": m.along_pl_m if m else None,
            "cross_pl_m": m.cross_pl_m if m else None, "track_confirmed": bool(m and m.confirmed),
            "correction_along_m": m.correction_along_m if m else None,
            "correction_cross_m": m.correction_cross_m if m else None,
            "balises": [b.balise_id for b in self.balises],
        })
        return d


class OnboardUnit:
    def __init__(self, nav: NavigationData, base_position_m, track_db: TrackDatabase | None = None,
                 sink: BaliseSink | None = None, options: RtkOptions | None = None,
                 integrity_risk: float = DEFAULT_INTEGRITY_RISK, lever_arm_m: float = 0.0,
                 base_is_vrs: bool = False):
        self.rtk = RtkFilter(nav, base_position_m, options, base_is_vrs=base_is_vrs)
        self.track_db = track_db
        self.integrity_risk = integrity_risk
        self.sink = sink or ListSink()
        self.balises = BaliseDetector(track_db, self.sink, lever_arm_m) if track_db is not None else None

    def correction_terms(self, sol: RtkSolution, base: EpochObs | None, bounds: CorrectionBounds | None):
        """(gain (3, S), sigma (S,)) of the corrections this solution used, or (None, None) when it used none
        or no 4001 came on their stream. A float or fixed solution on a base epoch without a 4001 (while they
        come) gets NaN sigmas: unbounded, so infinite PLs."""
        if bounds is None or not bounds.receiving or base is None or sol.status not in (Status.FIX, Status.FLOAT):
            return None, None
        geo = self.rtk.geometry
        if geo is None:
            return None, np.full(1, np.nan)  # corrections used, rows unknown: no gain to bound them by
        return dd_position_gain(geo), bounds.sigmas(base.time, geo.sats)

    def set_base_position(self, base_position_m, non_physical: bool | None = None) -> None:
        """A new reference station (or a repositioned VRS): the filter restarts its ambiguities.

        `non_physical`: the base is a computed station, a network VRS (RTCM 1005/1006 DF141, which
        `CorrectionDecoder.base_non_physical` reports); None leaves the filter's belief as it is."""
        p = np.asarray(base_position_m, dtype=float)
        vrs = self.rtk.base_is_vrs if non_physical is None else bool(non_physical)
        if not np.allclose(p, self.rtk.base_position_m, atol=1e-3) or vrs != self.rtk.base_is_vrs:
            self.rtk.base_position_m = p
            self.rtk.base_is_vrs = vrs
            self.rtk.reset()

    def step(self, rover: EpochObs, base: EpochObs | None, bounds: CorrectionBounds | None = None) -> UnitOutput:
        """`bounds`: the centre's 4001 bounds received with the corrections (`CorrectionDecoder.bounds`);
        while they come, the PLs carry the bound of the base epoch used (decision 0281)."""
        sol = self.rtk.step(rover, base)
        match = None
        events: list[BaliseEvent] = []
        if self.track_db is not None:
            gain, sigma = self.correction_terms(sol, base, bounds)
            match = self.track_db.match(sol.position_m, sol.covariance_m2, self.integrity_risk,
                                        correction_gain=gain, correction_sigma_m=sigma)
            if self.balises is not None:
                events = self.balises.update(sol.time, match)
        return UnitOutput(sol, match, events, gga(sol), rmc(sol))
