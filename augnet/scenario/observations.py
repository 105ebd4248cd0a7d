"""The simulator's observation arrays in the forms the system consumes.

- `RoverObservations`: a train receiver's own measurements as the onboard unit's `EpochObs` (satellites x
  frequency slots). On a train the positioning core reads its receiver directly; no seam to encode.
- `StationObservations`: a station's epoch as the centre's `StationEpoch` (its two-frequency signal plan).
  The runner feeds the centre station RTCM bytes, not these; they serve the evaluation only (the master
  station's observations that a VRS for a truth point is synthesised from, to read the interpolated
  ionosphere out of it).

The signal mapping is worked out once per world; per epoch it is a few array gathers.
"""

from __future__ import annotations

import numpy as np

from augnet.centre.observations import DEFAULT_SIGNAL_PLAN, StationEpoch
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.onboard.observations import BAND_FREQ_HZ, SYSTEM_BANDS, EpochObs
from stations.world import EpochBlock, World

N_SLOTS = 2  # dual frequency, the onboard default and the centre's plan


def _gather(a: np.ndarray, cols: np.ndarray, fill):
    """a (N, K) -> (N, F) with column cols[n, f] (fill where -1)."""
    out = np.take_along_axis(a, np.maximum(cols, 0), axis=1)
    return np.where(cols >= 0, out, fill)


class RoverObservations:
    def __init__(self, world: World, n_slots: int = N_SLOTS):
        self.world = world
        N = len(world.sats)
        self.cols = np.full((N, n_slots), -1)
        self.wavelength_m = np.full((N, n_slots), np.nan)
        self.signal = np.full((N, n_slots), "", dtype="<U3")
        for j, sat in enumerate(world.sats):
            bands = SYSTEM_BANDS.get(sat[0], ())
            for k, code in enumerate(world.codes[j]):
                if not code or code[0] not in bands:
                    continue
                f = bands.index(code[0])
                if f < n_slots and self.cols[j, f] < 0:
                    self.cols[j, f] = k
                    self.wavelength_m[j, f] = SPEED_OF_LIGHT_M_S / BAND_FREQ_HZ[(sat[0], code[0])]
                    self.signal[j, f] = code
        self.sats = np.array(world.sats, dtype="<U3")

    def epoch(self, blk: EpochBlock, e: int, r: int) -> EpochObs:
        """Receiver r's observations at epoch e of the block (satellites it tracked, in the world's order)."""
        tracked = blk.observed[e, r].any(axis=1)
        c = self.cols[tracked]
        lli = _gather(blk.lli[e, r][tracked].astype(np.int16), c, 0)
        return EpochObs(float(blk.t_gpst[e]), self.sats[tracked],
                        _gather(blk.pseudorange_m[e, r][tracked], c, np.nan),
                        _gather(blk.phase_cyc[e, r][tracked], c, np.nan),
                        _gather(blk.doppler_hz[e, r][tracked], c, np.nan),
                        _gather(blk.cnr_dbhz[e, r][tracked], c, np.nan), lli,
                        self.wavelength_m[tracked], self.signal[tracked])


class StationObservations:
    def __init__(self, world: World, plan=DEFAULT_SIGNAL_PLAN):
        self.world = world
        N = len(world.sats)
        self.cols = np.full((N, 2), -1)
        for j, sat in enumerate(world.sats):
            codes = list(world.codes[j])
            for f, candidates in enumerate(plan.get(sat[0], ((), ()))):
                for rc in candidates:
                    if rc in codes:
                        self.cols[j, f] = codes.index(rc)
                        break
        self.freq_hz = _gather(world.freq_hz, self.cols, np.nan)
        self.codes = _gather(world.codes, self.cols, "")
        self.sats = np.array(world.sats, dtype="<U3")

    def epoch(self, blk: EpochBlock, e: int, r: int) -> StationEpoch | None:
        tracked = blk.observed[e, r].any(axis=1) & (self.cols[:, 0] >= 0)
        if not tracked.any():
            return None
        c = self.cols[tracked]
        return StationEpoch(self.world.receivers[r].id, float(blk.t_gpst[e]), self.sats[tracked],
                            _gather(blk.pseudorange_m[e, r][tracked], c, np.nan),
                            _gather(blk.phase_cyc[e, r][tracked], c, np.nan),
                            _gather(blk.lli[e, r][tracked], c, 0).astype(np.int8),
                            _gather(blk.cnr_dbhz[e, r][tracked], c, np.nan),
                            self.freq_hz[tracked], self.codes[tracked])
