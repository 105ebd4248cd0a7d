"""One epoch of a baseline's between-station single differences (SD, b minus a): the satellites both stations
track on the same two signals, above the mask, with the known geometry and the troposphere model taken out.

The station coordinates are surveyed, so g = rho - c*dts (satellite positions at transmission, Sagnac included,
satellite and receiver clocks) is right to the millimetre and the SD hold only ambiguities, atmosphere,
multipath and noise. Where a station's antenna is modelled (`SatelliteGeometry.antenna_m`), its observations
get the phase-centre correction first, so both refer to the antenna reference points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.centre.observations import StationEpoch
from augnet.centre.satellite_geometry import SatelliteGeometry
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S


@dataclass(frozen=True)
class SingleDifferences:
    sats: np.ndarray  # (S,)
    a: StationEpoch  # the two stations' observations of `sats`
    b: StationEpoch
    ga: SatelliteGeometry  # and their geometry
    gb: SatelliteGeometry
    freq_hz: np.ndarray  # (S, 2)
    wavelength_m: np.ndarray  # (S, 2)
    gamma: np.ndarray  # (S,) (f1 / f2)^2: the ionosphere on f2 over f1
    phase_m: np.ndarray  # (S, 2) SD phase minus geometry and troposphere model [m]
    code_m: np.ndarray  # (S, 2) SD code, the same [m]

    @property
    def el_min_rad(self) -> np.ndarray:
        """The lower of the two stations' elevations."""
        return np.minimum(self.ga.elevation_rad, self.gb.elevation_rad)

    def noise_shape(self) -> np.ndarray:
        """SD variance over s^2 for undifferenced sigma^2(el) = s^2 + s^2 / sin^2(el) at both stations."""
        return 2.0 + 1.0 / np.sin(self.ga.elevation_rad) ** 2 + 1.0 / np.sin(self.gb.elevation_rad) ** 2

    def ambiguities_from_code(self) -> np.ndarray:
        """(S, 2) SD ambiguities [cycles] from phase minus code (the ionosphere taken as zero)."""
        return (self.phase_m - self.code_m) / self.wavelength_m


def common_dual_frequency(ep_a: StationEpoch, ep_b: StationEpoch, excluded=frozenset()):
    """The two stations' observations of the satellites both track on both frequencies, same signals;
    with the index of each in its station's epoch. (None, None, None, None) with fewer than two."""
    ia = {s: i for i, s in enumerate(np.asarray(ep_a.sats).tolist())}
    common = [(ia[s], j) for j, s in enumerate(np.asarray(ep_b.sats).tolist()) if s in ia and s not in excluded]
    if len(common) < 2:
        return None, None, None, None
    ja = np.array([p[0] for p in common], dtype=int)
    jb = np.array([p[1] for p in common], dtype=int)
    same = ep_a.dual_frequency()[ja] & ep_b.dual_frequency()[jb] & (ep_a.freq_hz[ja] == ep_b.freq_hz[jb]).all(axis=1)
    ja, jb = ja[same], jb[same]
    if len(ja) < 2:
        return None, None, None, None
    return ep_a.subset(ja), ep_b.subset(jb), ja, jb


def above_mask(a: StationEpoch, b: StationEpoch, ga: SatelliteGeometry, gb: SatelliteGeometry,
               mask_deg: float) -> SingleDifferences | None:
    """The single differences of the satellites with valid geometry above `mask_deg` at both stations; None with
    fewer than two."""
    mask = math.radians(mask_deg)
    use = ga.valid & gb.valid & (ga.elevation_rad >= mask) & (gb.elevation_rad >= mask)
    if use.sum() < 2:
        return None
    a, b, ga, gb = a.subset(use), b.subset(use), ga.subset(use), gb.subset(use)
    f = a.freq_hz
    lam = SPEED_OF_LIGHT_M_S / f
    phase_a = a.phase_cyc * lam - (ga.g_m + ga.trop_model_m)[:, None]
    phase_b = b.phase_cyc * lam - (gb.g_m + gb.trop_model_m)[:, None]
    code_a = a.code_m - (ga.g_m + ga.trop_model_m)[:, None]
    code_b = b.code_m - (gb.g_m + gb.trop_model_m)[:, None]
    for g, phase, code in ((ga, phase_a, code_a), (gb, phase_b, code_b)):
        if g.antenna_m is not None:  # observations referred to the ARP: phase centre offset and variations out
            phase += g.antenna_m
            code += g.antenna_m
    return SingleDifferences(a.sats, a, b, ga, gb, f, lam, (f[:, 0] / f[:, 1]) ** 2, phase_b - phase_a,
                             code_b - code_a)
