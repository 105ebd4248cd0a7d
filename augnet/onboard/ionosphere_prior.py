"""The rover's ionosphere-weighted model: when the single-difference (rover - base) ionosphere is
estimated, and its prior, random walk and lifetime.

The SD ionospheric delay on each satellite's first frequency is a state with a prior sigma of
sigma0 * M(el), M the thin-shell mapping function; phase sees -mu I and code +mu I, mu = (f1 / f)^2.
sigma0 is the user's figure, a network VRS's interpolation residual (`RtkOptions.vrs_iono_sigma_m`), or
grows with the distance to a physical base (IONO_SIGMA_PER_M).
"""

from __future__ import annotations

import math

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


# --- the learned prior (`RtkOptions.iono_prior = "learned"`) -------------------------------------------
# How fast the SD ionosphere moves, from the SD (rover - base) geometry-free phase at simultaneous epochs:
# per satellite, increments over one interval and over at least LEARN_LAG_S (and three intervals); for white
# phase noise s and a random walk of rate q, E[d^2] = 2 s^2 + q dt, so the two mean squares give q whatever
# the interval (the centre's estimator, augnet/centre/ionosphere_prior.py IonosphereActivity).
LEARN_LAG_S = 90.0
# Increments over the lag needed before the learned rate counts (a 30 s base, 8 satellites: ~3 minutes).
LEARN_MIN_SAMPLES = 40
# Exponential smoothing of the increments' mean squares [epochs of the base].
LEARN_TAU_EPOCHS = 30.0
# The prior sigma0 is this times the rate [ppm of the baseline per ppm/sqrt(s)]: the centre's figure fitted on
# the simulator's quiet to storm levels (decision 0103, iono_activity_ppm_per_rate).
LEARNED_PPM_PER_RATE = 150.0
# ... and never below this [ppm of the baseline, vertical]: the centre's floor of a day's level (decision 0102).
LEARNED_FLOOR_PPM = 0.7
PPM = 1.0e-6
# A vertical SD geometry-free step beyond this [m, in units of the first frequency's delay] is a slip the
# detectors missed (a reference receiver's unflagged phase reset, decision 0150), not ionosphere: the arc restarts.
LEARN_SLIP_M = 0.3
# A state's prior is tightened to the learned one only when that is this much tighter (the centre's share).
PRIOR_TIGHTER_SHARE = 0.9


# The day's level, once satellites are fixed: this times the one-sided 95 % upper bound of the RMS of the fixed
# satellites' vertical SD ionosphere (the centre's iono_prior_adapt, decision 0102), over a running mean square
# with this time constant [s], from at least DAY_MIN_SATS satellites.
DAY_ADAPT = 1.2
DAY_TAU_S = 300.0
DAY_MIN_SATS = 4
UPPER_BOUND_Z = 1.645


def rms_upper_bound_factor(n: int, z: float = UPPER_BOUND_Z) -> float:
    """sqrt(n / chi2_{5 %}(n)): the one-sided 95 % upper bound of an RMS of n samples over the RMS
    (Wilson-Hilferty), as the centre's."""
    q = n * (1.0 - 2.0 / (9.0 * n) - z * math.sqrt(2.0 / (9.0 * n))) ** 3
    return math.sqrt(n / q)


