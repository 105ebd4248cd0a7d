"""The rover's ionosphere-weighted model: when the single-difference (rover - base) ionosphere is
estimated, and its prior, random walk and lifetime.

The SD ionospheric delay on each satellite's first frequency is a state with a prior sigma of
sigma0 * M(el), M the thin-shell mapping function; phase sees -mu I and code +mu I, mu = (f1 / f)^2.
sigma0 is the user's figure, a network VRS's interpolation residual (`RtkOptions.vrs_iono_sigma_m`), or
grows with the distance to a physical base (IONO_SIGMA_PER_M).
"""

from __future__ import annotations

import numpy as np

from augnet.gnss.ionosphere import thin_shell_mapping

# sigma0 of the SD vertical ionosphere per metre of baseline to a physical base [m/m]: 2 mm per km.
# Quiet mid-latitude DD ionosphere is 1-4 ppm (../shared/design/network-rtk.md); RTKLIB's default is
# 3 mm per km (0.03 m per 10 km).  Choice: docs/decisions/0081-rtk-ionosphere-prior.md.
IONO_SIGMA_PER_M = 2.0e-6
# Below this sigma0 [m] (baselines under ~7 km) the DD ionosphere is left out of the model: the
# short-baseline model is then exact to millimetres and fixes from the first epoch.
IONO_ESTIMATE_MIN_SIGMA_M = 0.015
# Random walk of the SD ionosphere as a fraction of sigma0 per sqrt(s) [1/sqrt(s)]: a 2 cm VRS residual
# drifts by ~1 cm over 100 s as the satellites' pierce points move.
IONO_PROCESS_FRACTION_PER_SQRT_S = 0.03
# An SD ionosphere state not observed for longer than this [s] is dropped.  It is an atmospheric
# quantity, not a tracking one: across a shorter outage (an overbridge, a tunnel, a cutting) it is kept
# with the uncertainty its random walk has gathered (23 % of sigma0 after a minute), and a satellite
# re-acquired with new ambiguities is fixed against it.
MAX_IONO_OUTAGE_S = 60.0


def iono_sigma0(baseline_m: float, base_is_vrs: bool, user_sigma_m: float | None, vrs_sigma_m: float) -> float:
    """Prior sigma [m] of the SD vertical ionospheric delay on the first frequency: the user's figure,
    a network VRS's residual, or growing with the baseline."""
    if user_sigma_m is not None:
        return float(user_sigma_m)
    if base_is_vrs:
        return float(vrs_sigma_m)
    return IONO_SIGMA_PER_M * baseline_m


def estimate_ionosphere(mode: str, sigma0: float) -> bool:
    """Whether the SD ionosphere belongs in the model: 'estimate' always, 'auto' when sigma0 is large
    enough to matter, 'off' never."""
    return mode == "estimate" or (mode == "auto" and sigma0 >= IONO_ESTIMATE_MIN_SIGMA_M)


def mapping(el_rad: np.ndarray) -> np.ndarray:
    """Slant over vertical ionosphere at elevations el_rad (the thin-shell model)."""
    return thin_shell_mapping(el_rad)


def prior_variance(sigma0: float, slant_mapping):
    """Prior variance [m^2] of an SD slant ionosphere whose mapping function value is slant_mapping."""
    return (sigma0 * slant_mapping) ** 2


def process_variance(sigma0: float, dt_s: float) -> float:
    """Random-walk variance [m^2] an SD ionosphere state gathers over dt_s."""
    return (IONO_PROCESS_FRACTION_PER_SQRT_S * sigma0) ** 2 * dt_s
