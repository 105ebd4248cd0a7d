"""Integrity allocated like a safety case: the hourly integrity risk divided over the independent
decisions of an hour and over the fault modes, giving K for the fault-free term and a per-fault bound
for each fault mode, per axis (along-track for mileage, cross-track for track discrimination), each
protection level judged against its own alert limit (not the 2-D HPL).

Budget (railway.md, Helmet project): integrity risk < 1e-9 /h, alert limit 1.7 m for track
discrimination (cross-track) and for odometry correction (along-track). The two axes are separate
hazards with separate requirement rows, so each axis carries the whole hourly budget.

Fault-free term: a share of the hourly risk, divided over the independent decisions per hour
(3600 s / max(epoch interval, error correlation time)); K is the two-sided Gaussian quantile of the
per-decision risk.

Fault terms: our float/fixed RTK solves one all-in-view solution and provides no subset solutions, so
solution separation is not available; each fault mode gets instead a per-fault bound with a stated
prior: PL_i = b_i + K_md,i * sigma, where b_i [m] is the largest bias on the axis the residual checks let
through for that fault and K_md,i the one-sided quantile of the allowed missed-detection probability
R_i / P_i (R_i the mode's share of the hourly risk, P_i its prior per hour). A mode whose prior is
already below its share needs no coverage (P_i * 1 <= R_i).  PL = max(fault-free, every covered mode).

The centre's bound on its own correction error (RTCM 4001, docs/correction-bound-message.md) enters as a
variance inflation: the per-satellite overbound sigmas are carried to the axis by the solution's gain
(`correction_sigma_on_axis`) and added in quadrature to the receiver's sigma before K is applied, in the
fault-free and in every fault term. A satellite used without a bound (NaN) makes the PL infinite: the
corrections are then unbounded, never exact (docs/decisions/0280-correction-error-bound.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# Hourly integrity risk per axis (railway.md: Helmet, track discrimination and odometry correction).
HOURLY_INTEGRITY_RISK = 1e-9
# Alert limits [m] per axis (railway.md: Helmet, AL 1.7 m for track discrimination and odometry).
ALONG_TRACK_ALERT_LIMIT_M = 1.7
CROSS_TRACK_ALERT_LIMIT_M = 1.7
# Epoch interval [s] of the onboard PVT (the simulator and the recorded runs give 1 Hz).
DEFAULT_EPOCH_INTERVAL_S = 1.0
# Error correlation time [s]: no measured value for the moving antenna yet (the 120 s of decision 0101 is
# the static base's multipath); taking the epoch interval counts every epoch independent, which
# overcounts decisions and so errs on the safe side (larger K).
DEFAULT_ERROR_CORRELATION_S = 1.0
# Share of the hourly risk for the fault-free term; the rest is split equally over the fault modes.
DEFAULT_FAULT_FREE_SHARE = 0.5
SECONDS_PER_HOUR = 3600.0


def gaussian_k(integrity_risk: float) -> float:
    """K with P(|N(0,1)| > K) = integrity_risk (two-sided), by bisection on erfc."""
    if not 0.0 < integrity_risk < 1.0:
        raise ValueError("integrity risk must be in (0, 1)")
    lo, hi = 0.0, 40.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if math.erfc(mid / math.sqrt(2.0)) > integrity_risk:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def one_sided_k(probability: float) -> float:
    """K with P(N(0,1) > K) = probability (one-sided: a bias pushes the error one way)."""
    return gaussian_k(2.0 * probability) if probability < 0.5 else 0.0


@dataclass(frozen=True)
class FaultMode:
    """A fault the residual checks may miss: its prior onset rate and the bias it can leave."""

    name: str
    prior_per_hour: float
    bias_along_m: float  # largest undetected bias on the along-track axis [m]
    bias_cross_m: float  # largest undetected bias on the cross-track axis [m]


# Stated priors: satellite fault 1e-5 /h per satellite (ARAIM ISM P_sat, EU-US ARAIM report 2016) over
# ~10 satellites in view; wrong correction from the centre 1e-5 /h (assumed, one station fault in a
# small network per ~10 years of operation); odometer slide 1e-4 /h (assumed; along-track only).
# Biases: the RTK residual check passes a phase blunder up to about 0.5 m before rejecting it (assumed
# from the 4-sigma residual gate on the float solution); slide bounded by the fusion's residual check.
DEFAULT_FAULT_MODES = (
    FaultMode("satellite", 1e-4, 0.5, 0.5),
    FaultMode("wrong correction", 1e-5, 0.3, 0.3),
    FaultMode("odometer slide", 1e-4, 0.5, 0.0),
)


@dataclass(frozen=True)
class IntegrityAllocation:
    hourly_risk: float = HOURLY_INTEGRITY_RISK
    epoch_interval_s: float = DEFAULT_EPOCH_INTERVAL_S
    correlation_time_s: float = DEFAULT_ERROR_CORRELATION_S
    fault_free_share: float = DEFAULT_FAULT_FREE_SHARE
    faults: tuple[FaultMode, ...] = field(default=DEFAULT_FAULT_MODES)

    def __post_init__(self) -> None:
        if not 0.0 < self.hourly_risk < 1.0 or not 0.0 < self.fault_free_share <= 1.0:
            raise ValueError("hourly risk in (0, 1) and fault-free share in (0, 1] required")
        if self.epoch_interval_s <= 0.0 or self.correlation_time_s < 0.0:
            raise ValueError("epoch interval must be positive, correlation time non-negative")

    @property
    def decisions_per_hour(self) -> float:
        return SECONDS_PER_HOUR / max(self.epoch_interval_s, self.correlation_time_s)

    @property
    def per_decision_risk(self) -> float:
        """Fault-free integrity risk per independent decision."""
        return self.hourly_risk * self.fault_free_share / self.decisions_per_hour

    @property
    def k_fault_free(self) -> float:
        return gaussian_k(self.per_decision_risk)

    @property
    def risk_per_fault_mode(self) -> float:
        """Hourly risk share of each fault mode."""
        if not self.faults:
            return 0.0
        return self.hourly_risk * (1.0 - self.fault_free_share) / len(self.faults)

    def k_missed_detection(self, mode: FaultMode) -> float | None:
        """One-sided K for the mode's allowed missed-detection probability; None when the prior alone
        is within the mode's share (no coverage needed)."""
        r = self.risk_per_fault_mode
        if mode.prior_per_hour <= r:
            return None
        return one_sided_k(r / mode.prior_per_hour)

    def fault_bound(self, sigma_m: float, axis: str, modes=None) -> float:
        """The largest per-fault bound b_i + K_md,i sigma on `axis` over the covered modes [m] (0: none);
        `sigma_m` is the whole 1-sigma (correction bound already in); `modes`: names to consider (None: all).
        PL = max(K_ff sigma, this)."""
        if axis not in ("along", "cross"):
            raise ValueError("axis must be 'along' or 'cross'")
        if not math.isfinite(sigma_m):
            return math.inf
        out = 0.0
        for mode in self.faults:
            if modes is not None and mode.name not in modes:
                continue
            k = self.k_missed_detection(mode)
            bias = mode.bias_along_m if axis == "along" else mode.bias_cross_m
            if k is not None and bias > 0.0:
                out = max(out, bias + k * sigma_m)
        return out

    def protection_level(self, sigma_m: float, axis: str, correction_sigma_m: float = 0.0) -> float:
        """Protection level [m] on `axis` ('along' or 'cross') for a 1-sigma error `sigma_m`, inflated by the
        centre's correction-error overbound sigma on that axis (`correction_sigma_on_axis`; 0: none sent)."""
        if axis not in ("along", "cross"):
            raise ValueError("axis must be 'along' or 'cross'")
        if not math.isfinite(sigma_m) or not math.isfinite(correction_sigma_m):
            return math.inf
        if correction_sigma_m < 0.0:
            raise ValueError("correction sigma must be non-negative")
        sigma_m = math.hypot(sigma_m, correction_sigma_m)  # independent of the receiver's own errors
        return max(self.k_fault_free * sigma_m, self.fault_bound(sigma_m, axis))


