"""Inputs for post-processing: RINEX observation and navigation files, and base coordinates.

Reading is done by `augnet.gnss.rinex`; this module turns its values into what the positioning
core wants (`ObsArrays`, `NavigationData`, Klobuchar coefficients) and parses the coordinates a
user types on the command line.
"""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np

from augnet.gnss.antex import AntennaSetup
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import geodetic_deg_to_ecef
from augnet.onboard.observations import LLI_SLIP, ObsArrays

# |coordinate| above this [m] cannot be a latitude/longitude in degrees: it is ECEF.
ECEF_MIN_NORM_M = 1.0e5
# RINEX epoch flag 1: power failure between the previous and this epoch (every phase may slip).
EPOCH_FLAG_POWER_FAILURE = 1


class InputError(ValueError):
    """An input file or coordinate that cannot be used, with a message for the user."""


def load_obs(path: str | os.PathLike) -> ObsArrays:
    from augnet.gnss.rinex import RinexError, read_obs

    try:
        data = read_obs(path)
    except (OSError, RinexError) as exc:
        raise InputError(f"cannot read observations {path}: {exc}") from None
    if data.header.version < 3.0:
        from augnet.gnss.rinex.obs import to_rinex3_types

        data = to_rinex3_types(data)
    lli = {k: np.asarray(v, dtype=np.int16).copy() for k, v in data.lli.items()}
    flags = np.asarray(getattr(data, "flags", np.zeros(len(data.times))))
    power_fail = flags == EPOCH_FLAG_POWER_FAILURE
    if np.any(power_fail):
        for k in lli:
            lli[k][power_fail] |= LLI_SLIP
    return ObsArrays(np.asarray(data.times, dtype=float), [str(s) for s in data.sats], data.obs, lli,
                     np.asarray(data.header.approx_position_m, dtype=float),
                     marker_type=getattr(data.header, "marker_type", "") or "",
                     antenna_type=data.header.antenna_type, antenna_delta_hen_m=tuple(data.header.antenna_delta_hen_m))


def antenna_setup(obs: ObsArrays, antex, what: str) -> tuple[AntennaSetup | None, str]:
    """The receiver's antenna from its RINEX header (type and radome, DELTA H/E/N) and an ANTEX file, and a note;
    None when its type is not in the file and it has no antenna height either (nothing to model)."""
    from augnet.gnss.antex import NULL_ANTENNA, split_antenna_type

    h, e, n = obs.antenna_delta_hen_m
    delta = np.array([n, e, h], float)
    name, dome = split_antenna_type(obs.antenna_type or "")
    ant = None
    if name and name != NULL_ANTENNA:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ant = antex.receiver(name, dome)
    if ant is None:
        note = f"{what}: antenna {name or 'unknown'} {dome}: no calibration in the ANTEX file"
    else:
        note = f"{what}: {name} {dome}" + (" (radome NONE's calibration)" if ant.radome_fallback else "")
    if ant is None and not delta.any():
        return None, note
    return AntennaSetup(ant, delta), note + f", ARP {h:.4f} m above the marker"


def load_nav(paths: Sequence[str | os.PathLike]) -> tuple[NavigationData, tuple | None, tuple | None]:
    """NavigationData from one or more RINEX 3 nav files, and the GPS Klobuchar (alpha, beta) if given."""
    from augnet.gnss.rinex import RinexError, read_nav

    ephs = []
    alpha = beta = None
    for p in paths:
        try:
            nf = read_nav(p)
        except (OSError, RinexError) as exc:
            raise InputError(f"cannot read navigation data {p}: {exc}") from None
        ephs.extend(nf.ephemerides)
        a, b = klobuchar_from_header(nf.header.extra)
        alpha = alpha or a
        beta = beta or b
    if not ephs:
        raise InputError("no usable broadcast ephemerides in the navigation file(s)")
    return NavigationData(ephs), alpha, beta


def klobuchar_from_header(extra: Sequence[tuple[str, str]]) -> tuple[tuple | None, tuple | None]:
    """GPSA / GPSB coefficients from RINEX 3 'IONOSPHERIC CORR' header lines."""
    alpha = beta = None
    for content, label in extra:
        if label.strip() != "IONOSPHERIC CORR":
            continue
        kind = content[:4].strip()
        try:
            vals = tuple(float(content[5 + 12 * i: 17 + 12 * i].replace("D", "E")) for i in range(4))
        except ValueError:
            continue
        if kind == "GPSA":
            alpha = vals
        elif kind == "GPSB":
            beta = vals
    return alpha, beta


def parse_position(text: str) -> np.ndarray:
    """'X,Y,Z' (ECEF metres) or 'LAT,LON,H' (degrees, degrees, ellipsoidal metres) -> ECEF."""
    try:
        vals = [float(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        raise InputError(f"position {text!r}: expected three numbers separated by commas") from None
    if len(vals) != 3 or not all(np.isfinite(vals)):
        raise InputError(f"position {text!r}: expected three finite numbers")
    if max(abs(vals[0]), abs(vals[1])) > ECEF_MIN_NORM_M or abs(vals[2]) > ECEF_MIN_NORM_M:
        p = np.array(vals)
        if not 6.0e6 < np.linalg.norm(p) < 7.0e6:
            raise InputError(f"position {text!r}: ECEF coordinates not near the Earth's surface")
        return p
    lat, lon, h = vals
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0):
        raise InputError(f"position {text!r}: latitude/longitude out of range")
    return np.asarray(geodetic_deg_to_ecef(lat, lon, h), dtype=float)


def parse_gpst(text: str) -> float:
    """'YYYY-MM-DDTHH:MM:SS[.s]' (or with a space or '/' separators, as rnx2rtkp writes) in GPS time -> GPST
    seconds."""
    from augnet.gnss import time as gtime

    t = text.strip().replace("/", "-").replace(" ", "T")
    try:
        day, clock = t.split("T")
        y, mo, d = (int(v) for v in day.split("-"))
        hh, mm, ss = clock.split(":")
        return float(gtime.from_calendar(y, mo, d, int(hh), int(mm), float(ss)))
    except ValueError:
        raise InputError(f"time {text!r}: expected YYYY-MM-DDTHH:MM:SS (GPST)") from None


def time_window(data: ObsArrays, t0: float, t1: float) -> ObsArrays:
    """The epochs t0 <= t < t1 of `data`."""
    m = (data.times >= t0) & (data.times < t1)
    return ObsArrays(data.times[m], data.sats, {k: v[m] for k, v in data.obs.items()},
                     {k: v[m] for k, v in data.lli.items()}, data.approx_position_m, marker_type=data.marker_type)
