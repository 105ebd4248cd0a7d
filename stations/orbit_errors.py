"""Truth orbit and clock errors: truth = broadcast + a slowly varying error.

Broadcast orbits are good to decimetres and clocks to about a nanosecond (GPS SPS PS 2020: SIS URE
< 1 m 95 %; Galileo and BDS-3 similar or better).  The error of each satellite is drawn once from the
seed as a few harmonics of its orbital period (radial, along-track, cross-track; the once- and
twice-per-revolution signatures broadcast fits leave) and a clock error of harmonics of a few hours,
all with the stated 1-sigma.  Faults (a satellite clock step) are added on top.
"""

from __future__ import annotations

import numpy as np

HARMONICS = (1.0, 2.0)  # cycles per revolution
ALONG_TRACK_FACTOR = 2.0  # along-track errors are the largest in broadcast orbits
CLOCK_PERIODS_S = (3 * 3600.0, 7 * 3600.0, 11 * 3600.0)
SPEED_OF_LIGHT_M_S = 299_792_458.0


class OrbitClockErrors:
    """Errors for satellites `sats`; evaluate with satellite indices and GPST times."""

    def __init__(self, sats, orbit_sigma_m: float, clock_sigma_ns: float, seed: int,
                 orbital_period_s: np.ndarray, clock_steps=(), clock_ramps=()):
        rng = np.random.default_rng([seed, 0x0E77])
        n = len(sats)
        self.sats = list(sats)
        h = len(HARMONICS)
        # amplitudes so that the std of each component equals its sigma: sum of h sines, std a*sqrt(h/2)
        scale = orbit_sigma_m / np.sqrt(h / 2.0)
        self.amp = rng.normal(0.0, 1.0, (n, 3, h)) * scale / np.sqrt(1.0)
        self.amp[:, 1, :] *= ALONG_TRACK_FACTOR
        self.amp[:, 2, :] *= 0.7
        self.phase = rng.uniform(0, 2 * np.pi, (n, 3, h))
        self.w = 2 * np.pi / np.asarray(orbital_period_s, float)[:, None] * np.array(HARMONICS)[None, :]
        c = len(CLOCK_PERIODS_S)
        self.clk_amp = rng.normal(0.0, 1.0, (n, c)) * clock_sigma_ns * 1e-9 / np.sqrt(c / 2.0)
        self.clk_phase = rng.uniform(0, 2 * np.pi, (n, c))
        self.clk_w = 2 * np.pi / np.array(CLOCK_PERIODS_S)
        # clock steps: (satellite index, GPST of the step, step [s])
        self.steps = [(self.sats.index(s), t, d) for s, t, d in clock_steps if s in self.sats]
        # clock ramps: (satellite index, GPST start, GPST end, rate [s/s]); nominal again after the end
        self.ramps = [(self.sats.index(s), a, b, r) for s, a, b, r in clock_ramps if s in self.sats]

    def rtn_m(self, sat_idx, t_gpst) -> np.ndarray:
        """(..., 3) radial, along-track, cross-track error [m] for satellites sat_idx at times t."""
        t = np.asarray(t_gpst, float)[..., None]
        w = self.w[sat_idx]  # (..., h)
        comp = []
        for k in range(3):
            comp.append((self.amp[sat_idx, k, :] * np.sin(w * t + self.phase[sat_idx, k, :])).sum(-1))
        return np.stack(comp, axis=-1)

    def ecef_m(self, sat_idx, t_gpst, pos, vel) -> np.ndarray:
        """The error as an ECEF vector, with the RTN frame from the satellite's position/velocity."""
        rtn = self.rtn_m(sat_idx, t_gpst)
        r = pos / np.linalg.norm(pos, axis=-1, keepdims=True)
        c = np.cross(pos, vel)
        c /= np.linalg.norm(c, axis=-1, keepdims=True)
        a = np.cross(c, r)
        return rtn[..., 0:1] * r + rtn[..., 1:2] * a + rtn[..., 2:3] * c

    def clock_s(self, sat_idx, t_gpst) -> np.ndarray:
        """Truth minus broadcast satellite clock [s]."""
        t = np.asarray(t_gpst, float)[..., None]
        out = (self.clk_amp[sat_idx] * np.sin(self.clk_w * t + self.clk_phase[sat_idx])).sum(-1)
        for j, t_step, d in self.steps:
            out = out + np.where((np.asarray(sat_idx) == j) & (t[..., 0] >= t_step), d, 0.0)
        for j, a, b, rate in self.ramps:
            on = (np.asarray(sat_idx) == j) & (t[..., 0] >= a) & (t[..., 0] < b)
            out = out + np.where(on, rate * (t[..., 0] - a), 0.0)
        return out
