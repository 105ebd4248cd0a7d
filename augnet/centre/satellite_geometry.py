"""Satellite geometry seen from a point with known coordinates, at one epoch: ranges with the satellite
clocks, elevations, the troposphere model, the receiver clock from the code, and (given the station's ANTEX
calibration) the receiver antenna's phase-centre correction per frequency.

The point is the antenna reference point (ARP). Without an antenna model the phase centre is taken to be at
the ARP (`antenna_m` zero), as before antenna models existed; with one, `antenna_m` = e . PCO - PCV per
satellite and frequency (`augnet.gnss.antex`), which the single differences add to the observations so that
they refer to the ARP (equivalently: the modelled range to the phase centre is g - antenna_m)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.gnss import troposphere
from augnet.gnss.antex import ReceiverAntenna
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, transit
from augnet.gnss.geometry import azimuth_elevation, ecef_to_geodetic
from augnet.gnss.time import to_datetime

C = SPEED_OF_LIGHT_M_S
MIN_MODEL_ELEVATION_RAD = math.radians(1.0)  # mapping functions are not defined at the horizon


@dataclass
class SatelliteGeometry:
    sats: np.ndarray
    g_m: np.ndarray  # rho - c * dts [m]: range (Sagnac incl.) minus satellite clock (relativity incl.)
    elevation_rad: np.ndarray
    azimuth_rad: np.ndarray
    trop_model_m: np.ndarray  # model slant troposphere [m]
    wet_mapping: np.ndarray  # Niell wet mapping function
    clock_s: float  # receiver clock offset (from the code, or as given)
    valid: np.ndarray  # ephemeris available
    # (S, 2) receiver antenna phase-centre correction e . PCO - PCV [m] per frequency; None: no antenna model
    antenna_m: np.ndarray | None = None

    def subset(self, m) -> SatelliteGeometry:
        m = np.asarray(m)
        return SatelliteGeometry(self.sats[m], self.g_m[m], self.elevation_rad[m], self.azimuth_rad[m],
                                 self.trop_model_m[m], self.wet_mapping[m], self.clock_s, self.valid[m],
                                 None if self.antenna_m is None else self.antenna_m[m])


def satellite_geometry(sats, t_tag_gpst: float, xyz_m, nav: NavigationData, code_m=None,
                       clock_s: float = 0.0, antenna: ReceiverAntenna | None = None,
                       codes=None) -> SatelliteGeometry:
    """Geometry at a point for signals received at epoch tag t_tag (receiver time).

    With `code_m` (first-frequency pseudoranges) the receiver clock is estimated from it (median of the
    code minus geometry: robust, and good to some ns, which moves the satellites by micrometres);
    otherwise `clock_s` is used as given (a virtual station shares its master's clock). With `antenna` (the
    station's calibration) and `codes` (S, 2) the RINEX codes observed, `antenna_m` holds its phase-centre
    corrections.
    """
    sats = np.asarray(sats)
    xyz = np.asarray(xyz_m, float)
    dtr = clock_s
    iterations = 2 if code_m is not None else 1
    for _ in range(iterations):
        tr = transit(nav, list(sats), xyz, t_tag_gpst - dtr)
        if code_m is None:
            break
        res = np.asarray(code_m, float) - tr.range_m + C * tr.sat_clock_bias_s
        ok = np.isfinite(res)
        if not ok.any():
            break
        dtr = float(np.median(res[ok])) / C
    az, el = azimuth_elevation(xyz, tr.sat_position_m)
    lat, _, h = ecef_to_geodetic(xyz)
    doy = to_datetime(t_tag_gpst).timetuple().tm_yday
    el_c = np.clip(np.where(np.isfinite(el), el, math.pi / 2), MIN_MODEL_ELEVATION_RAD, None)
    dh, dw = troposphere.slant_delays_m(el_c, lat, h, doy)
    _, mw = troposphere.niell(el_c, lat, h, doy)
    ant = None
    if antenna is not None and codes is not None:
        ant = np.nan_to_num(antenna.correction_m(az, el, sats, codes))
    return SatelliteGeometry(sats, tr.range_m - C * tr.sat_clock_bias_s, el, az, dh + dw, mw, dtr,
                             tr.valid & np.isfinite(tr.range_m), ant)
