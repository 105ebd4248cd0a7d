"""Atmosphere models for the rover: Saastamoinen troposphere and the GPS Klobuchar ionosphere.

Vectorised over satellites.  Angles in radians.  (These belong in `augnet.gnss` eventually; they live
here until the gnss package grows an atmosphere module, and nothing else in onboard depends on where.)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S

# Standard atmosphere at sea level (ISO 2533): pressure [hPa], temperature [K], lapse rate [K/m].
STD_PRESSURE_HPA = 1013.25
STD_TEMPERATURE_K = 288.15
STD_LAPSE_K_M = 6.5e-3
# Relative humidity assumed without a met sensor (RTKLIB and most receivers use 0.7 or 0.5).
DEFAULT_RELATIVE_HUMIDITY = 0.7
# Saastamoinen (1972) hydrostatic and wet coefficients [m/hPa].
SAAS_HYDRO_M_HPA = 0.0022768
SAAS_WET_M_HPA = 0.002277
# The model is meaningless below the geoid or above the troposphere; heights outside are clamped.
TROPO_MIN_HEIGHT_M = -100.0
TROPO_MAX_HEIGHT_M = 1.0e4


def saastamoinen_m(lat_rad, height_m, elevation_rad, humidity: float = DEFAULT_RELATIVE_HUMIDITY):
    """Slant tropospheric delay [m] from Saastamoinen's model with a standard atmosphere.

    Elevations at or below zero give 0 (the caller masks those satellites anyway).
    """
    h = np.clip(np.asarray(height_m, dtype=float), TROPO_MIN_HEIGHT_M, TROPO_MAX_HEIGHT_M)
    el = np.asarray(elevation_rad, dtype=float)
    pres = STD_PRESSURE_HPA * (1.0 - 2.2557e-5 * h) ** 5.2568
    temp = STD_TEMPERATURE_K - STD_LAPSE_K_M * h
    # water vapour partial pressure [hPa] from relative humidity (Magnus-type formula)
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    z = np.pi / 2.0 - np.maximum(el, 1e-3)
    cosz = np.cos(z)
    hydro = SAAS_HYDRO_M_HPA * pres / (1.0 - 0.00266 * np.cos(2.0 * np.asarray(lat_rad)) - 0.00028 * h / 1e3) / cosz
    wet = SAAS_WET_M_HPA * (1255.0 / temp + 0.05) * e / cosz
    return np.where(el > 0.0, hydro + wet, 0.0)


# Klobuchar model constants (IS-GPS-200 20.3.3.5.2.5): earth-centred angle in semicircles, the
# geomagnetic pole (78.3 N, 291.0 E), a 350 km shell, night-time delay 5 ns, 72000 s minimum period.
_KLOB_NIGHT_S = 5e-9
_KLOB_MIN_PERIOD_S = 72000.0
_KLOB_PEAK_LOCAL_TIME_S = 50400.0
# Default coefficients (RTKLIB's ionutc defaults, a 2004 broadcast) used when the file gives none.
KLOBUCHAR_DEFAULT_ALPHA = (0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06)
KLOBUCHAR_DEFAULT_BETA = (0.1167e06, -0.2294e06, -0.1311e06, 0.1049e07)


def klobuchar_l1_m(t_gpst, lat_rad, lon_rad, azimuth_rad, elevation_rad, alpha, beta):
    """GPS L1 ionospheric group delay [m] (Klobuchar broadcast model).  Scale by (f1/f)^2 for f."""
    if np.ndim(t_gpst) == 0 and np.ndim(lat_rad) == 0 and np.ndim(lon_rad) == 0 and np.ndim(azimuth_rad) == 1 \
            and np.shape(azimuth_rad) == np.shape(elevation_rad) and len(alpha) == 4 and len(beta) == 4:
        # one receiver, many satellites (SPP every iteration): the same formulas compiled
        return _klobuchar_one_receiver(float(t_gpst), float(lat_rad), float(lon_rad),
                                       np.asarray(azimuth_rad, dtype=float), np.asarray(elevation_rad, dtype=float),
                                       np.asarray(alpha, dtype=float), np.asarray(beta, dtype=float))
    el_sc = np.asarray(elevation_rad, dtype=float) / np.pi
    az = np.asarray(azimuth_rad, dtype=float)
    lat_sc = np.asarray(lat_rad, dtype=float) / np.pi
    lon_sc = np.asarray(lon_rad, dtype=float) / np.pi
    psi = 0.0137 / (el_sc + 0.11) - 0.022
    phi_i = np.clip(lat_sc + psi * np.cos(az), -0.416, 0.416)
    lam_i = lon_sc + psi * np.sin(az) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)
    tow = np.mod(np.asarray(t_gpst, dtype=float), 86400.0)
    t_local = np.mod(4.32e4 * lam_i + tow, 86400.0)
    f = 1.0 + 16.0 * (0.53 - el_sc) ** 3
    amp = sum(a * phi_m**k for k, a in enumerate(alpha))
    per = sum(b * phi_m**k for k, b in enumerate(beta))
    amp = np.maximum(amp, 0.0)
    per = np.maximum(per, _KLOB_MIN_PERIOD_S)
    x = 2.0 * np.pi * (t_local - _KLOB_PEAK_LOCAL_TIME_S) / per
    day = _KLOB_NIGHT_S + amp * (1.0 - x**2 / 2.0 + x**4 / 24.0)
    delay_s = f * np.where(np.abs(x) < 1.57, day, _KLOB_NIGHT_S)
    return SPEED_OF_LIGHT_M_S * delay_s


@njit(cache=True)
def _klobuchar_one_receiver(t_gpst, lat_rad, lon_rad, az, el, alpha, beta):
    """`klobuchar_l1_m` for one receiver and a vector of satellites, compiled (term by term the same)."""
    out = np.empty(len(az))
    lat_sc = lat_rad / np.pi
    lon_sc = lon_rad / np.pi
    tow = np.mod(t_gpst, 86400.0)
    for k in range(len(az)):
        el_sc = el[k] / np.pi
        psi = 0.0137 / (el_sc + 0.11) - 0.022
        phi_i = min(max(lat_sc + psi * np.cos(az[k]), -0.416), 0.416)
        lam_i = lon_sc + psi * np.sin(az[k]) / np.cos(phi_i * np.pi)
        phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)
        t_local = np.mod(4.32e4 * lam_i + tow, 86400.0)
        f = 1.0 + 16.0 * (0.53 - el_sc) ** 3
        amp = alpha[0] + alpha[1] * phi_m + alpha[2] * phi_m**2 + alpha[3] * phi_m**3
        per = beta[0] + beta[1] * phi_m + beta[2] * phi_m**2 + beta[3] * phi_m**3
        amp = max(amp, 0.0)
        per = max(per, _KLOB_MIN_PERIOD_S)
        x = 2.0 * np.pi * (t_local - _KLOB_PEAK_LOCAL_TIME_S) / per
        if abs(x) < 1.57:
            delay = _KLOB_NIGHT_S + amp * (1.0 - x**2 / 2.0 + x**4 / 24.0)
        else:
            delay = _KLOB_NIGHT_S
        out[k] = SPEED_OF_LIGHT_M_S * f * delay
    return out
