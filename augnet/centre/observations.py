"""Per-station epochs of dual-frequency observations, the form the network engine works on.

A `StationEpoch` holds, for the satellites a station tracked at one epoch, code [m] and carrier phase
[cycles] on two frequencies per system (chosen by a signal plan), loss-of-lock flags and C/N0. Builders
make it from RINEX (`ObsData`) and from decoded RTCM MSM observables.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from augnet.gnss.signals import UnknownSignal, by_rinex

# Two frequencies per system, each with the RINEX codes to try in order. The first frequency carries the
# broadcast clock's reference signal (GPS L1 C/A, Galileo E1, BDS B1I); the second is the one commonly
# tracked beside it by geodetic receivers (GPS L2 P(Y)/L2C, Galileo E5a, BDS B3I).
DEFAULT_SIGNAL_PLAN: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "G": (("1C",), ("2W", "2L", "2X", "2S", "2C")),
    "E": (("1C", "1X"), ("5Q", "5X", "5I")),
    "C": (("2I", "2X"), ("6I", "6X")),
}


@dataclass
class StationEpoch:
    station: str
    t_gpst: float  # epoch time tag (receiver time, GPST scale)
    sats: np.ndarray  # (S,) '<U3' satellite ids, e.g. 'G05'
    code_m: np.ndarray  # (S, 2) pseudorange [m], NaN missing
    phase_cyc: np.ndarray  # (S, 2) carrier phase [cycles], NaN missing
    lli: np.ndarray  # (S, 2) int8: bit 0 = loss of lock since the previous epoch
    cnr_dbhz: np.ndarray  # (S, 2)
    freq_hz: np.ndarray  # (S, 2)
    codes: np.ndarray  # (S, 2) '<U2' RINEX codes used (e.g. '1C', '2W')

    @property
    def systems(self) -> np.ndarray:
        return np.array([s[0] for s in self.sats])

    def dual_frequency(self) -> np.ndarray:
        """Satellites with code and phase on both frequencies."""
        return np.isfinite(self.code_m).all(axis=1) & np.isfinite(self.phase_cyc).all(axis=1)

    def subset(self, mask) -> StationEpoch:
        m = np.asarray(mask)
        return StationEpoch(self.station, self.t_gpst, self.sats[m], self.code_m[m], self.phase_cyc[m],
                            self.lli[m], self.cnr_dbhz[m], self.freq_hz[m], self.codes[m])


def from_obsdata(obs, epoch: int, station: str,
                 plan: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] | None = None) -> StationEpoch:
    """One epoch of a RINEX observation file (`augnet.gnss.rinex.ObsData`) in the plan's signals."""
    plan = DEFAULT_SIGNAL_PLAN if plan is None else plan
    sats = np.asarray(obs.sats)
    n = len(sats)
    code = np.full((n, 2), np.nan)
    phase = np.full((n, 2), np.nan)
    lli = np.zeros((n, 2), np.int8)
    cnr = np.full((n, 2), np.nan)
    freq = np.full((n, 2), np.nan)
    used = np.full((n, 2), "", dtype="<U2")
    systems = np.array([s[0] for s in sats])
    for system, slots in plan.items():
        cols = np.flatnonzero(systems == system)
        if cols.size == 0:
            continue
        for k, candidates in enumerate(slots):
            for rc in candidates:
                c_arr = obs.obs.get("C" + rc)
                l_arr = obs.obs.get("L" + rc)
                if c_arr is None or l_arr is None:
                    continue
                try:
                    f = by_rinex(system, rc).freq_hz
                except UnknownSignal:
                    continue
                c = c_arr[epoch, cols]
                ph = l_arr[epoch, cols]
                take = np.isnan(code[cols, k]) & np.isfinite(c) & np.isfinite(ph)
                rows = cols[take]
                code[rows, k] = c[take]
                phase[rows, k] = ph[take]
                lli[rows, k] = obs.lli["L" + rc][epoch, cols][take]
                s_arr = obs.obs.get("S" + rc)
                if s_arr is not None:
                    cnr[rows, k] = s_arr[epoch, cols][take]
                freq[rows, k] = f
                used[rows, k] = rc
    keep = np.isfinite(code).any(axis=1) | np.isfinite(phase).any(axis=1)
    return StationEpoch(station, float(obs.times[epoch]), sats[keep], code[keep], phase[keep], lli[keep],
                        cnr[keep], freq[keep], used[keep])