@dataclass(frozen=True)
class AxisDecision:
    along_pl_m: float
    cross_pl_m: float
    along_available: bool  # mileage usable: along-track PL within its alert limit
    cross_available: bool  # track discrimination usable: cross-track PL within its alert limit


def correction_sigma_on_axis(gain: np.ndarray, correction_sigma_m: np.ndarray) -> np.ndarray:
    """Sigma [m] the centre's correction errors add on an axis: sum_j |g_j| sigma_j over the satellites' DDs.

    `gain` (..., S): the axis row(s) of the solution's gain (position change per metre of each DD);
    `correction_sigma_m` (S,) or (..., S): the 4001 overbound sigmas. The standard deviation of a sum is at
    most the sum of the standard deviations (Minkowski), so no correlation between the DDs' correction
    errors (they share the reference satellite and the interpolation) needs assuming. A satellite with a
    non-zero gain and no bound (NaN) gives inf; one the solution does not use (gain 0) is ignored."""
    g = np.abs(np.asarray(gain, dtype=float))
    s = np.broadcast_to(np.asarray(correction_sigma_m, dtype=float), g.shape)
    if np.any(s[np.isfinite(s)] < 0.0):
        raise ValueError("correction sigmas must be non-negative")
    used = g > 0.0
    unbounded = (used & ~np.isfinite(s)).any(axis=-1)
    return np.where(unbounded, np.inf, np.sum(np.where(used, g * np.where(np.isfinite(s), s, 0.0), 0.0),
                                              axis=-1))


def axis_availability(sigma_along_m: float, sigma_cross_m: float,
                      allocation: IntegrityAllocation | None = None,
                      along_alert_limit_m: float = ALONG_TRACK_ALERT_LIMIT_M,
                      cross_alert_limit_m: float = CROSS_TRACK_ALERT_LIMIT_M,
                      correction_sigma_along_m: float = 0.0,
                      correction_sigma_cross_m: float = 0.0) -> AxisDecision:
    """Per-axis protection levels and availability, each against its own alert limit; the centre's
    correction-error sigma per axis (`correction_sigma_on_axis`) inflates each (0: no bound received)."""
    a = allocation or IntegrityAllocation()
    apl = a.protection_level(sigma_along_m, "along", correction_sigma_along_m)
    xpl = a.protection_level(sigma_cross_m, "cross", correction_sigma_cross_m)
    return AxisDecision(apl, xpl, apl <= along_alert_limit_m, xpl <= cross_alert_limit_m)


DEFAULT_ALLOCATION = IntegrityAllocation()
# The fault modes a GNSS fix alone can carry (the odometer slide is the fusion's): what `trackmap.match`
# bounds a fix's PL by, with the shares of the whole allocation (decision 0253 applies decision 0250's terms).
GNSS_FAULT_MODES = ("satellite", "wrong correction")
# Per-decision fault-free integrity risk the onboard core uses for K (replaces the per-epoch 1e-7).
ALLOCATED_PER_DECISION_RISK = DEFAULT_ALLOCATION.per_decision_risk
