"""Receiver-side geometry: ECEF <-> geodetic (WGS 84, via pyproj), ENU, azimuth/elevation, Sagnac.

Angles in radians unless a name says `_deg`.  Arrays: positions are (..., 3); everything
broadcasts, so one call serves many satellites, receivers or epochs.
"""

from __future__ import annotations

import numpy as np
from pyproj import Transformer

from augnet.gnss.constants import OMEGA_E_GPS_RAD_S, SPEED_OF_LIGHT_M_S, WGS84_A_M, WGS84_E2

# EPSG:4978 = WGS 84 geocentric (ECEF), EPSG:4979 = WGS 84 geographic 3-D (lat, lon, ellipsoidal h).
# CGCS2000 and the Galileo reference frame agree with WGS 84 to centimetres; one ellipsoid serves.
_ECEF_TO_LLH = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
_LLH_TO_ECEF = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
REFINE_STEPS = 2


def ecef_to_geodetic(ecef_m):
    """(..., 3) ECEF [m] -> (..., 3) (latitude [rad], longitude [rad], ellipsoidal height [m])."""
    p = np.asarray(ecef_m, dtype=float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    lon, lat, _ = _ECEF_TO_LLH.transform(x, y, z, radians=True)
    # PROJ's closed-form inverse is micrometre-exact at the surface but drifts to decimetres at
    # GNSS orbit heights (0.3 m at 20,000 km, measured); two fixed-point steps of the exact
    # relation tan(lat) = z / (p (1 - e2 N / (N + h))) bring every height to micrometres.
    rho = np.hypot(x, y)
    for _ in range(REFINE_STEPS):
        sl, cl = np.sin(lat), np.cos(lat)
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sl * sl)
        h = rho * cl + z * sl - WGS84_A_M * np.sqrt(1.0 - WGS84_E2 * sl * sl)
        lat = np.arctan2(z, rho * (1.0 - WGS84_E2 * n / (n + h)))
    sl = np.sin(lat)
    h = rho * np.cos(lat) + z * sl - WGS84_A_M * np.sqrt(1.0 - WGS84_E2 * sl * sl)
    return np.stack(np.broadcast_arrays(lat, lon, h), axis=-1)


def geodetic_to_ecef(llh):
    """(..., 3) (latitude [rad], longitude [rad], height [m]) -> (..., 3) ECEF [m]."""
    q = np.asarray(llh, dtype=float)
    x, y, z = _LLH_TO_ECEF.transform(q[..., 1], q[..., 0], q[..., 2], radians=True)
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def geodetic_deg_to_ecef(lat_deg, lon_deg, h_m):
    return geodetic_to_ecef(np.stack(np.broadcast_arrays(np.radians(lat_deg), np.radians(lon_deg), h_m), axis=-1))


def enu_rotation(lat, lon):
    """(..., 3, 3) matrix R with enu = R @ d_ecef at geodetic (lat, lon) [rad]; rows E, N, U."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    zero = np.zeros_like(sl * so)
    rows = (
        (-so + zero, co + zero, zero),
        (-sl * co, -sl * so, cl + zero),
        (cl * co, cl * so, sl + zero),
    )
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def ecef_to_enu(d_ecef_m, origin_ecef_m):
    """ECEF vectors d (..., 3), relative to origin, into local east-north-up at the origin."""
    o = np.asarray(origin_ecef_m, dtype=float)
    llh = ecef_to_geodetic(o)
    rot = enu_rotation(llh[..., 0], llh[..., 1])
    return np.einsum("...ij,...j->...i", rot, np.asarray(d_ecef_m, dtype=float))


def enu_to_ecef(enu_m, origin_ecef_m):
    """Local ENU vectors at the origin back to ECEF vectors (not positions: add origin yourself)."""
    o = np.asarray(origin_ecef_m, dtype=float)
    llh = ecef_to_geodetic(o)
    rot = enu_rotation(llh[..., 0], llh[..., 1])
    return np.einsum("...ji,...j->...i", rot, np.asarray(enu_m, dtype=float))


def azimuth_elevation(receiver_ecef_m, sat_ecef_m):
    """(azimuth [rad, 0..2pi from north, clockwise], elevation [rad]) of satellites seen from a
    receiver.  receiver (..., 3) and satellites (..., 3) broadcast (e.g. (3,) with (N, 3))."""
    rx = np.asarray(receiver_ecef_m, dtype=float)
    llh = ecef_to_geodetic(rx)
    return azimuth_elevation_from(rx, enu_rotation(llh[..., 0], llh[..., 1]), sat_ecef_m)


def azimuth_elevation_from(receiver_ecef_m, rotation, sat_ecef_m):
    """`azimuth_elevation` with the receiver's ECEF -> ENU rotation given (`enu_rotation` of its latitude and
    longitude): a station that stands still computes it once."""
    rx = np.asarray(receiver_ecef_m, dtype=float)
    d = np.asarray(sat_ecef_m, dtype=float) - rx
    enu = np.einsum("...ij,...j->...i", rotation, d)
    e, n, u = enu[..., 0], enu[..., 1], enu[..., 2]
    az = np.mod(np.arctan2(e, n), 2.0 * np.pi)
    el = np.arctan2(u, np.hypot(e, n))
    return az, el


def sagnac_correction_m(sat_ecef_m, receiver_ecef_m, omega_e_rad_s: float = OMEGA_E_GPS_RAD_S):
    """Range correction [m] for the Earth's rotation during signal transit (Sagnac effect):
    omega_e (x_s y_r - y_s x_r) / c, with the satellite in the ECEF frame of transmission time.
    Add it to |sat - receiver| (IS-GPS-200 20.3.3.4.3.4; RTKLIB geodist uses the same form)."""
    s = np.asarray(sat_ecef_m, dtype=float)
    r = np.asarray(receiver_ecef_m, dtype=float)
    return omega_e_rad_s * (s[..., 0] * r[..., 1] - s[..., 1] * r[..., 0]) / SPEED_OF_LIGHT_M_S


def geometric_range_m(sat_ecef_m, receiver_ecef_m, omega_e_rad_s: float = OMEGA_E_GPS_RAD_S):
    """|sat - receiver| plus the Sagnac correction; satellite in the ECEF frame of transmission."""
    s = np.asarray(sat_ecef_m, dtype=float)
    r = np.asarray(receiver_ecef_m, dtype=float)
    return np.linalg.norm(s - r, axis=-1) + sagnac_correction_m(s, r, omega_e_rad_s)
