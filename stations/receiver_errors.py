"""Receiver-side truth errors: thermal noise, multipath, and the receiver clock.

Noise and multipath (per receiver, satellite, signal): the zenith figure of the receiver grade,
scaled with elevation like RTKLIB's error model (sigma^2 = a^2 + b^2 / sin^2(el), a = b), split into
white noise and an AR(1) multipath process whose correlation time is minutes for a static antenna
and seconds for a moving one (the reflection geometry changes as the train moves).

Receiver clock: a bias and a drift drawn per receiver, the drift wandering as a random walk
(white frequency noise of an OCXO-steered geodetic receiver or a train's TCXO).
"""

from __future__ import annotations

import math

import numpy as np

# Receiver grades: multipath correlation time, C/N0 at zenith [dB-Hz], clock drift scale [s/s] and
# random-walk frequency noise [s/s per sqrt(s)].
GRADES = {
    "geodetic": dict(mp_tau_s=120.0, cnr_zenith=50.0, clock_drift=2e-10, clock_rw=1e-11),
    "train": dict(mp_tau_s=3.0, cnr_zenith=46.0, clock_drift=5e-9, clock_rw=1e-10),
}
WHITE_SHARE_CODE = 0.5  # fraction of the code error variance that is white (the rest multipath)
WHITE_SHARE_PHASE = 0.7
CLOCK_BIAS_MAX_S = 5e-7  # steered receiver clocks start within +-0.5 us of GPST
CNR_LOSS_PER_SIGNAL_DB = (0.0, 3.0, 4.0)  # L2/L5-class signals are received a few dB weaker
CNR_LOW_ELEVATION_DB = 20.0  # C/N0 drop from zenith to the horizon (antenna gain pattern)


def elevation_scale(el_rad: np.ndarray) -> np.ndarray:
    """Noise multiplier relative to zenith: sqrt(a^2 + b^2 / sin^2 el) with a = b, 1 at zenith."""
    return np.sqrt(0.5 + 0.5 / np.sin(el_rad) ** 2)


def cnr_dbhz(cnr_zenith: np.ndarray, el_rad: np.ndarray, n_signals: int) -> np.ndarray:
    """C/N0 per (..., signal) from the zenith value and elevation."""
    base = cnr_zenith - CNR_LOW_ELEVATION_DB * (1.0 - np.sin(el_rad)) ** 2
    return base[..., None] - np.array(CNR_LOSS_PER_SIGNAL_DB[:n_signals])


class NoiseAndMultipath:
    """AR(1) multipath and white noise for (R, N, K), stepped one epoch at a time."""

    def __init__(self, shape, dt_s: float, sigma_code_m, sigma_phase_m, mp_tau_s, multipath: bool,
                 rng: np.random.Generator, rng_init: np.random.Generator, code_signal_factor=None):
        self.rng = rng
        self.multipath = multipath
        self.phi = np.exp(-dt_s / np.asarray(mp_tau_s, float))[:, None, None]
        self.innov = np.sqrt(1 - self.phi**2)
        self.sc_code = np.asarray(sigma_code_m, float)[:, None, None]
        if code_signal_factor is not None:  # (K,): per-signal scale of the code error (L2 noisier than L1)
            self.sc_code = self.sc_code * np.asarray(code_signal_factor, float)[None, None, :]
        self.sc_phase = np.asarray(sigma_phase_m, float)[:, None, None]
        self.mp_code = rng_init.standard_normal(shape)  # unit-variance AR(1) states
        self.mp_phase = rng_init.standard_normal(shape)
        self.shape = shape

    def step(self, el_scale: np.ndarray):
        """(code multipath, phase multipath, code noise, phase noise, unit normal for Doppler) [m]."""
        z = self.rng.standard_normal((4,) + self.shape)
        self.mp_code = self.phi * self.mp_code + self.innov * z[0]
        self.mp_phase = self.phi * self.mp_phase + self.innov * z[1]
        es = el_scale[..., None]
        if self.multipath:
            mp_c = self.sc_code * math.sqrt(1 - WHITE_SHARE_CODE) * es * self.mp_code
            mp_p = self.sc_phase * math.sqrt(1 - WHITE_SHARE_PHASE) * es * self.mp_phase
        else:
            mp_c = mp_p = np.zeros(self.shape)
        n_c = self.sc_code * math.sqrt(WHITE_SHARE_CODE) * es * z[2]
        n_p = self.sc_phase * math.sqrt(WHITE_SHARE_PHASE) * es * z[3]
        return mp_c, mp_p, n_c, n_p, z[3]


class ReceiverClocks:
    """Bias [s] and drift [s/s] of every receiver's clock, epoch by epoch."""

    def __init__(self, grades, dt_s: float, enabled: bool, rng: np.random.Generator,
                 rng_init: np.random.Generator):
        n = len(grades)
        drift_scale = np.array([GRADES[g]["clock_drift"] for g in grades])
        self.bias = rng_init.uniform(-CLOCK_BIAS_MAX_S, CLOCK_BIAS_MAX_S, n)
        self.freq = rng_init.uniform(-1, 1, n) * drift_scale
        self.rw = np.array([GRADES[g]["clock_rw"] for g in grades])
        if not enabled:
            self.bias[:] = 0.0
            self.freq[:] = 0.0
            self.rw[:] = 0.0
        self.dt = dt_s
        self.rng = rng

    def block(self, n_epochs: int):
        """(bias, drift) arrays (E, R) for the next n_epochs."""
        R = len(self.bias)
        bias = np.empty((n_epochs, R))
        freq = np.empty((n_epochs, R))
        w = self.rng.standard_normal((n_epochs, R))
        for e in range(n_epochs):
            bias[e] = self.bias
            freq[e] = self.freq
            self.bias = self.bias + self.freq * self.dt
            self.freq = self.freq + self.rw * math.sqrt(self.dt) * w[e]
        return bias, freq
