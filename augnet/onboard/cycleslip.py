"""Cycle-slip detection on one receiver's carrier phases, epoch by epoch.

Three independent tests, each cheap and each catching what the others miss:
  - the receiver's loss-of-lock indicator (RINEX LLI bit 0, RTCM MSM lock-time reset);
  - a jump in the geometry-free combination lambda1 phi1 - lambda2 phi2 (dual frequency):
    geometry, clocks and troposphere cancel, the ionosphere changes by millimetres per second,
    so a jump of several centimetres is a slip on one of the two frequencies;
  - phase against Doppler: the phase change over the interval must match the integrated Doppler;
    the receiver-clock part is common to all satellites, so the median discrepancy is removed.
A satellite not seen for longer than a gap limit is treated as slipped (its ambiguity is re-found).

A jump that every slot's Doppler test sees and the geometry-free test does not (no loss-of-lock flag) is
non-dispersive, the same in metres on both frequencies: a jump of the range itself (a satellite clock step,
an orbit fault), not of the ambiguities (a slip pair with n1 lambda1 = n2 lambda2 needs 77/60 cycles on GPS
L1/L2, 14.7 m). `range_jump` says which satellites of the last epoch jumped so (issue 15, decision 0253).
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
# ... of a base: a network reference station records at 30 s (IGS, EUREF, catnet), so its arc continues
# across one interval (its GF test then allows 2.5 cm + 30 s x 5 mm/s); a missed epoch (60 s) breaks it.
# (10 s reset every base ambiguity at each new 30 s epoch: docs/decisions/0162.)
BASE_MAX_ARC_GAP_S = 35.0


class SlipDetector:
    """Keeps the previous epoch per satellite and flags slips in the next one.

    The previous epoch lives in arrays with one row per satellite ever seen (a dict maps the id to its
    row), so an epoch is a handful of array operations whatever the number of satellites."""

    def __init__(self, max_gap_s: float = MAX_ARC_GAP_S, gf_threshold_m: float = GF_SLIP_THRESHOLD_M,
                 gf_drift_m_s: float = GF_DRIFT_M_S):
        self.max_gap_s = max_gap_s
        self.gf_threshold_m = gf_threshold_m
        self.gf_drift_m_s = gf_drift_m_s
        self.range_jump = np.zeros(0, bool)  # (N,) per satellite of the last epoch detected (module docstring)
        self.reset()

    def reset(self) -> None:
        self._row: dict[str, int] = {}
        self._nf = 0
        self._alloc(0, 0)

    def _alloc(self, rows: int, nf: int) -> None:
        self._has = np.zeros(rows, bool)  # a previous epoch is stored
        self._t = np.full(rows, np.nan)
        self._ph = np.full((rows, nf), np.nan)
        self._dop = np.full((rows, nf), np.nan)
        self._gf = np.full(rows, np.nan)

    def _rows(self, sats) -> np.ndarray:
        out = np.empty(len(sats), dtype=int)
        for j, sat in enumerate(sats):
            r = self._row.get(sat)
            if r is None:
                r = self._row[sat] = len(self._row)
            out[j] = r
        if len(self._row) > len(self._has):
            old = (self._has, self._t, self._ph, self._dop, self._gf)
            self._alloc(max(2 * len(self._has), len(self._row), 16), self._nf)
            n = len(old[0])
            self._has[:n], self._t[:n], self._ph[:n], self._dop[:n], self._gf[:n] = old
        return out

    def detect(self, obs: EpochObs) -> np.ndarray:
        """(N, F) bool: True where the phase of that satellite and slot must not be trusted to continue."""
        n, nf = obs.phase_cyc.shape
        if nf != self._nf:  # a different number of slots: nothing stored is comparable
            self._row.clear()
            self._nf = nf
            self._alloc(0, nf)
        phase = obs.phase_cyc
        has_phase = np.isfinite(phase)
        slip = ((obs.lli & LLI_SLIP) != 0) & has_phase
        gf = _geometry_free(obs)
        rows = self._rows(obs.sats.tolist())
        seen = self._has[rows]
        t0 = self._t[rows]
        ph0 = self._ph[rows]
        dt = obs.time - t0
        gap = seen & ((dt < 0.0) | (dt > self.max_gap_s))
        cont = seen & ~gap
        slip |= gap[:, None] & has_phase
        prev_t = np.where(cont, t0, np.nan)
        prev_gf = np.where(cont, self._gf[rows], np.nan)
        # RINEX sign convention: phase grows with range, Doppler is positive when approaching
        dop = 0.5 * (obs.doppler_hz + self._dop[rows])
        dop_disc = np.where(cont[:, None], (phase - ph0) + dop * dt[:, None], np.nan)
        # a phase that vanished and returned within the gap is not continuous either
        slip |= cont[:, None] & has_phase & ~np.isfinite(ph0)
        dt_all = np.nan_to_num(obs.time - prev_t, nan=0.0)
        jump = np.abs(gf - prev_gf)
        gf_slip = jump > self.gf_threshold_m + self.gf_drift_m_s * dt_all
        slip |= gf_slip[:, None] & has_phase
        lim = DOPPLER_SLIP_THRESHOLD_CYC + DOPPLER_DRIFT_CYC_S * dt_all
        lli = ((obs.lli & LLI_SLIP) != 0).any(axis=1)
        dop_flag = np.zeros((n, nf), bool)
        for f in range(nf):
            col = dop_disc[:, f]
            ok = np.isfinite(col)
            if np.count_nonzero(ok) >= 2:
                common = np.median(col[ok])
                dop_flag[:, f] = ok & (np.abs(col - common) > lim)
        slip |= dop_flag
        # every slot's phase ran away from its Doppler by the same metres (GF steady): the range jumped
        self.range_jump = (cont & ~lli & np.isfinite(jump) & ~gf_slip & (has_phase.sum(axis=1) >= 2)
                           & np.all(dop_flag | ~has_phase, axis=1))
        upd = rows[has_phase.any(axis=1)]
        keep = has_phase.any(axis=1)
        self._has[upd] = True
        self._t[upd] = obs.time
        self._ph[upd] = phase[keep]
        self._dop[upd] = obs.doppler_hz[keep]
        self._gf[upd] = gf[keep]
        return slip


def _geometry_free(obs: EpochObs) -> np.ndarray:
    """lambda1 phi1 - lambda2 phi2 [m] per satellite (NaN without two frequencies)."""
    if obs.phase_cyc.shape[1] < 2:
        return np.full(len(obs.sats), np.nan)
    return obs.wavelength_m[:, 0] * obs.phase_cyc[:, 0] - obs.wavelength_m[:, 1] * obs.phase_cyc[:, 1]
