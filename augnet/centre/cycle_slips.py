"""Cycle slips on a baseline: per satellite, loss-of-lock flags at either station, jumps of either station's
geometry-free phase, and gaps.

A slip restarts the satellite's ambiguities (its ionosphere state carries on); a gap longer than `max_gap_s`, or a
satellite the filter does not carry, starts a new arc (everything about the satellite starts afresh).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.centre.observations import StationEpoch
from augnet.gnss import combinations as comb


@dataclass
class _Arc:
    t_last: float = -math.inf
    gf_a: float = math.nan  # geometry-free phase at station a at the last epoch [m]
    gf_b: float = math.nan


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
        lli = ((a.lli & 1).any(axis=1)) | ((b.lli & 1).any(axis=1))
        slipped: set[str] = set()
        new_arc: set[str] = set()
        for k, s in enumerate(a.sats):
            s = str(s)
            arc = self._arcs.get(s)
            if arc is None or s not in carried or t - arc.t_last > self.max_gap_s:
                new_arc.add(s)
            else:
                dt = t - arc.t_last
                if lli[k] or comb.slip_geometry_free(arc.gf_a, gf_a[k], dt) or \
                        comb.slip_geometry_free(arc.gf_b, gf_b[k], dt):
                    slipped.add(s)
            if arc is None:
                self._arcs[s] = arc = _Arc()
            arc.gf_a, arc.gf_b = gf_a[k], gf_b[k]
        return Slips(slipped, new_arc, gf_b - gf_a)

    def start_arc(self, sat: str) -> None:
        """A new arc forgets the satellite's previous one (its geometry-free phase included)."""
        self._arcs[sat] = _Arc()

    def seen(self, sats, t: float) -> None:
        for s in sats:
            self._arcs[str(s)].t_last = t
