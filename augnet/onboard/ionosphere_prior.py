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
# The day's level, once satellites are fixed with the ionosphere in the model: DAY_ADAPT times the one-sided
# 95 % upper bound of the RMS of their vertical SD ionosphere (the centre's iono_prior_adapt, decision 0102),
# over a running mean square with time constant DAY_TAU_S [s], from at least DAY_MIN_SATS satellites, never
# below LEARNED_FLOOR_PPM of the baseline (the centre's floor of a day's level).  Until then the per-km prior.
# (The SD geometry-free phase's rate, the centre's first stage, was measured and left out: on catnet's 30 s
# data multipath reads as ionosphere, 7-9 cm at 20 km on a quiet night: docs/decisions/0162.)
DAY_ADAPT = 1.2
DAY_TAU_S = 300.0
DAY_MIN_SATS = 4
UPPER_BOUND_Z = 1.645
LEARNED_FLOOR_PPM = 0.7
PPM = 1.0e-6
# A state's prior is tightened to the learned one only when that is this much tighter (the centre's share).
PRIOR_TIGHTER_SHARE = 0.9


def rms_upper_bound_factor(n: int, z: float = UPPER_BOUND_Z) -> float:
    """sqrt(n / chi2_{5 %}(n)): the one-sided 95 % upper bound of an RMS of n samples over the RMS
    (Wilson-Hilferty), as the centre's."""
    q = n * (1.0 - 2.0 / (9.0 * n) - z * math.sqrt(2.0 / (9.0 * n))) ** 3
    return math.sqrt(n / q)


class LearnedPrior:
    """The SD vertical ionosphere prior learned from the fixed satellites' estimated DD ionosphere."""

    def __init__(self):
        self._day_ms: float | None = None  # running mean square of the fixed satellites' vertical SD ionosphere
        self._day_n = 0
        self._day_t = math.nan

    @property
    def known(self) -> bool:
        return self._day_ms is not None

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

    def sigma0_m(self, baseline_m: float) -> float | None:
        """The learned prior sigma [m] of the SD vertical ionosphere on the first frequency, None until known."""
        if self._day_ms is None:
            return None
        return max(LEARNED_FLOOR_PPM * PPM * baseline_m,
                   DAY_ADAPT * math.sqrt(self._day_ms) * rms_upper_bound_factor(self._day_n))


# --- the quiet-ionosphere hypothesis (before the day's level is known) -----------------------------------
# The DD ionosphere's rate from the SD geometry-free phase (L1 - L2 [m] = (mu2 - 1) I1, no geometry, no clock):
# per satellite over RATE_WINDOW_S [s] of an unbroken arc, against the highest satellite, vertical (over
# sqrt(M_k^2 + M_ref^2)).  A 1 Hz rover's GF multipath (mm, minutes) sets the window: longer averages it down.
RATE_WINDOW_S = 60.0
# ... and the shortest span [s] whose least-squares slope is used before a first full window (a cold start).
RATE_MIN_S = 30.0
# The tight prior tried when the rate says the night is quiet [m]: the vertical SD ionosphere of fixed
# satellites at 20 km on catnet-2010-077 was 0.3-1.0 cm (decision 0162); 0.5 cm is the hypothesis' level.
QUIET_SIGMA_M = 0.005
# Quiet: the RMS vertical DD rate would take at least this long [s] to move the DD ionosphere by QUIET_SIGMA_M:
# the span of the decisions a quiet fix rests on (two 30 s base epochs, `RtkFilter._spans_base_epochs`), after
# which the fixed satellites' own level (LearnedPrior) decides.  Measured 2.7-5.7e-5 m/s RMS at 20 km on
# catnet-2010-077 05:00-05:20 (mostly the rover's GF multipath over 120 s), against 8.3e-5 allowed.
QUIET_HORIZON_S = 60.0
# A quiet fix's own check: each fixed satellite's DD ionosphere within this many sigmas of the tight prior.
QUIET_CHECK_SIGMAS = 3.0
# mu of L2 over L1 for GPS: (f1 / f2)^2 = (1575.42 / 1227.60)^2.
GPS_MU2 = (1575.42 / 1227.60) ** 2


# The base's part of the SD GF rate from its own measured epochs (a 30 s base; in a file, also the
# BASE_RATE_SPAN_S before the rover's start): a quadratic least-squares fit over BASE_RATE_SPAN_S [s] of the
# unbroken arc, its derivative at the rover window's middle, from BASE_RATE_MIN_EPOCHS epochs.  Inside a 30 s
# SD slope the interpolated base contributes two epochs' GF noise over 30 s, ~1e-4 m/s on catnet-2010-077,
# the gate's own size; twenty epochs average it down (docs/decisions/0221).
BASE_RATE_SPAN_S = 600.0
BASE_RATE_MIN_EPOCHS = 8
# A base arc broken by a gap longer than this [s] (one 30 s interval and slack, cycleslip.BASE_MAX_ARC_GAP_S).
BASE_RATE_MAX_GAP_S = 35.0


