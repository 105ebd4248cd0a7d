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

# Standard atmosphere at sea level (ICAO): 1013.25 hPa, 15 C, lapse 6.5 K/km; humidity 50 %.
P0_HPA = 1013.25
T0_K = 288.15
LAPSE_K_M = 6.5e-3
REL_HUMIDITY = 0.5
WET_SCALE_HEIGHT_M = 2000.0
RESIDUAL_WAVES = 16
RESIDUAL_DRIFT_M_S = 10.0  # advection of water-vapour structures by the wind

# Niell (1996) mapping coefficients at latitudes 15, 30, 45, 60, 75 deg (J. Geophys. Res. 101(B2)).
_NMF_LAT = np.array([15.0, 30.0, 45.0, 60.0, 75.0])
_NMF_H_AVG = np.array([
    [1.2769934e-3, 1.2683230e-3, 1.2465397e-3, 1.2196049e-3, 1.2045996e-3],
    [2.9153695e-3, 2.9152299e-3, 2.9288445e-3, 2.9022565e-3, 2.9024912e-3],
    [62.610505e-3, 62.837393e-3, 63.721774e-3, 63.824265e-3, 64.258455e-3]])
_NMF_H_AMP = np.array([
    [0.0, 1.2709626e-5, 2.6523662e-5, 3.4000452e-5, 4.1202191e-5],
    [0.0, 2.1414979e-5, 3.0160779e-5, 7.2562722e-5, 11.723375e-5],
    [0.0, 9.0128400e-5, 4.3497037e-5, 84.795348e-5, 170.37206e-5]])
_NMF_W = np.array([
    [5.8021897e-4, 5.6794847e-4, 5.8118019e-4, 5.9727542e-4, 6.1641693e-4],
    [1.4275268e-3, 1.5138625e-3, 1.4572752e-3, 1.5007428e-3, 1.7599082e-3],
    [4.3472961e-2, 4.6729510e-2, 4.3908931e-2, 4.4626982e-2, 5.4736038e-2]])
_NMF_HT = (2.53e-5, 5.49e-3, 1.14e-3)
_NMF_DOY_PHASE = 28.0  # day of year of the seasonal minimum (northern hemisphere)


def _marini(sin_el, a, b, c):
    """Marini continued fraction normalised to 1 at zenith (the form of all Niell functions)."""
    top = 1 + a / (1 + b / (1 + c))
    return top / (sin_el + a / (sin_el + b / (sin_el + c)))


def niell(el, lat, h_m, doy):
    """Niell hydrostatic and wet mapping functions at elevation el, latitude lat [rad], height."""
    lat_deg = np.clip(np.abs(np.degrees(lat)), 15.0, 75.0)
    season = np.cos(2 * np.pi * (doy - _NMF_DOY_PHASE) / 365.25)
    if np.ndim(lat) and np.any(np.asarray(lat) < 0):
        season = np.where(np.asarray(lat) < 0, -season, season)
    ah = [np.interp(lat_deg, _NMF_LAT, _NMF_H_AVG[i]) - np.interp(lat_deg, _NMF_LAT, _NMF_H_AMP[i]) * season
          for i in range(3)]
    aw = [np.interp(lat_deg, _NMF_LAT, _NMF_W[i]) for i in range(3)]
    sin_el = np.sin(el)
    mh = _marini(sin_el, *ah)
    mh = mh + (1.0 / sin_el - _marini(sin_el, *_NMF_HT)) * h_m / 1e3
    mw = _marini(sin_el, *aw)
    return mh, mw


def zenith_delays_m(lat, h_m):
    """Saastamoinen zenith hydrostatic and wet delays [m] in the standard atmosphere."""
    h = np.clip(np.asarray(h_m, float), -500.0, 9000.0)
    p = P0_HPA * (1 - 2.2557e-5 * h) ** 5.2568
    t = T0_K - LAPSE_K_M * h
    e = 6.108 * REL_HUMIDITY * np.exp((17.15 * t - 4684.0) / (t - 38.45))  # hPa
    f = 1 - 0.00266 * np.cos(2 * lat) - 0.00028 * h / 1e3
    zhd = 0.0022768 * p / f
    zwd = 0.002277 * (1255.0 / t + 0.05) * e / f
    return zhd, zwd


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