class LearnedPrior:
    """The SD vertical ionosphere prior learned from the data, in two stages: LEARNED_PPM_PER_RATE times the
    measured rate of the SD geometry-free phase (once LEARN_MIN_SAMPLES long increments), then, once satellites
    are fixed with the ionosphere in the model, the day's level from their estimated DD ionosphere."""

    def __init__(self):
        self._hist: dict[str, list[tuple[float, float]]] = {}  # sat -> (t, slant SD GF in units of I1 [m])
        self._means: np.ndarray | None = None  # mean squares and spans: short [m^2, s], long [m^2, s]
        self._samples = 0
        self._day_ms: float | None = None  # running mean square of the fixed satellites' vertical SD ionosphere
        self._day_n = 0
        self._day_t = math.nan

    @property
    def stage(self) -> int:
        """0: nothing learned, 1: the rate, 2: the day's level."""
        if self._day_ms is not None:
            return 2
        return 1 if self.rate_m_sqrt_s() is not None else 0

    def learn_fixed(self, t: float, sd_vertical_m: np.ndarray) -> None:
        """A declared fix's satellites' SD vertical ionosphere [m] (DD over sqrt(M_k^2 + M_ref^2))."""
        q = sd_vertical_m[np.isfinite(sd_vertical_m)]
        if q.size < DAY_MIN_SATS:
            return
        ms = float(np.mean(q**2))
        if self._day_ms is None:
            self._day_ms = ms
        else:
            self._day_ms += min(1.0, max(t - self._day_t, 0.0) / DAY_TAU_S) * (ms - self._day_ms)
        self._day_n, self._day_t = q.size, t

    def observe(self, t: float, sats, sd_gf_m: np.ndarray, gamma_minus_1: np.ndarray, el_rad: np.ndarray,
                restarted) -> None:
        """One simultaneous epoch: SD geometry-free phase lambda1 phi1 - lambda2 phi2 [m] per satellite (NaN
        without), (f1/f2)^2 - 1, the elevations, and the satellites whose arc restarted (a slip)."""
        # slant, in units of the first frequency's delay; increments scaled to vertical (the arc's constant
        # ambiguity would not survive the mapping)
        slant = sd_gf_m / gamma_minus_1
        to_vert = 1.0 / mapping(el_rad)
        short, long_ = [], []
        for k, s in enumerate(sats):
            if s in restarted:
                self._hist.pop(s, None)
            if not np.isfinite(slant[k]) or not np.isfinite(to_vert[k]):
                continue
            h = self._hist.setdefault(s, [])
            if h and abs(slant[k] - h[-1][1]) * to_vert[k] > LEARN_SLIP_M:
                h.clear()
            if h:
                dt = t - h[-1][0]
                short.append((((slant[k] - h[-1][1]) * to_vert[k]) ** 2, dt))
                span = max(LEARN_LAG_S, 3.0 * dt)
                old = next((p for p in reversed(h) if t - p[0] >= span - 1e-6), None)
                if old is not None:
                    long_.append((((slant[k] - old[1]) * to_vert[k]) ** 2, t - old[0]))
                while len(h) > 1 and t - h[1][0] >= span - 1e-6:
                    h.pop(0)
            h.append((t, float(slant[k])))
        if not short or not long_:
            return
        now = np.array([np.mean([d for d, _ in short]), np.mean([d for _, d in short]),
                        np.mean([d for d, _ in long_]), np.mean([d for _, d in long_])])
        self._means = now if self._means is None else self._means + (now - self._means) / LEARN_TAU_EPOCHS
        self._samples += len(long_)

    def rate_m_sqrt_s(self) -> float | None:
        """The SD vertical ionosphere's random-walk rate [m/sqrt(s)], None until learned."""
        if self._means is None or self._samples < LEARN_MIN_SAMPLES:
            return None
        ms_short, dt_short, ms_long, dt_long = self._means
        if not dt_long > dt_short:
            return None
        return math.sqrt(max(ms_long - ms_short, 0.0) / (dt_long - dt_short))

    def sigma0_m(self, baseline_m: float) -> float | None:
        """The learned prior sigma [m] of the SD vertical ionosphere on the first frequency, None until learned."""
        floor = LEARNED_FLOOR_PPM * PPM * baseline_m
        if self._day_ms is not None:
            return max(floor, DAY_ADAPT * math.sqrt(self._day_ms) * rms_upper_bound_factor(self._day_n))
        rate = self.rate_m_sqrt_s()
        if rate is None:
            return None
        rate_ppm = rate / (PPM * baseline_m)
        return max(LEARNED_FLOOR_PPM, LEARNED_PPM_PER_RATE * rate_ppm) * PPM * baseline_m
