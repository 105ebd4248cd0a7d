"""Along-track position from GNSS fixes and the odometer: the weighted median and its comparison methods.

Each GNSS along-track fix s_h at t_h, carried forward by the odometer increment from t_h to now, is an
estimate of the position now (railway.md, weighted-median fusion):

    x_h = s_h + dir * (odo(now) - odo(t_h)),   var(x_h) = sigma_h^2 + var_odo(t_h -> now)

The estimates share the odometer increments, so they are correlated: for two fixes i, j the increment from
the later one to now is common (white speed error, slip and the end count), and the scale (radius) error is
common in proportion to both distances:

    C_ij = delta_ij (sigma_i^2 + q^2/12) + r (now - max(t_i, t_j)) + s^2 D_i D_j + q^2/12

(r: the model's variance rate [m^2/s], s: its scale sigma, D: distances travelled, q: metres per pulse;
`augnet.onboard.odometer`). Methods, one `AlongTrackFusion` each, compared side by side in a run:

* `gnss_raim`: this epoch's fix alone, PL = K sigma (or the fault modes' b_i + K_md sigma when larger, as for
  every method's PL: decisions 0250, 0253); nothing without a fix (tunnels);
* `median`: the median of the window's estimates;
* `weighted_median`: weights 1 / C_hh;
* `residual_weighted_median`: weights 1 / C_hh, further down-weighted (Huber) by each estimate's normalised
  residual to the weighted median, var(x_i - x_k) = C_ii + C_kk - 2 C_ik (the correlation enters here).

A window method's PL is the smallest bound b = K sigma_i such that the estimates with K sigma_i <= b carry more
than half the median's weight: if those are within their bounds, more than half the weight lies within b of
the truth, and so does the (weighted) median, whatever the other estimates do (railway.md: "protection levels
come from the variance bound of the selected estimate"; this is that bound made robust to the estimates the
median outvotes). K per estimate for now; splitting the risk over the window's estimates is issue 15's
integrity allocation. When this epoch's fix passed the residual check and bounds tighter on its own, it is the
output (its integrity is GNSS + RAIM's plus the check against the odometry): the median protects, the newest
checked fix gives the precision. Before a fix enters the window it must
pass a residual check against the prediction (last output + odometer increment); a rejected fix widens that
epoch's PL to cover the window's separation from it (either may be the faulty one); `LOCKOUT_REJECTIONS`
rejections in a row mean the prediction, not the fixes, is wrong (an odometer slide): alarm, window
cleared, restart from the next fix. Without fixes (tunnels) the window's estimates carry on by odometry
and the PL grows with their variance. Sans-IO: `step(now, odometer, fix)`; no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.onboard.integrity_allocation import DEFAULT_ALLOCATION
from augnet.onboard.odometer import OdometerModel, OdometerSample, OdometerError, check_sample
from augnet.onboard.trackmap import DEFAULT_INTEGRITY_RISK, gaussian_k

METHODS = ("gnss_raim", "median", "weighted_median", "residual_weighted_median")
# railway.md: Helmet odometry correction (along-track) alert limit 1.7 m.
ALONG_TRACK_ALERT_LIMIT_M = 1.7
# Estimates in the window: railway.md counts ~240 fixes between balises 2 km apart at 300 km/h and 10 Hz;
# at the scenarios' 1 Hz that span is 24 fixes; 30 keeps a tunnel exit's first estimates company.
DEFAULT_WINDOW_FIXES = 30
# Residual check before a fix enters: a false rejection only loses a fix (continuity, not integrity), so the
# gate sits at P(|N(0,1)| > 4) = 6e-5 per fix.
RESIDUAL_GATE_SIGMA = 4.0
# This many rejected fixes in a row: the prediction has gone wrong (odometer slide), not the GNSS.
LOCKOUT_REJECTIONS = 3
# Residual-weighted median: Huber down-weighting beyond this normalised residual (the usual 95 % efficiency
# constant, Huber 1964).
HUBER_C = 1.345


@dataclass(frozen=True)
class AlongTrackFix:
    """A GNSS along-track estimate: chainage of the antenna [m] at `time`, its 1-sigma [m]."""

    time: float
    position_m: float
    sigma_m: float


@dataclass(frozen=True)
class FusionSettings:
    """One table of the fusion's settings (style.md: each setting declared once)."""

    window_fixes: int = DEFAULT_WINDOW_FIXES
    alert_limit_m: float = ALONG_TRACK_ALERT_LIMIT_M
    integrity_risk: float = DEFAULT_INTEGRITY_RISK
    residual_gate_sigma: float = RESIDUAL_GATE_SIGMA
    lockout_rejections: int = LOCKOUT_REJECTIONS
    huber_c: float = HUBER_C
    direction: int = 1  # +1: forward pulses increase the chainage (the train's orientation on its journey)
    # PL = max(K sigma, b_i + K_md sigma) over decision 0250's fault modes (satellite, wrong correction,
    # odometer slide): a bias the checks let through shifts every estimate alike (decision 0253)
    fault_terms: bool = True

    def __post_init__(self):
        if self.direction not in (1, -1):
            raise ValueError(f"fusion direction must be +1 or -1, got {self.direction}")
        if self.window_fixes < 1 or self.lockout_rejections < 1:
            raise ValueError("fusion window_fixes and lockout_rejections must be >= 1")
        for name in ("alert_limit_m", "residual_gate_sigma", "huber_c"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"fusion {name} must be positive, got {v}")


