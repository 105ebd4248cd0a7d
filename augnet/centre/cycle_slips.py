"""Cycle slips on a baseline: per satellite and station, loss-of-lock flags, jumps of the geometry-free phase
against its linear prediction, jumps of the Melbourne-Wuebbena combination against its arc mean, and gaps.

A slip restarts the satellite's ambiguities (its ionosphere state carries on); a gap longer than `max_gap_s`, or a
satellite the filter does not carry, starts a new arc (everything about the satellite starts afresh).

Real reference receivers at 30 s need all three tests (catnet-2010-077, decision 0150): Trimble NetRS phases
are re-aligned to the code now and then without a loss-of-lock flag (2-25 times a station-day, a jump of
kilometres in code minus phase on both frequencies, but well under a metre in the geometry-free phase, which a
30 s rate limit lets through); the Melbourne-Wuebbena test sees those and every wide-lane slip, the predicted
geometry-free phase the slips that keep the wide lane (e.g. 9/7, 1/0 cycles on L1/L2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.observations import StationEpoch
from augnet.gnss import combinations as comb

# Geometry-free phase against its linear prediction from the arc's last two epochs: the second difference at
# 30 s is under 4 cm in 99.9 % of real epochs (catnet-2010-077, three stations, a day); a 1/1 slip moves it by
# 5.4 cm, a 1/0 slip by 19 cm. The limit grows with the square of the interval (the ionosphere's acceleration).
GF_PREDICTED_SLIP_M = 0.05
GF_PREDICTED_SLIP_M_AT_30S = 0.03  # added at a 30 s interval, scaled with (dt / 30 s)^2
GF_PREDICTION_REF_S = 30.0
# ... and at least this many times the arc's own RMS prediction error (receivers noisier than geodetic ones, or
# multipath at low elevation); the RMS counts from GF_MIN_RESIDUALS residuals, exponentially over GF_RMS_EPOCHS.
GF_SLIP_SIGMAS = 5.0
GF_MIN_RESIDUALS = 3
GF_RMS_EPOCHS = 30.0
# Melbourne-Wuebbena against its running arc mean: 5 sigma of the arc's scatter, at least 2 wide-lane cycles
# (NetRS C1/P2 at 30 s scatter ~0.25 cycles with multipath tails to ~2.5; looser than combinations.py's 1 Hz
# tracker, whose 1-cycle floor such 30 s tails would trip).
MW_ARC_SLIP_SIGMAS = 5.0
MW_ARC_SLIP_FLOOR_CYCLES = 2.0
MW_MIN_EPOCHS = 3  # the arc's scatter is not known before this many epochs (the floor alone applies)


@dataclass
class _Track:
    """One station's view of a satellite's arc."""

    t: tuple[float, float] = (-math.inf, -math.inf)  # the last two epochs [s]
    gf: tuple[float, float] = (math.nan, math.nan)  # geometry-free phase there [m]
    mw_n: int = 0
    mw_mean: float = 0.0  # [wide-lane cycles]
    mw_m2: float = 0.0
    gf_n: int = 0  # geometry-free prediction residuals seen
    gf_ms: float = 0.0  # their running mean square [m^2]
    _gf_residual: float = math.nan  # this epoch's, kept by `slipped` for `add`

    def slipped(self, t: float, gf: float, mw: float) -> bool:
        """The tests against this arc's history (no update)."""
        dt = t - self.t[1]
        self._gf_residual = math.nan
        if math.isfinite(self.gf[1]) and math.isfinite(gf):
            if math.isfinite(self.gf[0]) and self.t[1] > self.t[0]:
                pred = self.gf[1] + (self.gf[1] - self.gf[0]) * dt / (self.t[1] - self.t[0])
                limit = GF_PREDICTED_SLIP_M + GF_PREDICTED_SLIP_M_AT_30S * (dt / GF_PREDICTION_REF_S) ** 2
                if self.gf_n >= GF_MIN_RESIDUALS:
                    limit = max(limit, GF_SLIP_SIGMAS * math.sqrt(self.gf_ms))
                self._gf_residual = gf - pred
                if abs(gf - pred) > limit:
                    return True
            elif comb.slip_geometry_free(self.gf[1], gf, dt):
                return True
        if self.mw_n > 0 and math.isfinite(mw):
            sigma = math.sqrt(self.mw_m2 / (self.mw_n - 1)) if self.mw_n >= MW_MIN_EPOCHS else 0.0
            if abs(mw - self.mw_mean) > max(MW_ARC_SLIP_FLOOR_CYCLES, MW_ARC_SLIP_SIGMAS * sigma):
                return True
        return False

    def add(self, t: float, gf: float, mw: float) -> None:
        self.t = (self.t[1], t)
        self.gf = (self.gf[1], gf)
        if math.isfinite(self._gf_residual):
            self.gf_n += 1
            w = max(1.0 / self.gf_n, 1.0 / GF_RMS_EPOCHS)
            self.gf_ms += w * (self._gf_residual**2 - self.gf_ms)
        if math.isfinite(mw):
            self.mw_n += 1
            d = mw - self.mw_mean
            self.mw_mean += d / self.mw_n
            self.mw_m2 += d * (mw - self.mw_mean)


