"""A baseline's DD phase residuals once the integers are known: the corrections the network interpolates.

With N1 and N2 fixed, the DD phase residuals on f1 and f2 split into the dispersive part (DD slant ionosphere on
f1) and the non-dispersive part (DD troposphere beyond the model plus orbit error), each then smoothed over time
while the satellite's reference and integers stay.
"""

from __future__ import annotations

import numpy as np

from augnet.centre.baseline_integers import BaselineIntegers


def dd_integers(sats: np.ndarray, ref_of: np.ndarray, fixed: BaselineIntegers) -> np.ndarray:
    """(S, 2) DD integers N1, N2 against the reference: NaN where not both fixed, 0 for references."""
    dd_n = np.full((len(sats), 2), np.nan)
    for k, s in enumerate(sats):
        if s == ref_of[k]:
            dd_n[k] = 0.0
        elif fixed.both(s):
            dd_n[k] = (fixed.n1[s], fixed.n2[s])
    return dd_n


def dispersive_split(phase_m: np.ndarray, ref_k: np.ndarray, wavelength_m: np.ndarray, dd_n: np.ndarray,
                     gamma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The DD phase residuals (SD phase minus geometry and model [m], minus the integers) as (DD ionosphere on
    f1, DD non-dispersive residual) [m]; NaN where the integers are unknown."""
    r = phase_m - phase_m[ref_k] - wavelength_m * dd_n
    return (r[:, 0] - r[:, 1]) / (gamma - 1.0), (gamma * r[:, 0] - r[:, 1]) / (gamma - 1.0)


class ResidualSmoother:
    """Exponential smoothing of each satellite's DD residuals while its reference and integers stay (a gap longer
    than `max_gap_s` starts it again): the geometry-free split carries ~2x the phase noise while the DD
    ionosphere moves by millimetres per minute over a network baseline."""

    def __init__(self, tau_s: float, max_gap_s: float):
        self.tau_s = tau_s
        self.max_gap_s = max_gap_s
        self._last: dict[str, tuple] = {}  # sat -> ((ref, N1, N2), t, iono, trop)

    def smooth(self, t: float, sats, ref_of, dd_n, fixed, iono, trop) -> tuple[np.ndarray, np.ndarray]:
        tau = self.tau_s
        out_i, out_t = iono.copy(), trop.copy()
        for k, s in enumerate(sats):
            s = str(s)
            if not fixed[k] or s == ref_of[k] or tau <= 0:
                self._last.pop(s, None)
                continue
            key = (ref_of[k], float(dd_n[k, 0]), float(dd_n[k, 1]))
            prev = self._last.get(s)
            if prev is None or prev[0] != key or t - prev[1] > self.max_gap_s:
                si, st = iono[k], trop[k]
            else:
                a = min(1.0, (t - prev[1]) / tau)
                si = prev[2] + a * (iono[k] - prev[2])
                st = prev[3] + a * (trop[k] - prev[3])
            self._last[s] = (key, t, si, st)
            out_i[k], out_t[k] = si, st
        return out_i, out_t
