"""Base observations interpolated to the rover's epoch, for post-processing (what RTKLIB's misc-timeinterp does).

A 1 Hz rover against a 30 s base otherwise uses corrections up to 29 s old, whose error grows with the age (the
satellite clocks' wander that the broadcast clock does not predict: `correction_age.py`; not predictable from
the base's own past either).  In a file both base epochs around the rover's epoch are known: each satellite's base
residual (observation minus geometric range and a-priori troposphere plus satellite clock, per slot and kind,
as RTKLIB interpolates its zero-difference residuals) is interpolated linearly
in time and the geometry and clock of the rover's epoch are put back.  What is common to every satellite (the
base receiver's clock, even a millisecond step) cancels in the double differences.  A phase that slipped between
the two epochs (its LLI, or found by `flag_slips` at the base's own rate: a slip bridged by a straight line would
be a slow ramp no 1 s test catches) keeps its earlier residual, as without interpolation.  A real-time rover has
no later epoch: this is post-processing only.
"""

from __future__ import annotations

import numpy as np

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData
from augnet.onboard.atmosphere import DEFAULT_RELATIVE_HUMIDITY, saastamoinen_m
from augnet.onboard.cycleslip import BASE_GF_DRIFT_M_S, BASE_GF_SLIP_THRESHOLD_M, SlipDetector
from augnet.onboard.observations import LLI_HALF_CYCLE, LLI_SLIP, EpochObs
from augnet.onboard.spp import azimuth_elevation_from, first_code, geometric_range, receiver_frame, satellite_positions

# Base epochs further apart than this [s] are not interpolated between (one missing epoch of a 30 s base is).
MAX_INTERPOLATION_SPAN_S = 60.5
# Transmission-time iterations: the first from the earlier epoch's code (up to ~25 km off over 30 s: 6 cm of
# range), the second from the interpolated code (millimetres off: nanometres of range).
TRANSMISSION_ITERATIONS = 2


def flag_slips(base_epochs) -> None:
    """Set the loss-of-lock flag where a base phase slipped since the previous base epoch (the base's LLI, a
    geometry-free jump or a phase-Doppler mismatch at the base's own interval; epochs in time order)."""
    det = SlipDetector(max_gap_s=MAX_INTERPOLATION_SPAN_S, gf_threshold_m=BASE_GF_SLIP_THRESHOLD_M,
                       gf_drift_m_s=BASE_GF_DRIFT_M_S)
    for ep in base_epochs:
        ep.lli = np.where(det.detect(ep), ep.lli | LLI_SLIP, ep.lli).astype(ep.lli.dtype)


def _geometry_minus_clock(nav: NavigationData, sats, t: float, code_m: np.ndarray, base_position_m,
                          t_select: float, humidity: float = DEFAULT_RELATIVE_HUMIDITY) -> tuple[np.ndarray, np.ndarray]:
    """(geometric range plus a-priori troposphere minus the satellite clock [m], valid) per satellite for a base
    epoch at t: the model whose residual is interpolated (the troposphere's growth towards the horizon, 5 mm/s
    at 15 degrees, is in the model, not in the straight line)."""
    rx = np.asarray(base_position_m, dtype=float)
    sp = satellite_positions(nav, sats, t, code_m, t_select=t_select)
    pos = np.where(sp.valid[:, None], sp.position_m, rx + np.array([0.0, 0.0, 1.0]))
    rho, _ = geometric_range(pos, rx)
    llh, rot = receiver_frame(rx)
    _, el = azimuth_elevation_from(rx, rot, pos)
    trop = saastamoinen_m(llh[0], llh[2], el, humidity)
    return rho + trop - SPEED_OF_LIGHT_M_S * sp.clock_s, sp.valid & np.isfinite(rho)


def interpolate(b0: EpochObs, b1: EpochObs, t: float, nav: NavigationData, base_position_m,
                first_after_b0: bool = True, humidity: float = DEFAULT_RELATIVE_HUMIDITY) -> EpochObs:
    """The base's observations at t (b0.time < t < b1.time), for b0's satellites.

    `first_after_b0`: this is the first epoch built from b0, so it carries b0's loss-of-lock flags (later ones
    only the half-cycle flag, a state).  The result's `info_age_s` is the distance to the nearer base epoch.
    `humidity`: the RTK filter's troposphere model (RtkOptions.tropo_humidity), so that holding a residual
    (a slipped phase) is exactly what the filter would do with the older epoch.
    """
    t0, t1 = float(b0.time), float(b1.time)
    f = (t - t0) / (t1 - t0)
    n, nf = b0.code_m.shape
    # b1's rows in b0's satellite order (NaN where b1 lacks the satellite)
    pos = {s: i for i, s in enumerate(b1.sats)}
    j = np.array([pos.get(s, -1) for s in b0.sats], dtype=int)
    has1 = j >= 0
    take = np.where(has1, j, 0)

    def rows1(a: np.ndarray, fill) -> np.ndarray:
        return np.where(has1[:, None], a[take], fill)

    code1, phase1, lli1 = rows1(b1.code_m, np.nan), rows1(b1.phase_cyc, np.nan), rows1(b1.lli, 0)
    dop1 = rows1(b1.doppler_hz, np.nan)
    g0, ok0 = _geometry_minus_clock(nav, b0.sats, t0, first_code(b0), base_position_m, t, humidity)
    b1_code_first = first_code(EpochObs(t1, b0.sats, code1, phase1, dop1, b0.snr_dbhz, lli1, b0.wavelength_m,
                                        b0.signal))
    g1, ok1 = _geometry_minus_clock(nav, b0.sats, t1, b1_code_first, base_position_m, t, humidity)
    wl = b0.wavelength_m
    # residuals [m] at both ends, per slot
    rc0, rc1 = b0.code_m - g0[:, None], code1 - g1[:, None]
    rp0, rp1 = b0.phase_cyc * wl - g0[:, None], phase1 * wl - g1[:, None]
    both = (ok0 & ok1)[:, None]
    code_ok = both & np.isfinite(rc0) & np.isfinite(rc1)
    # a slip at b1 (or no phase there) breaks the arc between the epochs: keep b0's residual
    phase_ok = both & np.isfinite(rp0) & np.isfinite(rp1) & ((lli1 & LLI_SLIP) == 0)
    rc = np.where(code_ok, rc0 + f * (rc1 - rc0), rc0)
    rp = np.where(phase_ok, rp0 + f * (rp1 - rp0), rp0)
    # geometry and clock at t, from a transmission time that converges on the interpolated code
    code_t = first_code(b0)
    for _ in range(TRANSMISSION_ITERATIONS):
        g, ok = _geometry_minus_clock(nav, b0.sats, t, code_t, base_position_m, t, humidity)
        first_rc = first_code(EpochObs(t, b0.sats, rc, rp, b0.doppler_hz, b0.snr_dbhz, b0.lli, wl, b0.signal))
        code_t = first_rc + g
    code = np.where(ok[:, None], rc + g[:, None], np.nan)
    phase = np.where(ok[:, None], (rp + g[:, None]) / wl, np.nan)
    dop = np.where(np.isfinite(dop1), b0.doppler_hz + f * (dop1 - b0.doppler_hz), b0.doppler_hz)
    lli = b0.lli if first_after_b0 else (b0.lli & LLI_HALF_CYCLE)
    return EpochObs(float(t), b0.sats, code, phase, dop, b0.snr_dbhz.copy(), lli.copy(), wl, b0.signal,
                    float(min(t - t0, t1 - t)), t1)