@dataclass
class _Arc:
    t_last: float = -math.inf
    a: _Track = field(default_factory=_Track)
    b: _Track = field(default_factory=_Track)


@dataclass(frozen=True)
class Slips:
    slipped: set[str]  # ambiguities restart
    new_arc: set[str]  # the satellite starts afresh
    sd_geometry_free_m: np.ndarray  # (S,) this epoch's SD (b - a) geometry-free phase [m]

    @property
    def restarted(self) -> set[str]:
        return self.slipped | self.new_arc


class CycleSlipDetector:
    def __init__(self, max_gap_s: float):
        self.max_gap_s = max_gap_s
        self._arcs: dict[str, _Arc] = {}

    def detect(self, t: float, a: StationEpoch, b: StationEpoch, freq_hz: np.ndarray, carried) -> Slips:
        """Slips and new arcs of the satellites of `a` (and `b`, the same ones); `carried`: satellites the filter
        has states for."""
        f = freq_hz
        gf_a = comb.geometry_free_phase_m(a.phase_cyc[:, 0], a.phase_cyc[:, 1], f[:, 0], f[:, 1])
        gf_b = comb.geometry_free_phase_m(b.phase_cyc[:, 0], b.phase_cyc[:, 1], f[:, 0], f[:, 1])
        mw_a = comb.melbourne_wubbena_cycles(a.phase_cyc[:, 0], a.phase_cyc[:, 1], a.code_m[:, 0], a.code_m[:, 1],
                                             f[:, 0], f[:, 1])
        mw_b = comb.melbourne_wubbena_cycles(b.phase_cyc[:, 0], b.phase_cyc[:, 1], b.code_m[:, 0], b.code_m[:, 1],
                                             f[:, 0], f[:, 1])
        lli = ((a.lli & 1).any(axis=1)) | ((b.lli & 1).any(axis=1))
        slipped: set[str] = set()
        new_arc: set[str] = set()
        sd_gf = gf_b - gf_a
        # the per-satellite tests on Python floats: the same IEEE arithmetic, without numpy's scalar overhead
        gf_a, gf_b, mw_a, mw_b, lli = gf_a.tolist(), gf_b.tolist(), mw_a.tolist(), mw_b.tolist(), lli.tolist()
        for k, s in enumerate(a.sats):
            s = str(s)
            arc = self._arcs.get(s)
            if arc is None or s not in carried or t - arc.t_last > self.max_gap_s:
                new_arc.add(s)
                self._arcs[s] = arc = _Arc()  # the previous arc is forgotten; this epoch starts the new one
            else:
                jump_a = arc.a.slipped(t, gf_a[k], mw_a[k])
                jump_b = arc.b.slipped(t, gf_b[k], mw_b[k])
                if lli[k] or jump_a or jump_b:
                    slipped.add(s)
                    # the slipped station's arc history restarts; the other's carries on
                    if lli[k] or jump_a:
                        arc.a = _Track()
                    if lli[k] or jump_b:
                        arc.b = _Track()
            arc.a.add(t, gf_a[k], mw_a[k])
            arc.b.add(t, gf_b[k], mw_b[k])
        return Slips(slipped, new_arc, sd_gf)

    def seen(self, sats, t: float) -> None:
        for s in sats:
            self._arcs[str(s)].t_last = t
