"""Satellite geometry seen from a point with known coordinates, at one epoch: ranges with the satellite
clocks, elevations, the troposphere model, the receiver clock from the code, and (given the station's ANTEX
calibration) the receiver antenna's phase-centre correction per frequency.

The point is the antenna reference point (ARP). Without an antenna model the phase centre is taken to be at
the ARP (`antenna_m` zero), as before antenna models existed; with one, `antenna_m` = e . PCO - PCV per
satellite and frequency (`augnet.gnss.antex`), which the single differences add to the observations so that
they refer to the ARP (equivalently: the modelled range to the phase centre is g - antenna_m)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from augnet.gnss import troposphere
from augnet.gnss.antex import ReceiverAntenna
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, Transit, transit_each
from augnet.gnss.geometry import azimuth_elevation_from, ecef_to_geodetic, enu_rotation
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
    return station_geometries([GeometryRequest(sats, t_tag_gpst, xyz_m, code_m, clock_s, antenna, codes)], nav)[0]


@dataclass(frozen=True)
class GeometryRequest:
    """One point's arguments of `satellite_geometry`."""

    sats: object
    t_tag_gpst: float
    xyz_m: object
    code_m: object = None
    clock_s: float = 0.0
    antenna: ReceiverAntenna | None = None
    codes: object = None


def station_geometries(requests: list[GeometryRequest], nav: NavigationData) -> list[SatelliteGeometry]:
    """`satellite_geometry` of many points at once: every point's satellites go through one transit evaluation
    per clock iteration (numpy over all stations' satellites, each point's Kepler iterations as if alone), so
    the results are those of one call per point, bit for bit."""
    sats = [np.asarray(r.sats) for r in requests]
    xyz = [np.asarray(r.xyz_m, float) for r in requests]
    dtr = [r.clock_s for r in requests]
    trs: list[Transit | None] = [None] * len(requests)
    # stations still iterating: the clock from the code is estimated twice (once without code: not at all)
    todo = list(range(len(requests)))
    for it in range(2):
        todo = [i for i in todo if it == 0 or requests[i].code_m is not None]
        if not todo:
            break
        for i, tr in zip(todo, _transits(nav, [sats[i] for i in todo], [xyz[i] for i in todo],
                                         [requests[i].t_tag_gpst - dtr[i] for i in todo])):
            trs[i] = tr
        nxt = []
        for i in todo:
            if requests[i].code_m is None:
                continue
            res = np.asarray(requests[i].code_m, float) - trs[i].range_m + C * trs[i].sat_clock_bias_s
            ok = np.isfinite(res)
            if not ok.any():
                continue
            dtr[i] = float(np.median(res[ok])) / C
            nxt.append(i)
        todo = nxt
    return [_geometry(sats[i], r.t_tag_gpst, xyz[i], trs[i], dtr[i], r.antenna, r.codes)
            for i, r in enumerate(requests)]


def _transits(nav: NavigationData, sats: list[np.ndarray], xyz: list[np.ndarray], t_rx: list[float]) -> list[Transit]:
    """One `transit` per point, evaluated together (`transit_each`) and split again."""
    counts = [len(s) for s in sats]
    flat = transit_each(nav, np.concatenate([np.asarray(s, dtype=object) for s in sats]) if sats else [],
                        np.repeat(np.asarray(xyz).reshape(-1, 3), counts, axis=0),
                        np.repeat(np.asarray(t_rx, float), counts), np.repeat(np.arange(len(sats)), counts))
    out, at = [], 0
    for n in counts:
        out.append(Transit(*(f[at:at + n] for f in flat)))
        at += n
    return out


@functools.lru_cache(maxsize=4096)  # a network's stations stand still: their frame once, not every epoch
def _station_frame(xyz: tuple[float, float, float]):
    """Latitude [rad], height [m], ECEF -> ENU rotation and the model's zenith delays [m] at a point."""
    llh = ecef_to_geodetic(np.array(xyz))
    zhd, zwd = troposphere.zenith_delays_m(llh[0], llh[2])
    return llh[0], llh[2], enu_rotation(llh[..., 0], llh[..., 1]), zhd, zwd


def _geometry(sats, t_tag_gpst: float, xyz, tr: Transit, dtr: float, antenna, codes) -> SatelliteGeometry:
    lat, h, rot, zhd, zwd = _station_frame(tuple(np.asarray(xyz, float).reshape(3).tolist()))
    az, el = azimuth_elevation_from(xyz, rot, tr.sat_position_m)
    doy = to_datetime(t_tag_gpst).timetuple().tm_yday
    el_c = np.clip(np.where(np.isfinite(el), el, math.pi / 2), MIN_MODEL_ELEVATION_RAD, None)
    mh, mw = troposphere.niell(el_c, lat, h, doy)
    dh, dw = zhd * mh, zwd * mw  # troposphere.slant_delays_m, with the wet mapping kept
    ant = None
    if antenna is not None and codes is not None:
        ant = np.nan_to_num(antenna.correction_m(az, el, sats, codes))
    return SatelliteGeometry(sats, tr.range_m - C * tr.sat_clock_bias_s, el, az, dh + dw, mw, dtr,
                             tr.valid & np.isfinite(tr.range_m), ant)
