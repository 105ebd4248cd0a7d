"""Cycle-slip detection on one receiver's carrier phases, epoch by epoch.

Three independent tests, each cheap and each catching what the others miss:
  - the receiver's loss-of-lock indicator (RINEX LLI bit 0, RTCM MSM lock-time reset);
  - a jump in the geometry-free combination lambda1 phi1 - lambda2 phi2 (dual frequency):
    geometry, clocks and troposphere cancel, the ionosphere changes by millimetres per second,
    so a jump of several centimetres is a slip on one of the two frequencies;
  - phase against Doppler: the phase change over the interval must match the integrated Doppler;
    the receiver-clock part is common to all satellites, so the median discrepancy is removed.
A satellite not seen for longer than a gap limit is treated as slipped (its ambiguity is re-found).
"""

from __future__ import annotations

import numpy as np

from augnet.onboard.observations import LLI_SLIP, EpochObs

# Geometry-free jump threshold [m] (RTKLIB's default thresslip is 0.05 m); the ionosphere moves the
# combination by under 1 cm/s even in a storm at low elevation, so 5 cm over a 1 s step is a slip.
GF_SLIP_THRESHOLD_M = 0.05
# Allowed geometry-free drift per second of interval [m/s] (ionospheric rate, generous).
GF_DRIFT_M_S = 0.01
# A reference station (or a VRS, which carries its master station's data) is static and geodetic: its
# geometry-free combination moves only with the ionosphere (mm/s) and mm-level noise, so a tighter test
# catches jumps a rover's test would miss -- e.g. a VRS whose satellite switches from single-base to
# network-corrected data, a dispersive step of several cm with no loss-of-lock flag.
BASE_GF_SLIP_THRESHOLD_M = 0.025
BASE_GF_DRIFT_M_S = 0.005
# Phase vs integrated Doppler, after removing the common (clock) part [cycles]; Doppler noise and
# the averaging error of a train's acceleration stay far below this.
DOPPLER_SLIP_THRESHOLD_CYC = 5.0
DOPPLER_DRIFT_CYC_S = 1.0
# Longer gaps than this [s] break the arc: integer ambiguities are not carried across.
MAX_ARC_GAP_S = 10.0


class SlipDetector:
    """Keeps the previous epoch per satellite and flags slips in the next one."""

    def __init__(self, max_gap_s: float = MAX_ARC_GAP_S, gf_threshold_m: float = GF_SLIP_THRESHOLD_M,
                 gf_drift_m_s: float = GF_DRIFT_M_S):
        self.max_gap_s = max_gap_s
        self.gf_threshold_m = gf_threshold_m
        self.gf_drift_m_s = gf_drift_m_s
        self._prev: dict[str, tuple[float, np.ndarray, np.ndarray, float]] = {}

    def reset(self) -> None:
        self._prev.clear()

    def detect(self, obs: EpochObs) -> np.ndarray:
        """(N, F) bool: True where the phase of that satellite and slot must not be trusted to continue."""
        n, nf = obs.phase_cyc.shape
        slip = (obs.lli & LLI_SLIP) != 0
        slip &= np.isfinite(obs.phase_cyc)
        gf = _geometry_free(obs)
        dop_disc = np.full((n, nf), np.nan)
        prev_t = np.full(n, np.nan)
        prev_gf = np.full(n, np.nan)
        for i, sat in enumerate(obs.sats):
            p = self._prev.get(str(sat))
            if p is None:
                continue
            t0, ph0, d0, g0 = p
            dt = obs.time - t0
            if dt < 0.0 or dt > self.max_gap_s:
                slip[i] |= np.isfinite(obs.phase_cyc[i])
                continue
            prev_t[i] = t0
            prev_gf[i] = g0
            dop = 0.5 * (obs.doppler_hz[i] + d0)
            # RINEX sign convention: phase grows with range, Doppler is positive when approaching
            dop_disc[i] = (obs.phase_cyc[i] - ph0) + dop * dt
            # a phase that vanished and returned within the gap is not continuous either
            slip[i] |= np.isfinite(obs.phase_cyc[i]) & ~np.isfinite(ph0)
        dt_all = obs.time - prev_t
        jump = np.abs(gf - prev_gf)
        gf_slip = jump > self.gf_threshold_m + self.gf_drift_m_s * np.nan_to_num(dt_all, nan=0.0)
        slip |= gf_slip[:, None] & np.isfinite(obs.phase_cyc)
        for f in range(nf):
            col = dop_disc[:, f]
            ok = np.isfinite(col)
            if np.count_nonzero(ok) >= 2:
                common = np.median(col[ok])
                lim = DOPPLER_SLIP_THRESHOLD_CYC + DOPPLER_DRIFT_CYC_S * np.nan_to_num(dt_all, nan=0.0)
                slip[:, f] |= ok & (np.abs(col - common) > lim)
        for i, sat in enumerate(obs.sats):
            if np.any(np.isfinite(obs.phase_cyc[i])):
                self._prev[str(sat)] = (obs.time, obs.phase_cyc[i].copy(), obs.doppler_hz[i].copy(), gf[i])
        return slip


def _geometry_free(obs: EpochObs) -> np.ndarray:
    """lambda1 phi1 - lambda2 phi2 [m] per satellite (NaN without two frequencies)."""
    if obs.phase_cyc.shape[1] < 2:
        return np.full(len(obs.sats), np.nan)
    return obs.wavelength_m[:, 0] * obs.phase_cyc[:, 0] - obs.wavelength_m[:, 1] * obs.phase_cyc[:, 1]
