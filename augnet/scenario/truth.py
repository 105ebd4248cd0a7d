"""The simulator's truth, as the scenario runner compares against it.

Everything here reads the world's truth (`stations.world.EpochBlock`'s truth arrays, receiver positions,
the track geometry) and nothing here is ever handed to the centre or the onboard unit: the runner feeds
those only bytes and observations, and compares their outputs with these functions afterwards.
"""

from __future__ import annotations

import numpy as np

from stations.ionosphere import delay_m
from stations.world import World

FREQ_MATCH_HZ = 1.0  # two carriers within this are the same signal band


class TruthIndex:
    """Lookups from the names the system uses (satellite ids, frequencies, receiver ids) into the world's
    truth arrays."""

    def __init__(self, world: World):
        self.world = world
        self.sat_col = {s: j for j, s in enumerate(world.sats)}
        self.rx_row = {r.id: i for i, r in enumerate(world.receivers)}

    def sat_cols(self, sats) -> np.ndarray:
        return np.array([self.sat_col.get(str(s), -1) for s in sats], dtype=int)

    def signal_cols(self, cols: np.ndarray, freq_hz: np.ndarray) -> np.ndarray:
        """(S, F) index of the world's signal column carrying each frequency (-1 where none)."""
        wf = self.world.freq_hz[np.maximum(cols, 0)]  # (S, K)
        match = np.abs(wf[:, None, :] - np.asarray(freq_hz, float)[:, :, None]) < FREQ_MATCH_HZ  # (S, F, K)
        k = np.argmax(match, axis=2)
        return np.where(match.any(axis=2) & (cols >= 0)[:, None], k, -1)

    def dd_ambiguity(self, ambiguity_cyc: np.ndarray, rx_a: str, rx_b: str, sats, refs: dict[str, str],
                     freq_hz: np.ndarray) -> np.ndarray:
        """Truth DD integer ambiguities (b - a, satellite - its system's reference) [cycles], (S, F).

        `ambiguity_cyc`: one epoch of `EpochBlock.ambiguity_cyc` (R, N, K); NaN where either receiver did
        not track the signal."""
        a, b = self.rx_row[rx_a], self.rx_row[rx_b]
        sats = np.asarray(sats).astype(str)
        cols = self.sat_cols(sats)
        ref_cols = self.sat_cols([refs.get(s[0], "") for s in sats])
        k = self.signal_cols(cols, freq_hz)
        k_ref = self.signal_cols(ref_cols, freq_hz)
        sd = ambiguity_cyc[b] - ambiguity_cyc[a]  # (N, K)
        ok = (cols >= 0)[:, None] & (ref_cols >= 0)[:, None] & (k >= 0) & (k_ref >= 0)
        own = sd[np.maximum(cols, 0)[:, None], np.maximum(k, 0)]
        ref = sd[np.maximum(ref_cols, 0)[:, None], np.maximum(k_ref, 0)]
        return np.where(ok, own - ref, np.nan)

    def iono_f1_m(self, stec_tecu: np.ndarray, rx: str, sats, f1_hz: np.ndarray) -> np.ndarray:
        """Truth slant ionosphere delay on each satellite's first frequency [m] at a receiver, one epoch.
        `stec_tecu`: one epoch of `EpochBlock.stec_tecu` (R, N)."""
        cols = self.sat_cols(sats)
        v = delay_m(stec_tecu[self.rx_row[rx], np.maximum(cols, 0)], f1_hz)
        return np.where(cols >= 0, v, np.nan)


def passages(along_m: np.ndarray, t_s: np.ndarray, marks_m: np.ndarray) -> np.ndarray:
    """Times [s] at which a path with along-track positions `along_m` (at times `t_s`, monotonic motion
    assumed between epochs) passes each mark; NaN for marks it never passes. Vectorised over marks."""
    a0, a1 = along_m[:-1], along_m[1:]
    m = np.asarray(marks_m, float)[:, None]
    inside = ((a1 > a0) & (a0 < m) & (m <= a1)) | ((a1 < a0) & (a1 <= m) & (m < a0))  # (M, E-1)
    first = np.argmax(inside, axis=1)
    hit = inside.any(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = (m[:, 0] - a0[first]) / (a1[first] - a0[first])
    return np.where(hit, t_s[first] + frac * (t_s[first + 1] - t_s[first]), np.nan)
