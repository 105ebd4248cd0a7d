"""The bounds of a position a client may report (NMEA GGA) and the centre may serve a VRS at.

Both the caster's GGA parser and the centre's session opening check against these, so a value one lets
through the other cannot refuse with a different rule. Heights are ellipsoidal (GGA altitude + geoid
separation) in metres.
"""

from __future__ import annotations

import math

# Lowest land is the Dead Sea shore (-430 m); the highest railway (Tanggula, Qinghai-Tibet) is at 5,068 m,
# the highest summit at 8,849 m: -1,000 .. +10,000 m keeps every receiver on the ground with room to spare.
MIN_HEIGHT_M = -1_000.0
MAX_HEIGHT_M = 10_000.0
# Geoid separation (GGA field 11): EGM2008 spans -107 .. +86 m; 200 m bounds it with room.
MAX_GEOID_SEPARATION_M = 200.0


def position_problem(lat_deg: float, lon_deg: float, height_m: float) -> str | None:
    """Why (lat, lon, height) is no position on Earth's surface a client can be at, or None if it is one."""
    try:
        lat, lon, h = float(lat_deg), float(lon_deg), float(height_m)
    except (TypeError, ValueError, OverflowError):
        return "position is not a number"
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(h)):
        return "position is not finite"
    if not -90.0 <= lat <= 90.0:
        return f"latitude {lat:.6g} deg outside -90..90"
    if not -180.0 <= lon <= 180.0:
        return f"longitude {lon:.6g} deg outside -180..180"
    if not MIN_HEIGHT_M <= h <= MAX_HEIGHT_M:
        return f"height {h:.6g} m outside {MIN_HEIGHT_M:.0f}..{MAX_HEIGHT_M:.0f} m"
    return None
