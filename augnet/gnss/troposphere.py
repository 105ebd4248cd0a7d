"""A priori troposphere model: Saastamoinen zenith delays in a standard atmosphere, Niell mapping.

Zenith hydrostatic delay from Saastamoinen (1972) with the standard-atmosphere pressure at the station
height; zenith wet delay from Saastamoinen's wet term with a standard temperature lapse and fixed relative
humidity; both mapped with the Niell (1996) functions (hydrostatic incl. the height correction, wet).
Non-dispersive: the same delay on code and phase and on every frequency. The simulator's truth adds a
residual wet field to this model; the network estimates that residual.
"""

from __future__ import annotations

import numpy as np

# Standard atmosphere at sea level (ICAO): 1013.25 hPa, 15 C, lapse 6.5 K/km; humidity 50 %.
P0_HPA = 1013.25
T0_K = 288.15
LAPSE_K_M = 6.5e-3
REL_HUMIDITY = 0.5

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


def slant_delays_m(el, lat, h_m, doy):
    """Hydrostatic and wet slant delays [m] of the model at elevation el [rad] (any broadcastable shape)."""
    zhd, zwd = zenith_delays_m(lat, h_m)
    mh, mw = niell(el, lat, h_m, doy)
    return zhd * mh, zwd * mw


def slant_delay_m(el, lat, h_m, doy):
    """Total model slant delay [m]."""
    dh, dw = slant_delays_m(el, lat, h_m, doy)
    return dh + dw