@dataclass(frozen=True)
class FusedPosition:
    """One method's output at one epoch."""

    time: float
    method: str
    position_m: float  # chainage [m]; NaN when none
    pl_m: float  # along-track protection level [m]; inf when none
    available: bool  # a position with PL below the alert limit
    alarm: bool  # this epoch the method withdrew its position (became unavailable, or locked out)
    n_estimates: int  # estimates in the window (1 for gnss_raim with a fix)
    rejected: bool  # this epoch's fix failed the residual check
    odometry_only: bool  # no fix entered this epoch: the position is carried by odometry
    from_fix: bool = False  # a window method output this epoch's checked fix (it bounded tighter than the median)
    sigma_m: float = math.inf  # the 1-sigma the PL was made from [m] (inf when none)


@dataclass(frozen=True)
class _Entry:
    time: float
    position_m: float
    sigma_m: float
    pulses: int


def weighted_median(values: np.ndarray, weights: np.ndarray) -> int:
    """Index of the weighted median: the smallest value whose cumulative weight reaches half the total."""
    order = np.argsort(values, kind="stable")
    c = np.cumsum(weights[order])
    return int(order[int(np.searchsorted(c, 0.5 * c[-1]))])


class AlongTrackFusion:
    def __init__(self, method: str, odometer: OdometerModel | None = None, settings: FusionSettings | None = None):
        if method not in METHODS:
            raise ValueError(f"fusion method {method!r} unknown; allowed: {', '.join(METHODS)}")
        self.method = method
        self.odometer = odometer or OdometerModel()
        self.settings = settings or FusionSettings()
        self.k = gaussian_k(self.settings.integrity_risk)
        self.window: list[_Entry] = []
        self._last: tuple[float, int, float, float] | None = None  # time, pulses, position, variance
        self._last_odo: OdometerSample | None = None
        self._rejections = 0
        self._was_available = False
        self.rejected_total = 0
        self.lockouts = 0

    # --- the estimates --------------------------------------------------------------------------

    def _increment_m(self, pulses_from: int, pulses_to: int) -> float:
        return self.settings.direction * self.odometer.distance_m(pulses_to - pulses_from)

    def estimates(self, now: float, pulses: int) -> tuple[np.ndarray, np.ndarray]:
        """The window's estimates of the position now [m] and their covariance [m^2] (module docstring)."""
        m = self.odometer
        t = np.array([e.time for e in self.window])
        s = np.array([e.position_m for e in self.window])
        sig = np.array([e.sigma_m for e in self.window])
        inc = np.array([self._increment_m(e.pulses, pulses) for e in self.window])
        x = s + inc
        d = np.abs(inc)
        q2 = m.metres_per_pulse ** 2 / 12.0
        rate = m.speed_sigma_m_s ** 2 * m.sample_interval_s + m.slip_wiener_m2_per_s
        shared_s = np.maximum(now - np.maximum(t[:, None], t[None, :]), 0.0)
        cov = rate * shared_s + m.scale_sigma ** 2 * np.outer(d, d) + q2
        cov[np.diag_indices_from(cov)] += sig ** 2 + q2
        return x, cov

    def _weights(self, x: np.ndarray, cov: np.ndarray) -> np.ndarray:
        var = np.diag(cov)
        if self.method == "median":
            return np.ones_like(x)
        w = 1.0 / var
        if self.method == "weighted_median":
            return w
        k = weighted_median(x, w)
        dvar = np.maximum(var + var[k] - 2.0 * cov[:, k], 1e-12)
        r = np.abs(x - x[k]) / np.sqrt(dvar)
        r[k] = 0.0
        return w * np.minimum(1.0, self.settings.huber_c / np.maximum(r, 1e-12))

    def bound(self, sigma_m: float) -> float:
        """The PL [m] of an estimate with 1-sigma `sigma_m`: K sigma, or the fault modes' bound if larger."""
        pl = self.k * sigma_m
        if self.settings.fault_terms:
            pl = max(pl, DEFAULT_ALLOCATION.fault_bound(sigma_m, "along"))
        return pl

    # --- one epoch --------------------------------------------------------------------------------

    def step(self, now: float, odometer: OdometerSample | None, fix: AlongTrackFix | None) -> FusedPosition:
        """The position at `now` from this epoch's odometer reading and GNSS fix (either may be None)."""
        if odometer is not None:
            try:
                check_sample(odometer, self._last_odo)
            except OdometerError:
                odometer = None  # a bad reading is no reading: the window cannot be carried on it
        if fix is not None and not (math.isfinite(fix.position_m) and math.isfinite(fix.sigma_m)
                                    and fix.sigma_m > 0):
            fix = None
        if self.method == "gnss_raim":
            return self._gnss_alone(now, fix)
        if odometer is None:
            self.window.clear()  # nothing carries old fixes to now
            self._last = None
        else:
            self._last_odo = odometer
        rejected = lockout = False
        entered = False
        if fix is not None:
            if self._passes(now, odometer, fix):
                self._rejections = 0
                if odometer is not None:
                    self.window.append(_Entry(fix.time, fix.position_m, fix.sigma_m, odometer.pulses))
                    del self.window[:-self.settings.window_fixes]
                    entered = True
                else:
                    out = self._gnss_alone(now, fix)
                    return out
            else:
                rejected = True
                self.rejected_total += 1
                self._rejections += 1
                if self._rejections >= self.settings.lockout_rejections:
                    lockout = True
                    self.lockouts += 1
                    self.window.clear()
                    self._last = None
                    self._rejections = 0
        if not self.window or odometer is None:
            return self._output(now, math.nan, math.inf, 0, rejected, not entered, lockout)
        x, cov = self.estimates(now, odometer.pulses)
        w = self._weights(x, cov)
        k = weighted_median(x, w)
        sigma = np.sqrt(np.diag(cov))
        sel = float(sigma[weighted_median(sigma, w)])
        pl = self.bound(sel)  # the median bound (module docstring)
        from_fix = bool(entered and self.bound(float(sigma[-1])) < pl)
        if from_fix:
            # this epoch's checked fix bounds tighter on its own
            k, sel = len(x) - 1, float(sigma[-1])
            pl = self.bound(sel)
        self._last = (now, odometer.pulses, float(x[k]), sel ** 2)
        if rejected:
            # Either the fix or the carried window is faulty (one fault at a time): bound both cases.
            pl = max(pl, abs(float(x[k]) - fix.position_m) + self.bound(fix.sigma_m))
        return self._output(now, float(x[k]), pl, len(x), rejected, not entered, lockout, from_fix, sel)

    def _passes(self, now: float, odometer: OdometerSample | None, fix: AlongTrackFix) -> bool:
        if self._last is None or odometer is None:
            return True
        t0, p0, x0, v0 = self._last
        inc = self._increment_m(p0, odometer.pulses)
        pred = x0 + inc
        var = v0 + self.odometer.increment_variance_m2(inc, now - t0) + fix.sigma_m ** 2
        return abs(fix.position_m - pred) <= self.settings.residual_gate_sigma * math.sqrt(var)

    def _gnss_alone(self, now: float, fix: AlongTrackFix | None) -> FusedPosition:
        if fix is None:
            return self._output(now, math.nan, math.inf, 0, False, True, False)
        return self._output(now, fix.position_m, self.bound(fix.sigma_m), 1, False, False, False,
                            sigma_m=fix.sigma_m)

    def _output(self, now, x, pl, n, rejected, odometry_only, lockout, from_fix=False,
                sigma_m=math.inf) -> FusedPosition:
        available = bool(math.isfinite(x) and pl < self.settings.alert_limit_m)
        alarm = bool(lockout or (self._was_available and not available))
        self._was_available = available
        return FusedPosition(now, self.method, x, pl, available, alarm, n, rejected, odometry_only, from_fix,
                             sigma_m)
