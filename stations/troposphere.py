"""Truth troposphere: Saastamoinen zenith delays, Niell mapping, and a residual wet field.

Zenith hydrostatic delay from Saastamoinen (1972) with the standard-atmosphere pressure at the
station height; zenith wet delay from Saastamoinen's wet term with a standard temperature lapse and a
fixed relative humidity; both mapped with the Niell (1996) functions (hydrostatic incl. the height
correction, wet).  The truth adds a residual zenith wet delay that varies with position and time
(drifting random plane waves, like the ionosphere's irregularities) and decays with height (water
vapour scale height ~2 km), which is what a network has to estimate and interpolate.

Non-dispersive: the same delay on code and phase and on every frequency.
"""

from __future__ import annotations

import numpy as np

# The model part is the estimators' own a priori model: one implementation, so truth and model agree
# wherever the truth has no residual.
from augnet.gnss.troposphere import niell, zenith_delays_m  # noqa: F401  (re-exported for the world)

WET_SCALE_HEIGHT_M = 2000.0
RESIDUAL_WAVES = 16
RESIDUAL_DRIFT_M_S = 10.0  # advection of water-vapour structures by the wind


class WetResidualField:
    """Residual zenith wet delay [m] over the region: zero-mean, given std and horizontal scale."""

    def __init__(self, std_m: float, scale_km: float, lat0_deg: float, lon0_deg: float, seed: int):
        rng = np.random.default_rng([seed, 0x7209])
        self.lat0 = np.radians(lat0_deg)
        self.lon0 = np.radians(lon0_deg)
        k = 2 * np.pi / (scale_km * 1e3 * rng.uniform(0.6, 1.6, RESIDUAL_WAVES))
        ang = rng.uniform(0, 2 * np.pi, RESIDUAL_WAVES)
        self.kvec = np.column_stack([k * np.cos(ang), k * np.sin(ang)])
        wind = rng.uniform(0, 2 * np.pi)
        self.omega = self.kvec @ (RESIDUAL_DRIFT_M_S * np.array([np.cos(wind), np.sin(wind)]))
        self.phase = rng.uniform(0, 2 * np.pi, RESIDUAL_WAVES)
        self.amp = std_m / np.sqrt(RESIDUAL_WAVES / 2.0)

    def zwd_residual_m(self, lat, lon, h_m, t_gpst):
        if self.amp == 0.0:
            return np.zeros(np.broadcast(lat, lon, h_m, t_gpst).shape)
        x = 6_371_000.0 * (lon - self.lon0) * np.cos(self.lat0)
        y = 6_371_000.0 * (lat - self.lat0)
        xy = np.stack(np.broadcast_arrays(x, y), axis=-1)
        arg = xy @ self.kvec.T - self.omega * np.asarray(t_gpst, float)[..., None] + self.phase
        return self.amp * np.cos(arg).sum(axis=-1) * np.exp(-np.maximum(h_m, 0.0) / WET_SCALE_HEIGHT_M)
