"""The ionosphere prior of a baseline's integer decisions, and how it is learned.

The DD ionosphere is what separates the wide-lane candidates (one wide-lane cycle with the ionosphere-free phase
kept is 0.57-0.8 m of DD ionosphere), so the prior must be the day's. Levels are in ppm of the baseline length,
vertical, mapped to slant with the single-layer mapping function. The prior in force is:

1. the default (`iono_prior_ppm`), raised by the ionosphere's rate measured from the SD geometry-free phase
   (`IonosphereActivity`); nothing is committed before the rate is known;
2. then the day's level: the 95 % upper bound of the RMS of the fixed satellites' DD ionosphere times
   `iono_prior_adapt`, pooled over the whole network (`share_network_ionosphere`);
3. per satellite, the network's single-layer model's prediction where that is tighter (`network.py`).

The filter's own SD ionosphere states start with a storm's prior (`iono_state_prior_ppm`); the prior in force
enters the integer decision only, as a DD ionosphere pseudo-observation making up the difference
(`IonospherePrior.pseudo_observations`), so no state is pulled by a prior the day disproves (decision 0103).
"""

from __future__ import annotations

import math

import numpy as np

from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.baseline_integers import BaselineIntegers
from augnet.gnss.ionosphere import SHELL_HEIGHT_M, thin_shell_mapping

PPM = 1e-6
# The 95 % one-sided normal quantile: the day's level is an upper bound of the RMS seen (the satellites fixed
# first are the ones the default prior agreed with, a sample biased low)
UPPER_BOUND_Z = 1.645
# Decisions taken before the rate was known are dropped if the rate then raises the prior by more than this
DRY_RUN_PRIOR_TOLERANCE = 1.05
# A prior in force counts only where it is this much tighter than the state's own (1/new = 1/old + 1/extra)
PRIOR_TIGHTER_SHARE = 0.9


def slant_mapping(el_rad: np.ndarray, shell_height_km: float | None) -> np.ndarray:
    """Slant over vertical ionosphere of the baseline's prior (single layer); ones without a shell height."""
    if shell_height_km is None:
        return np.ones_like(el_rad)
    return thin_shell_mapping(el_rad, 1e3 * shell_height_km)


def network_shell_height_km(shell_height_km: float | None) -> float:
    """The shell of the network's hint error model and single-layer model: the configured one, else Klobuchar's
    350 km (a thin-shell model needs one; decision 0100)."""
    return shell_height_km or SHELL_HEIGHT_M / 1e3


def rms_upper_bound_factor(n: int, z: float = UPPER_BOUND_Z) -> float:
    """sqrt(n / chi2_{5 %}(n)): the one-sided 95 % upper bound of an RMS from n samples, over the RMS
    (Wilson-Hilferty's approximation of the chi-square quantile)."""
    q = n * (1.0 - 2.0 / (9.0 * n) - z * math.sqrt(2.0 / (9.0 * n))) ** 3
    return math.sqrt(n / q)


def day_ionosphere_ppm(rms_ppm: float, n: int, cfg: BaselineConfig) -> float | None:
    """The day's ionosphere prior from the RMS of n fixed satellites' DD ionosphere [ppm, vertical]: its 95 %
    upper bound times `iono_prior_adapt`, never below the floor; None with too few satellites."""
    if cfg.iono_prior_adapt <= 0 or n < cfg.iono_day_min_sats or not math.isfinite(rms_ppm):
        return None
    return max(cfg.iono_day_floor_ppm, cfg.iono_prior_adapt * rms_ppm * rms_upper_bound_factor(n))


class IonosphereActivity:
    """How fast the ionosphere moves between the stations, from the SD geometry-free phase (no ambiguity within an
    arc, no clock, no geometry: its changes are the SD ionosphere's, plus noise). Per satellite, the increment
    since the previous epoch and since one at least `activity_lag_s` (and three epochs) back, squared, in vertical
    ppm of the baseline: E[d^2] = 2 sigma^2 + q dt for white phase noise sigma and a random walk of rate q, so the
    two means give q whatever the observation interval."""

    def __init__(self, cfg: BaselineConfig, length_m: float):
        self.cfg = cfg
        self.length_m = length_m
        self._history: dict[str, list[tuple[float, float]]] = {}  # sat -> (t, SD geometry-free [m]) of its arc
        # smoothed mean squared increments and their spans: one epoch, and the lag [ppm^2, s, ppm^2, s]
        self._means: np.ndarray | None = None
        self._samples = 0

    def forget(self, sat: str) -> None:
        self._history.pop(sat, None)

    def observe(self, t: float, sats, sd_gf_m: np.ndarray, restarted: set[str], mapping: np.ndarray,
                gamma: np.ndarray) -> None:
        cfg = self.cfg
        short, long_ = [], []  # (squared increment [ppm^2], its time span [s])
        for k, s in enumerate(sats):
            s = str(s)
            if s in restarted:
                self._history[s] = []
            hist = self._history.setdefault(s, [])
            gf = sd_gf_m[k]
            if not math.isfinite(gf):
                continue
            scale = 1.0 / ((gamma[k] - 1.0) * mapping[k] * PPM * self.length_m)
            if hist:
                dt = t - hist[-1][0]
                short.append((((gf - hist[-1][1]) * scale) ** 2, dt))
                span = max(cfg.activity_lag_s, 3.0 * dt)
                old = next((h for h in reversed(hist) if t - h[0] >= span - 1e-6), None)
                if old is not None:
                    long_.append((((gf - old[1]) * scale) ** 2, t - old[0]))
                while len(hist) > 1 and t - hist[1][0] >= span - 1e-6:
                    hist.pop(0)
            hist.append((t, gf))
        if not short or not long_:
            return
        now = np.array([np.mean([d for d, _ in short]), np.mean([d for _, d in short]),
                        np.mean([d for d, _ in long_]), np.mean([d for _, d in long_])])
        a = 1.0 if self._means is None else 1.0 / cfg.activity_tau_epochs
        self._means = now if self._means is None else self._means + a * (now - self._means)
        self._samples += len(long_)

    @property
    def rate_ppm_sqrt_s(self) -> float | None:
        """The measured SD ionosphere rate [ppm/sqrt(s), vertical], None until enough increments."""
        if self._means is None or self._samples < self.cfg.activity_min_samples:
            return None
        ms_short, dt_short, ms_long, dt_long = self._means
        if not dt_long > dt_short:
            return None
        return math.sqrt(max(ms_long - ms_short, 0.0) / (dt_long - dt_short))


