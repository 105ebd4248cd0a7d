"""Geometry: ECEF <-> geodetic, ENU, azimuth/elevation, Sagnac."""

from __future__ import annotations

import numpy as np

from augnet.gnss.constants import OMEGA_E_GPS_RAD_S, SPEED_OF_LIGHT_M_S, WGS84_A_M, WGS84_F
from augnet.gnss.geometry import (
    azimuth_elevation,
    ecef_to_enu,
    ecef_to_geodetic,
    enu_to_ecef,
    geodetic_deg_to_ecef,
    geodetic_to_ecef,
    geometric_range_m,
    sagnac_correction_m,
)


def test_ecef_geodetic_round_trip_vectorised():
    rng = np.random.default_rng(1)
    llh = np.column_stack(
        [
            rng.uniform(-np.pi / 2, np.pi / 2, 1000),
            rng.uniform(-np.pi, np.pi, 1000),
            rng.uniform(-500.0, 30_000_000.0, 1000),
        ]
    )
    ecef = geodetic_to_ecef(llh)
    assert ecef.shape == (1000, 3)
    back = ecef_to_geodetic(ecef)
    # Micrometres at every height up to GNSS orbits (PROJ alone drifts to 0.3 m at 20,000 km).
    assert np.max(np.abs(back[:, 0] - llh[:, 0])) < 1e-13
    assert np.max(np.abs(np.angle(np.exp(1j * (back[:, 1] - llh[:, 1]))))) < 1e-13
    assert np.max(np.abs(back[:, 2] - llh[:, 2])) < 1e-6
    assert np.max(np.abs(geodetic_to_ecef(back) - ecef)) < 1e-6


def test_known_points():
    assert np.allclose(geodetic_deg_to_ecef(0.0, 0.0, 0.0), [WGS84_A_M, 0.0, 0.0], atol=1e-6)
    b = WGS84_A_M * (1 - WGS84_F)
    assert np.allclose(geodetic_deg_to_ecef(90.0, 0.0, 100.0), [0.0, 0.0, b + 100.0], atol=1e-6)
    assert np.allclose(geodetic_deg_to_ecef(0.0, 90.0, 0.0), [0.0, WGS84_A_M, 0.0], atol=1e-6)
    # The 2024 static base: position file gives lat/lon/h, the RINEX header the same point in ECEF
    # (header approx position within a metre).
    p = geodetic_deg_to_ecef(35.134707705, 136.977577939, 104.853)
    assert np.linalg.norm(p - [-3817680.7270, 3562839.5216, 3650159.2407]) < 1.0


def test_azimuth_elevation_known_cases():
    rx = np.array([WGS84_A_M, 0.0, 0.0])  # equator, Greenwich
    sats = np.array(
        [
            [WGS84_A_M + 2e7, 0.0, 0.0],  # zenith
            [WGS84_A_M, 0.0, 1e6],  # due north on the horizon
            [WGS84_A_M, 1e6, 0.0],  # due east on the horizon
            [WGS84_A_M, -1e6, 0.0],  # due west
            [WGS84_A_M + 1e6, 0.0, -1e6],  # south, 45 degrees up
        ]
    )
    az, el = azimuth_elevation(rx, sats)
    assert np.isclose(el[0], np.pi / 2)
    assert np.allclose(np.degrees(az[1:]), [0.0, 90.0, 270.0, 180.0], atol=1e-9)
    assert np.allclose(np.degrees(el[1:]), [0.0, 0.0, 0.0, 45.0], atol=1e-9)
    # Many receivers against many satellites by broadcasting: (R, 1, 3) with (S, 3) -> (R, S).
    rxs = geodetic_deg_to_ecef(np.array([10.0, 50.0]), np.array([20.0, -70.0]), 0.0)
    az2, el2 = azimuth_elevation(rxs[:, None, :], sats[None, :, :])
    assert az2.shape == (2, 5)


def test_enu_round_trip_and_up_axis():
    origin = geodetic_deg_to_ecef(35.0, 139.0, 50.0)
    up = geodetic_deg_to_ecef(35.0, 139.0, 150.0) - origin
    assert np.allclose(ecef_to_enu(up, origin), [0.0, 0.0, 100.0], atol=1e-6)
    d = np.array([[10.0, -3.0, 7.0], [1000.0, 2000.0, -50.0]])
    assert np.allclose(enu_to_ecef(ecef_to_enu(d, origin), origin), d, atol=1e-9)


def test_sagnac_correction():
    rx = np.array([WGS84_A_M, 0.0, 0.0])
    sat = np.array([0.0, 2.6e7, 0.0])
    expected = -OMEGA_E_GPS_RAD_S * 2.6e7 * WGS84_A_M / SPEED_OF_LIGHT_M_S  # about -40 m
    assert np.isclose(sagnac_correction_m(sat, rx), expected)
    assert -41.0 < expected < -40.0
    # Same as rotating the satellite by omega*tau (the exact form) to within a millimetre.
    rng_lin = geometric_range_m(sat, rx)
    tau = np.linalg.norm(sat - rx) / SPEED_OF_LIGHT_M_S
    for _ in range(3):
        a = OMEGA_E_GPS_RAD_S * tau
        rot = np.array([sat[0] * np.cos(a) + sat[1] * np.sin(a), -sat[0] * np.sin(a) + sat[1] * np.cos(a), sat[2]])
        tau = np.linalg.norm(rot - rx) / SPEED_OF_LIGHT_M_S
    assert abs(rng_lin - np.linalg.norm(rot - rx)) < 2e-3
