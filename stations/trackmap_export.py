"""The simulated line as the train's track database (format "augnet-trackmap/1", read by
`augnet.onboard.trackmap.TrackDatabase.from_dict`): what a railway's survey department would hand the
onboard unit, derived here from the scenario's track geometry (the truth the trains run on).

Every track of the line is exported (main-line tracks and station loops) as its polyline vertices
with their chainage, and a virtual balise group is placed on every main-line track
every `BALISE_SPACING_KM` (railway.md: virtual balises replace physical ones at the same kind of
spacing as the balise groups they stand in for, typically a few km on high-speed lines).
"""

from __future__ import annotations

import numpy as np

from stations.scenario import Scenario
from stations.track import TrackLine

FORMAT = "augnet-trackmap/1"  # same tag as augnet.onboard.trackmap.FORMAT (stations may not import augnet.onboard)
BALISE_SPACING_KM = 5.0
BALISE_MARGIN_KM = 1.0  # none within this of either end of the line


def track_database(sc: Scenario, line: TrackLine | None = None, *,
                   balise_spacing_km: float = BALISE_SPACING_KM) -> dict:
    """The scenario's tracks and virtual balises as an augnet-trackmap/1 dictionary."""
    if sc.line is None:
        raise ValueError(f"scenario {sc.name!r} has no line: there is no track database to export")
    line = line or TrackLine(sc.line)
    tracks = []
    for tid, poly in line.tracks.items():
        # the polyline's own vertices: truth positions are linear between them, so the map is exact
        llh = line.plane_to_geodetic(poly.enu)
        tracks.append({"id": tid, "line": sc.line.id, "points": np.round(llh, 9).tolist(),
                       "km": np.round(poly.s_m / 1000.0, 6).tolist()})
    balises = []
    if balise_spacing_km > 0:
        kms = np.arange(BALISE_MARGIN_KM, line.length_m / 1000.0 - BALISE_MARGIN_KM, balise_spacing_km)
        for k in range(1, sc.line.tracks + 1):
            tid = line.track_id(k)
            for km in kms:
                bid = f"VB-{tid}-{km:07.3f}"
                balises.append({"id": bid, "track": tid, "km": round(float(km), 3),
                                "telegram": f"{k:02x}{int(round(km * 1000)):08x}"})
    return {"format": FORMAT, "name": sc.name, "tracks": tracks, "balises": balises}