class IonospherePrior:
    """A baseline's ionosphere prior: the default, the measured activity, the day's level (its own, or the
    network's once `share_network_ionosphere` has set it), and the pseudo-observations that put the prior in
    force into the integer decision."""

    def __init__(self, cfg: BaselineConfig, length_m: float):
        self.cfg = cfg
        self.length_m = length_m
        self.activity = IonosphereActivity(cfg, length_m)
        self._mean_square: float | None = None  # of fixed satellites' DD ionosphere [ppm^2, vertical]
        self._day_own: float | None = None  # the day's level from this baseline's fixed satellites [ppm]
        self.day_network: float | None = None  # ... from the whole network's [ppm]
        self.rate_network: float | None = None  # the network's mean rate [ppm/sqrt(s)]
        self.day_q = np.zeros(0)  # this epoch's fixed satellites' DD ionosphere [ppm, vertical]
        self._dry_level: float | None = None  # prior in force while decisions ran without committing [ppm]
        self._state_prior: dict[str, float] = {}  # sat -> prior variance its SD ionosphere state started with [m^2]

    # --- the levels -----------------------------------------------------------------------------------

    @property
    def day_ppm(self) -> float | None:
        """The day's level [ppm, vertical]: the network's (pooled over every baseline's fixed satellites) where
        there is one, else this baseline's own; None until either is known (decision 0102)."""
        return self.day_network if self.day_network is not None else self._day_own

    @property
    def own_rate(self) -> float | None:
        """This baseline's measured rate [ppm/sqrt(s), vertical]."""
        return self.activity.rate_ppm_sqrt_s

    @property
    def rate(self) -> float | None:
        """The ionosphere's rate [ppm/sqrt(s)]: the network's mean where there is one, else this baseline's."""
        return self.rate_network if self.rate_network is not None else self.own_rate

    @property
    def level_ppm(self) -> float:
        """The prior in force [ppm, vertical]: the day's level once known; before, the default raised (never
        lowered) by the measured activity and by what the few fixed satellites show."""
        cfg = self.cfg
        ppm = self.day_ppm
        if ppm is not None:
            return ppm
        ppm = cfg.iono_prior_ppm
        rate = self.rate
        if rate is not None and cfg.iono_activity_ppm_per_rate > 0:
            ppm = max(ppm, cfg.iono_activity_ppm_per_rate * rate)
        if self._mean_square is not None and cfg.iono_prior_adapt > 0:
            ppm = max(ppm, cfg.iono_prior_adapt * math.sqrt(self._mean_square))
        return ppm

    @property
    def random_walk_m2_s(self) -> float:
        """Random-walk variance rate of the SD ionosphere states, vertical [m^2/s]: the configured rate, or
        `activity_rate_margin` times the measured one where that is higher."""
        rate = max(self.cfg.iono_rate_ppm_sqrt_s, self.cfg.activity_rate_margin * (self.rate or 0.0))
        return (rate * PPM * self.length_m) ** 2

    # --- the filter state's own prior -------------------------------------------------------------------

    def state_prior_m2(self, sat: str, mapping: float) -> float:
        """The prior variance a new SD ionosphere state starts with [m^2] (a storm's), recorded for the
        pseudo-observations."""
        var = max((self.cfg.iono_state_prior_ppm * PPM * self.length_m) ** 2 * mapping**2, self.cfg.iono_prior_min_m**2)
        self._state_prior[sat] = var
        return var

    def state_prior_dd(self, sat: str, ref: str) -> float:
        """The prior variance the DD ionosphere (sat - ref) had in the filter state [m^2] (NaN if unknown)."""
        return self._state_prior.get(sat, math.nan) + self._state_prior.get(ref, math.nan)

    def state_priors(self, sats) -> np.ndarray:
        """(S,) the prior variance each satellite's SD ionosphere state started with [m^2] (NaN if unknown):
        `state_prior_dd` is the sum of two of them."""
        return np.array([self._state_prior.get(s, math.nan) for s in sats], dtype=float)

    # --- learning ---------------------------------------------------------------------------------------

    def may_commit(self) -> bool:
        """Nothing is fixed before the ionosphere's rate is known (when the activity raises the prior)."""
        return self.cfg.iono_activity_ppm_per_rate <= 0 or self.rate is not None

    def dry_run_outdated(self) -> bool:
        """Once per epoch: True when the rate has just become known and raised the prior the decisions taken
        meanwhile (without committing) used; their confirmation counts are then dropped."""
        commit = self.may_commit()
        level = self.level_ppm
        outdated = commit and self._dry_level is not None and level > DRY_RUN_PRIOR_TOLERANCE * self._dry_level
        self._dry_level = None if commit else level
        return outdated

    def learn(self, dt: float, fixed: np.ndarray, ref_k: np.ndarray, mapping: np.ndarray,
              dd_iono_m: np.ndarray) -> None:
        """This epoch's fixed satellites' DD ionosphere in the prior's units (vertical ppm; `day_q`, which the
        network pools), their running mean square, and from it this baseline's own day level."""
        cfg = self.cfg
        self.day_q = np.zeros(0)
        if cfg.iono_prior_adapt <= 0 or not fixed.any():
            return
        q = dd_iono_m[fixed] / (PPM * self.length_m * np.hypot(mapping[fixed], mapping[ref_k[fixed]]))
        q = q[np.isfinite(q)]
        if not q.size:
            return
        self.day_q = q
        ms = float(np.mean(q**2))
        if self._mean_square is None:
            self._mean_square = ms
        else:
            self._mean_square += min(1.0, dt / cfg.iono_prior_adapt_tau_s) * (ms - self._mean_square)
        level = day_ionosphere_ppm(math.sqrt(self._mean_square), q.size, cfg)
        if level is not None:
            self._day_own = level

    # --- the prior in the integer decision ---------------------------------------------------------------

    def pseudo_observations(self, sats, rows, ref_k, mapping, fixed: BaselineIntegers, hints=None, model=None):
        """The network's hints, plus, where the prior in force is tighter than the one a satellite's ionosphere
        state (and its reference's) started with, a DD ionosphere pseudo-observation whose variance makes up the
        difference (1/new = 1/old + 1/extra): as if the satellite had started with it (combined with the
        network's hint where there is one). The prior in force is the day's level around zero, or the network's
        ionosphere model's prediction (`model`: sat -> (reference, DD ionosphere [m], variance [m^2])) where that
        is tighter. Returns sat -> (reference, DD ionosphere [m], variance [m^2])."""
        out = dict(hints or {})
        day = (self.level_ppm * PPM * self.length_m) ** 2
        floor = self.cfg.iono_prior_min_m**2
        for k in rows:
            s, r = str(sats[k]), str(sats[ref_k[k]])
            if fixed.both(s):
                continue
            old = self.state_prior_dd(s, r)
            mean, new = 0.0, max(day * mapping[k] ** 2, floor) + max(day * mapping[ref_k[k]] ** 2, floor)
            m = (model or {}).get(s)
            if m is not None and m[0] == r and m[2] < self.cfg.iono_model_max_variance_share * new:
                mean, new = m[1], max(m[2], 2.0 * floor)
            if not new < PRIOR_TIGHTER_SHARE * old:
                continue
            v = 1.0 / (1.0 / new - 1.0 / old)
            z = mean * v / new  # the state started at zero: prior mean = z * new / v
            h = out.get(s)
            if h is not None and h[0] == r:  # a network hint as well: two independent pseudo-observations
                out[s] = (r, (z * h[2] + h[1] * v) / (v + h[2]), h[2] * v / (v + h[2]))
            elif h is None:
                out[s] = (r, z, v)
        return out


def share_network_ionosphere(priors: list[IonospherePrior], cfg: BaselineConfig) -> None:
    """The ionosphere's measured rate (mean over the baselines) and the day's level from every baseline's fixed
    satellites at once (in ppm of each baseline's length), handed to every baseline: a network of four baselines
    with three satellites fixed on each knows the day's level after the first fixes, where one baseline alone
    would wait for more."""
    rates = [p.own_rate for p in priors if p.own_rate is not None]
    for p in priors:
        p.rate_network = float(np.mean(rates)) if rates else None
    q = np.concatenate([p.day_q for p in priors])
    level = day_ionosphere_ppm(float(np.sqrt(np.mean(q**2))) if q.size else math.nan, q.size, cfg)
    if level is None:
        return
    for p in priors:
        # kept until a lower level is well established (an epoch with few fixes does not reset it); a higher one
        # is followed at once
        prev = p.day_network
        p.day_network = level if prev is None or level > prev or q.size >= 2 * cfg.iono_day_min_sats else prev
