"""The first-order ionosphere on the single-layer (thin-shell) model: the constants and the mapping function
the centre's network engine and the onboard core share."""

from __future__ import annotations

import numpy as np

# First-order ionospheric group delay I [m] = 40.3 m^3/s^2 * TEC [el/m^2] / f^2 (Hofmann-Wellenhof et al., GNSS,
# 2008, 5.3.2); one TECU is 1e16 el/m^2, so I [m] = IONO_K_M3_S2 * TEC [TECU] / f^2
IONO_K_M3_S2 = 40.3e16
# Thin ionospheric shell (Klobuchar's): its height [m] over a sphere of the Earth's mean radius [m]
SHELL_HEIGHT_M = 350_000.0
EARTH_MEAN_RADIUS_M = 6_371_000.0


def thin_shell_mapping(el_rad, shell_height_m: float = SHELL_HEIGHT_M) -> np.ndarray:
    """Slant over vertical ionospheric delay at elevation `el_rad` for a shell at `shell_height_m`."""
    s = EARTH_MEAN_RADIUS_M / (EARTH_MEAN_RADIUS_M + shell_height_m) * np.cos(np.asarray(el_rad, dtype=float))
    return 1.0 / np.sqrt(1.0 - s * s)