class BaseRateHistory:
    """The base's own zero-difference geometry-free phase per satellite, at its measured epochs."""

    def __init__(self):
        self._arc: dict[str, list[tuple[float, float]]] = {}

    def update(self, t: float, sats, gf_m: np.ndarray, broken: np.ndarray) -> None:
        """A measured base epoch's GF [m] per satellite (NaN: none); `broken`: its arc slipped."""
        for k, sat in enumerate(sats):
            g = float(gf_m[k])
            if broken[k] or not np.isfinite(g):
                self._arc.pop(sat, None)
                continue
            arc = self._arc.setdefault(sat, [])
            if arc and t <= arc[-1][0]:
                continue  # this epoch seen already (a 30 s base reused by a 1 Hz rover)
            if arc and t - arc[-1][0] > BASE_RATE_MAX_GAP_S:
                arc.clear()
            arc.append((t, g))
            while arc[0][0] < t - BASE_RATE_SPAN_S:
                arc.pop(0)

    def break_arcs(self, sats, broken: np.ndarray) -> None:
        for sat, b in zip(sats, broken):
            if b:
                self._arc.pop(sat, None)

    def rate(self, sat: str, t: float) -> float | None:
        """d GF / dt [m/s] of the base's arc at t (inside it, or no further than one gap past its last epoch),
        or None."""
        arc = self._arc.get(sat)
        if not arc or len(arc) < BASE_RATE_MIN_EPOCHS or not arc[0][0] <= t <= arc[-1][0] + BASE_RATE_MAX_GAP_S:
            return None
        a = np.asarray(arc)
        x = a[:, 0] - arc[-1][0]
        c2, c1, _ = np.polyfit(x, a[:, 1], 2)
        return float(2.0 * c2 * (t - arc[-1][0]) + c1)


class QuietMonitor:
    """The DD ionosphere's rate [m/s, vertical, L1] from the SD geometry-free phase, and whether it is quiet.

    Per satellite the SD rate is the rover's own GF slope (1 Hz) minus the base's (`BaseRateHistory`, many
    30 s epochs) where the base's arc is long enough; otherwise the slope of the SD GF itself."""

    def __init__(self, base: BaseRateHistory | None = None):
        # per satellite and series ("sd", "rov"): the window's start time and its least-squares sums
        # (n, sum dt, sum g, sum dt^2, sum dt g)
        self._win: dict[tuple[str, str], tuple[float, np.ndarray]] = {}
        # per satellite and series: (t, window middle, GF rate [m/s]) of its last window
        self._rate: dict[tuple[str, str], tuple[float, float, float]] = {}
        self.base = base if base is not None else BaseRateHistory()

    def update(self, t: float, sats: list[str], gf_m: np.ndarray, broken: np.ndarray,
               gf_rover_m: np.ndarray | None = None) -> None:
        """This epoch's SD geometry-free phase per satellite (NaN: none), and the rover's own; `broken`: its arc
        slipped."""
        series = [("sd", gf_m)] + ([("rov", gf_rover_m)] if gf_rover_m is not None else [])
        for name, gfs in series:
            for k, sat in enumerate(sats):
                key = (sat, name)
                g = float(gfs[k])
                if broken[k] or not np.isfinite(g):
                    self._win.pop(key, None)
                    self._rate.pop(key, None)
                    continue
                win = self._win.get(key)
                if win is None:
                    win = self._win[key] = (t, np.zeros(5))
                dt = t - win[0]
                win[1][:] += (1.0, dt, g, dt * dt, dt * g)
                slope = _slope(win[1])
                # a least-squares slope over the window's every epoch (a 1 Hz rover's GF noise averaged down),
                # usable from RATE_MIN_S; a full window closes and the next one starts, its rate kept meanwhile
                mid = 0.5 * (win[0] + t)
                if dt >= RATE_WINDOW_S:
                    self._rate[key] = (t, mid, slope)
                    self._win[key] = (t, np.zeros(5))
                elif dt >= RATE_MIN_S and (key not in self._rate or t - self._rate[key][0] > RATE_WINDOW_S):
                    self._rate[key] = (t, mid, slope)

    def _sd_rate(self, t: float, sat: str) -> float | None:
        """The satellite's SD GF rate [m/s]: rover minus base where the base's arc has it, else the SD slope."""
        rov = self._rate.get((sat, "rov"))
        if rov is not None and t - rov[0] <= 2 * RATE_WINDOW_S:
            b = self.base.rate(sat, rov[1])
            if b is not None:
                return rov[2] - b
        sd = self._rate.get((sat, "sd"))
        if sd is not None and t - sd[0] <= 2 * RATE_WINDOW_S:
            return sd[2]
        return None

    def rms_rate(self, t: float, sats: list[str], el: np.ndarray) -> float | None:
        """The RMS vertical DD L1 ionosphere rate [m/s] over this epoch's satellites with a recent window
        (against the highest of them); None with fewer than DAY_MIN_SATS + 1."""
        rates = [(k, self._sd_rate(t, s)) for k, s in enumerate(sats) if np.isfinite(el[k])]
        rates = [(k, r) for k, r in rates if r is not None and np.isfinite(r)]
        if len(rates) < DAY_MIN_SATS + 1:
            return None
        idx = np.array([k for k, _ in rates])
        r = np.array([v for _, v in rates]) / (GPS_MU2 - 1.0)
        m = mapping(el[idx])
        ref = int(np.argmax(el[idx]))
        dd = np.delete((r - r[ref]) / np.hypot(m, m[ref]), ref)
        return float(np.sqrt(np.mean(dd**2)))

    def quiet(self, t: float, sats: list[str], el: np.ndarray) -> bool:
        rate = self.rms_rate(t, sats, el)
        return rate is not None and rate * QUIET_HORIZON_S <= QUIET_SIGMA_M


def _slope(sums: np.ndarray) -> float:
    """The least-squares slope of g over dt from the sums (n, sum dt, sum g, sum dt^2, sum dt g); NaN if degenerate."""
    n, st, sg, stt, stg = sums
    den = n * stt - st * st
    return float((n * stg - st * sg) / den) if den > 0 else math.nan
