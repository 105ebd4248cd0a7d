"""Linear combinations of dual-frequency observables and the cycle-slip tests built on them.

All functions take numpy arrays (any shape, broadcasting: satellites, epochs, stations) with code in metres
and phase in cycles, and the two carrier frequencies in Hz. Formulas: Teunissen & Montenbruck (eds.),
Springer Handbook of GNSS (2017), ch. 20; Melbourne (1985) and Wuebbena (1985) for the wide-lane
combination; Blewitt (1990) for the slip tests.
"""

from __future__ import annotations

import numpy as np

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S

# Cycle-slip thresholds. A wide-lane slip of one cycle is 86 cm (GPS L1/L2); Melbourne-Wuebbena noise at
# 1 Hz is ~0.2-0.3 cycles for geodetic code, so 4 sigma of the running scatter with a floor of 1 cycle.
MW_SLIP_FLOOR_CYCLES = 1.0
MW_SLIP_SIGMAS = 4.0
# Geometry-free phase changes by the ionosphere rate only (a few mm/s in a quiet one at 1 Hz); a 1/1 slip on
# L1/L2 moves it by 5.4 cm. 5 cm per second, scaled with the interval, as RTKLIB's default thresslip.
GF_SLIP_M_PER_S = 0.05
GF_SLIP_MIN_M = 0.05


def wavelength(f_hz):
    return SPEED_OF_LIGHT_M_S / np.asarray(f_hz, dtype=float)


def widelane_wavelength(f1_hz, f2_hz):
    return SPEED_OF_LIGHT_M_S / (np.asarray(f1_hz, float) - np.asarray(f2_hz, float))


def narrowlane_wavelength(f1_hz, f2_hz):
    return SPEED_OF_LIGHT_M_S / (np.asarray(f1_hz, float) + np.asarray(f2_hz, float))


def iono_factor(f1_hz, f2_hz):
    """gamma = (f1/f2)^2: first-order ionospheric delay on f2 relative to f1."""
    return (np.asarray(f1_hz, float) / np.asarray(f2_hz, float)) ** 2


def geometry_free_phase_m(L1_cyc, L2_cyc, f1_hz, f2_hz):
    """L1 - L2 in metres: ionosphere (times gamma - 1) plus ambiguities, no geometry, no clocks."""
    return L1_cyc * wavelength(f1_hz) - L2_cyc * wavelength(f2_hz)


def geometry_free_code_m(P1_m, P2_m):
    """P2 - P1: ionosphere (gamma - 1) I1 plus code biases and noise."""
    return np.asarray(P2_m, float) - np.asarray(P1_m, float)


def ionosphere_free(x1, x2, f1_hz, f2_hz):
    """Ionosphere-free combination of two observables in metres."""
    g = iono_factor(f1_hz, f2_hz)
    return (g * np.asarray(x1, float) - np.asarray(x2, float)) / (g - 1.0)


def ionosphere_free_phase_m(L1_cyc, L2_cyc, f1_hz, f2_hz):
    return ionosphere_free(L1_cyc * wavelength(f1_hz), L2_cyc * wavelength(f2_hz), f1_hz, f2_hz)


def melbourne_wubbena_cycles(L1_cyc, L2_cyc, P1_m, P2_m, f1_hz, f2_hz):
    """Wide-lane phase minus narrow-lane code, in wide-lane cycles: N1 - N2 plus biases and code noise.

    Free of geometry, clocks, troposphere and first-order ionosphere, so averaging it over an arc gives the
    wide-lane ambiguity (its double difference is an integer).
    """
    f1 = np.asarray(f1_hz, float)
    f2 = np.asarray(f2_hz, float)
    lw = widelane_wavelength(f1, f2)
    phase_wl_m = (f1 * L1_cyc * wavelength(f1) - f2 * L2_cyc * wavelength(f2)) / (f1 - f2)
    code_nl_m = (f1 * np.asarray(P1_m, float) + f2 * np.asarray(P2_m, float)) / (f1 + f2)
    return (phase_wl_m - code_nl_m) / lw


def ionosphere_on_f1_m(L1_cyc, L2_cyc, f1_hz, f2_hz, ambiguity_term_m=0.0):
    """Slant ionospheric delay on f1 [m] from the geometry-free phase, once its ambiguity term is known.

    Phase advances by I on each frequency, I2 = gamma I1, so
    L1 - L2 [m] = (gamma - 1) I1 + (lambda1 N1 - lambda2 N2).
    """
    g = iono_factor(f1_hz, f2_hz)
    return (geometry_free_phase_m(L1_cyc, L2_cyc, f1_hz, f2_hz) - ambiguity_term_m) / (g - 1.0)


def slip_geometry_free(gf_prev_m, gf_now_m, dt_s):
    """True where the geometry-free phase jumped more than the ionosphere can move in dt_s."""
    limit = np.maximum(GF_SLIP_MIN_M, GF_SLIP_M_PER_S * np.asarray(dt_s, float))
    return np.abs(np.asarray(gf_now_m, float) - np.asarray(gf_prev_m, float)) > limit


class MelbourneWubbenaTracker:
    """Running mean and scatter of the Melbourne-Wuebbena combination per arc, with slip detection.

    One instance per receiver (or per baseline); arrays are indexed by an integer channel key (satellite x
    frequency pair) chosen by the caller. Vectorised: `update` takes arrays of keys and values.
    """

    def __init__(self, n_channels: int):
        self.count = np.zeros(n_channels, dtype=np.int64)
        self.mean = np.zeros(n_channels)
        self.m2 = np.zeros(n_channels)  # Welford's sum of squared deviations

    def reset(self, keys) -> None:
        self.count[keys] = 0
        self.mean[keys] = 0.0
        self.m2[keys] = 0.0

    def sigma(self, keys) -> np.ndarray:
        n = self.count[keys]
        return np.sqrt(np.where(n > 1, self.m2[keys] / np.maximum(n - 1, 1), np.inf))

    def update(self, keys, mw_cycles, lli_slip=None) -> np.ndarray:
        """Add one epoch; returns a boolean array: slip detected (the arc is restarted at this value)."""
        keys = np.asarray(keys)
        mw = np.asarray(mw_cycles, float)
        ok = np.isfinite(mw)
        n = self.count[keys]
        dev = mw - self.mean[keys]
        thresh = np.maximum(MW_SLIP_FLOOR_CYCLES, MW_SLIP_SIGMAS * self.sigma(keys))
        slip = ok & (n > 0) & (np.abs(dev) > thresh)
        if lli_slip is not None:
            slip |= ok & np.asarray(lli_slip, bool) & (n > 0)
        restart = slip | (n == 0)
        k_new = keys[ok & restart]
        self.count[k_new] = 1
        self.mean[k_new] = mw[ok & restart]
        self.m2[k_new] = 0.0
        cont = ok & ~restart
        k = keys[cont]
        n1 = self.count[k] + 1
        d = mw[cont] - self.mean[k]
        self.mean[k] += d / n1
        self.m2[k] += d * (mw[cont] - self.mean[k])
        self.count[k] = n1
        return slip
