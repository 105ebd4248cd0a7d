"""Real-time kinematic positioning: an extended Kalman filter on double differences, with integer
ambiguity resolution (LAMBDA, partial fixing, ratio test and bootstrapped success rate) and
fix-and-hold.

State: rover ECEF position (and velocity and acceleration when the dynamic model is on), then one
*single-difference* (rover minus base) carrier ambiguity per satellite and frequency slot, in
cycles.  Measurements are double differences (per system and slot, against that group's highest
satellite) of phase and code; forming DDs in the measurement model rather than in the state lets
satellites rise and set and the reference change without touching the state.

Atmosphere.  The troposphere model is applied at each receiver.  On a short baseline (under ~7 km) the
DD ionosphere is millimetres and is not modelled: the filter fixes from the first epoch.  Against a
network VRS (RINEX MARKER TYPE NON_PHYSICAL, RTCM DF141 = 1) or a longer baseline the filter is
*ionosphere-weighted*: one SD ionospheric delay per satellite is a state with a prior of sigma0 times
the thin-shell mapping function (sigma0 2 cm for a VRS -- the network's interpolation residual --
or 2 mm per km of baseline), phase sees -mu I and code +mu I, and code is weighted down (300:1) since
the base's multipath is correlated over minutes.  A relative zenith troposphere state was tried and
left out: over a minute it cannot be told from the height (network-70km VRS: V95 1.9 -> 4.4 cm) and
the VRS's non-dispersive DD residuals measured there are ~0.5 cm.

Validation.  LAMBDA with partial fixing (the largest decorrelated block with a bootstrapped success
rate >= 0.999 that passes the ratio test), a fixed position sigma <= 3 cm, DD phase residuals <= 5 cm
after fixing (else the worst satellite is left out and the search repeated; with the ionosphere
estimated, the lowest satellite), and with the ionosphere in the model a fix is declared only when
3 consecutive epochs' validated integer decisions agree: a partial fix that passed every test but pins
too few combinations for the 3 cm (the wide-lane-like ones come first) is such a decision, the fix
declared is a complete one (network-70km VRS switch-ons: median time to first fix 11 -> 9 s); a
satellite whose ambiguity restarted (a slip) is, like a rising one, left out of the comparison.  The
rover losing lock (overbridge, tunnel, up to a minute) keeps its SD ionosphere states, grown by their
random walk over the outage: the new ambiguities are fixed against them (demo re-fixes 7 -> 2 s).
Fix-and-hold after 5 declared fixes.
The covariance of a fixed solution is the float covariance conditioned on the fixed combinations, so
it carries the estimated ionosphere's uncertainty: protection levels K sigma bound the error in
every simulated epoch measured (baseline-10km, network-70km with a VRS under quiet to active
ionosphere, single-base 35 km).

Status per epoch (RTKLIB's Q codes so tools compare): FIX (1) when a validated integer set is
applied, FLOAT (2), SINGLE (5) when the rover falls back to SPP (no or stale corrections, base
inconsistent, filter diverged), NONE (0) when not even SPP is possible.  `step` never raises on
data; each solution carries a message saying why it is what it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Sequence

import numpy as np
from numba import njit
from threadpoolctl import ThreadpoolController

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ambiguity import (
    AmbiguityError,
    PartialFix,
    reduce,
    search,
)
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.ionosphere import thin_shell_mapping
from augnet.onboard.atmosphere import saastamoinen_m
from augnet.onboard.cycleslip import BASE_GF_DRIFT_M_S, BASE_GF_SLIP_THRESHOLD_M, SlipDetector
from augnet.onboard.observations import BAND_FREQ_HZ, SYSTEM_BANDS, EpochObs
from augnet.onboard.spp import (
    SELECTION_CACHE_S,
    SatPositions,
    SppOptions,
    SppResult,
    azimuth_elevation_from,
    chi2_quantile,
    doppler_velocity,
    first_code,
    geometric_range,
    receiver_frame,
    satellite_positions,
    solve_spp,
)


class Status(IntEnum):
    NONE = 0
    FIX = 1
    FLOAT = 2
    SINGLE = 5


# Carrier-phase noise sigma^2 = a^2 + b^2/sin^2(el) per receiver [m] (RTKLIB's defaults, typical of
# geodetic and good automotive receivers); code noise is the phase noise times this ratio.
PHASE_SIGMA_A_M = 0.003
PHASE_SIGMA_B_M = 0.003
CODE_PHASE_ERROR_RATIO = 100.0
# ... and with the ionosphere estimated (VRS, medium baselines): code then also carries the base's (for
# a VRS, the master station's) multipath, correlated over minutes on a static antenna, which a filter
# treating code as white noise would trust too much; its float would sit tens of cm off with a
# covariance claiming a few, and the integer search would fail or fix wrongly.  300 is RTKLIB EX's
# default (demo5 eratio1); measured on network-70km with the centre's VRS, 8 starts: median time to
# first fix 15 -> 8 s, fixed after the first fix 87 -> 100 %.
CODE_PHASE_ERROR_RATIO_WITH_IONOSPHERE = 300.0
# Initial standard deviations of new states.
INIT_POSITION_SIGMA_M = 30.0
INIT_VELOCITY_SIGMA_M_S = 10.0
INIT_ACCELERATION_SIGMA_M_S2 = 10.0
INIT_AMBIGUITY_SIGMA_CYC = 30.0
# Random-walk process noise of a single-difference ambiguity [cycles / sqrt(s)].
AMBIGUITY_PROCESS_SIGMA_CYC = 1e-4
# Acceleration process noise (white jerk) [m/s^2 / sqrt(s)]: horizontal and vertical.  A train
# brakes at ~1 m/s^2 and accelerates slower; a road vehicle changes faster, hence 3 by default.
ACCEL_PROCESS_SIGMA_H = 3.0
ACCEL_PROCESS_SIGMA_V = 1.0
# Corrections older than this are stale: RTK is abandoned for SPP.  Network RTK practice: corrections
# normally arrive under 2 s old and must stay under 5 s (../shared/design/network-rtk.md); in
# post-processing a missing base epoch simply ages the last one.
DEFAULT_MAX_AGE_S = 5.0
# Beyond this baseline [m] the short-baseline model (no DD ionosphere) breaks down; also, a base
# position given wrong by more than this cannot be RTK'd against.
DEFAULT_MAX_BASELINE_M = 100_000.0
# The base's own SPP must agree with its given coordinates within this [m], or the coordinates (or
# the base data) are wrong and a "fixed" rover would be wrong by the same amount.
BASE_POSITION_TOLERANCE_M = 100.0
# ... measured by this many SPP steps from the given coordinates (the first step lands within a
# millimetre of the converged solution when the coordinates are within a few hundred metres, and
# anything farther fails the check anyway; the second makes the step size itself a small number)
BASE_CHECK_SPP_STEPS = 2
ROVER_SPP_STEPS = 2
# Prefit screening: code DD innovations beyond this [m] are blunders; a phase DD whose ambiguity is
# already known (sigma below AMB_KNOWN_SIGMA_CYC) and whose innovation exceeds
# max(PHASE_INNOVATION_SIGMAS * sigma, PHASE_INNOVATION_MIN_M) is a slip the detectors missed.
MAX_CODE_INNOVATION_M = 30.0
PHASE_INNOVATION_SIGMAS = 6.0
PHASE_INNOVATION_MIN_M = 0.10
AMB_KNOWN_SIGMA_CYC = 0.5
# Phase observations of a satellite not updated for more epochs than this lose their ambiguity.
MAX_AMBIGUITY_OUTAGE_EPOCHS = 5
# An SD ionosphere state not observed for longer than this [s] is dropped.  It is an atmospheric quantity,
# not a tracking one: across a shorter outage (an overbridge, a tunnel, a satellite behind a cutting) it
# is kept with the uncertainty its random walk has gathered (IONO_PROCESS_FRACTION_PER_SQRT_S: 23 % of
# its prior sigma after a minute), and a satellite re-acquired with new ambiguities is fixed against it.
MAX_IONO_OUTAGE_S = 60.0
# Fix-and-hold: after this many consecutive fixes the integers are fed back into the float filter
# as pseudo-observations with this variance [cycles^2] (RTKLIB uses 0.001 cycle^2 as well).
HOLD_AFTER_FIXES = 5
HOLD_VARIANCE_CYC2 = 0.001
# A time step longer than this [s] restarts the position/velocity part of the filter.
MAX_PREDICTION_GAP_S = 30.0
# Redo the measurement update linearised at the updated position when it landed farther than this [m]
# from the linearisation point (tropospheric delay changes ~0.3 mm per metre of height: 5 cm of
# linearisation error is ~15 um).
RELINEARISE_M = 0.05
# A white-noise kinematic rover is linearised at its last solution carried by its velocity when that
# is at most this old [s] (else at the state's position, i.e. SPP).
MAX_LINEARISATION_PREDICTION_S = 5.0
# ... and, when enough DD phases have established ambiguities (their sigma from the ambiguity and
# ionosphere states below this [m]: held after a fix), at the position those phases give if their
# residuals agree to this RMS [m].
LINEARISATION_SIGMA_M = 0.01
LINEARISATION_MIN_ROWS = 6
LINEARISATION_MAX_RMS_M = 0.03
# Fixed solutions failing the residual check are retried this many times, each without the worst
# satellite (RTKLIB-EX and commercial engines exclude satellites the same way).
AR_EXCLUSION_RETRIES = 3
# A fixed solution must have a 3-D position sigma below this [m] (a fix that only pins a few
# ambiguity combinations leaves decimetres: it is still a float solution; with 3 cm the vertical
# sigma of a fix stays under ~2.5 cm, what a 4 cm vertical 95 % figure needs).
MAX_FIXED_POSITION_SIGMA_M = 0.03
# Partial ambiguity resolution tries at most this many nested subsets per search: each integer
# search costs up to ~0.5 s in Python on a poor float solution, and a rover must keep up with 1 Hz.
MAX_PARTIAL_FIX_TRIES = 8
# False-alarm probability of the chi-square test that a float ambiguity vector is consistent with
# its covariance (the bootstrapped solution's norm), before an integer search is spent on it.
FLOAT_CONSISTENCY_FALSE_ALARM = 1e-6
# ... and the RMS of the conditional fractional parts [cycles] beyond which it is called biased: with a
# success rate >= 0.999 every conditional sigma is below ~0.15 cycles, so 0.2 is well outside noise.
BIASED_FLOAT_RMS_CYC = 0.2
# The float position may differ from the epoch's SPP by the SPP's error; beyond this [m] plus five
# SPP sigmas the filter has gone wrong.
SPP_CONSISTENCY_M = 30.0
# Fixed solutions whose DD phase residuals exceed this [m] are rejected (wrong fix).
MAX_FIXED_PHASE_RESIDUAL_M = 0.05
# Ionosphere-weighted model (medium baselines and network VRS).  The single-difference (rover - base)
# ionospheric delay on each satellite's first frequency is a state with a prior sigma of
# sigma0 * M(el), M the thin-shell mapping function; phase sees -mu I and code +mu I, mu = (f1/f)^2.
# sigma0 for a physical base grows with the baseline: 3 mm per km (RTKLIB's default 0.03 m per 10 km;
# quiet mid-latitude DD ionosphere is 1-4 ppm, network-rtk.md).  For a network VRS it is the network's
# interpolation residual: 1-3 cm DD at 30-70 km spacing (network-rtk.md: Tang et al. 2016; "better than
# 3 cm under 100 km"), i.e. about 2 cm single-difference.
IONO_SIGMA_PER_M = 2.0e-6
VRS_IONO_SIGMA_M = 0.02
# Below this prior sigma [m] (baselines under ~5 km) the DD ionosphere is left out of the model: the
# short-baseline model is then exact to millimetres and fixes from the first epoch.
IONO_ESTIMATE_MIN_SIGMA_M = 0.015
# Random walk of the SD ionosphere, as a fraction of sigma0 per sqrt(s): a 2 cm VRS residual may drift
# by ~1 cm over 100 s (the interpolation error changes with the satellites' pierce points).
IONO_PROCESS_FRACTION_PER_SQRT_S = 0.03
# With the ionosphere in the model, a validated fix is declared only when the same integers have been
# found in this many consecutive epochs (a biased float can pass one epoch's tests by chance).
CONFIRM_EPOCHS_WITH_IONOSPHERE = 3
# A DD ambiguity counts as determined by a fix when its conditional sigma is below this [cycles].
CONFIRM_SIGMA_CYC = 0.05
SOLUTION_STATUS_NAMES = {Status.NONE: "none", Status.FIX: "fix", Status.FLOAT: "float", Status.SINGLE: "single"}


@dataclass
class RtkOptions:
    mode: str = "kinematic"  # 'kinematic' or 'static'
    dynamics: bool = False  # kinematic only: position-velocity-acceleration model (else white position)
    elevation_mask_rad: float = math.radians(15.0)
    systems: Sequence[str] = ("G", "E", "C", "J")
    n_slots: int = 2
    phase_sigma_a_m: float = PHASE_SIGMA_A_M
    phase_sigma_b_m: float = PHASE_SIGMA_B_M
    code_phase_ratio: float | None = None  # None: CODE_PHASE_ERROR_RATIO, or ..._WITH_IONOSPHERE
    ratio_threshold: float = 3.0
    min_success_rate: float = 0.999
    min_fix_ambiguities: int = 4
    fix_and_hold: bool = True
    ambiguity_resolution: bool = True
    max_age_s: float = DEFAULT_MAX_AGE_S
    max_baseline_m: float = DEFAULT_MAX_BASELINE_M
    # 'auto': estimate the SD ionosphere per satellite for a VRS or beyond ~5 km; 'estimate': always;
    # 'off': never (the short-baseline model)
    ionosphere: str = "auto"
    iono_sigma_m: float | None = None  # prior sigma of the SD vertical ionosphere [m]; None: from the base
    vrs_iono_sigma_m: float = VRS_IONO_SIGMA_M
    confirm_epochs: int | None = None  # consecutive agreeing fixes before FIX; None: 1, or 3 with ionosphere
    accel_sigma_h: float = ACCEL_PROCESS_SIGMA_H
    accel_sigma_v: float = ACCEL_PROCESS_SIGMA_V
    spp: SppOptions = field(default_factory=SppOptions)


@dataclass
class RtkSolution:
    time: float
    status: Status
    position_m: np.ndarray  # (3,) ECEF
    covariance_m2: np.ndarray  # (3, 3) ECEF
    n_sats: int = 0  # satellites used (with both receivers' data for RTK)
    ratio: float = 0.0
    success_rate: float = 0.0
    n_fixed: int = 0  # ambiguities (decorrelated combinations) fixed
    age_s: float = math.nan
    baseline_m: float = math.nan
    velocity_m_s: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    message: str = ""
    # a FIX: (satellite, reference satellite, frequency slot) -> integer DD ambiguity [cycles] of every DD
    # ambiguity the fix determines (conditional sigma below CONFIRM_SIGMA_CYC), for checks against a truth
    fixed_dd: dict[tuple[str, str, int], int] = field(default_factory=dict)

    @property
    def status_name(self) -> str:
        return SOLUTION_STATUS_NAMES[self.status]


@dataclass
class _Group:
    """The DD rows of one system and slot at one epoch."""
    sats: list[int]  # indices into the epoch's satellite list; first is the reference
    slot: int


@dataclass
class _DD:
    """One epoch's double differences as parallel index arrays (one entry per non-reference satellite
    and slot): epoch satellite indices, slot, group, and the state indices of the SD ambiguities and
    (when estimated) SD ionospheres involved."""
    k: np.ndarray
    ref: np.ndarray
    f: np.ndarray
    group: np.ndarray
    i: np.ndarray
    iref: np.ndarray
    ion: np.ndarray | None
    ion_ref: np.ndarray | None


def _first_wavelength(system: str) -> float:
    """Wavelength [m] of a system's first frequency (slot 0: L1, E1, B1I), the ionosphere's reference."""
    return SPEED_OF_LIGHT_M_S / BAND_FREQ_HZ[(system, SYSTEM_BANDS[system][0])]


class RtkFilter:
    """The rover's RTK engine.  Feed it epochs with `step`; it keeps its own state between them."""

    def __init__(self, nav: NavigationData, base_position_m, options: RtkOptions | None = None,
                 base_is_vrs: bool = False):
        self.nav = nav
        self.opt = options or RtkOptions()
        self.base_position_m = np.asarray(base_position_m, dtype=float)
        # a computed (non-physical) base, a network VRS: its residual atmosphere is modelled
        self.base_is_vrs = bool(base_is_vrs)
        self.ion_index: dict[str, int] = {}
        self.ion_seen: dict[str, float] = {}  # when each SD ionosphere state was last observed
        self.iono_active = False
        self._iono_sigma_now = 0.0
        self._candidate: tuple | None = None  # the last validated integer decision (see `_decision`)
        self._candidate_count = 0
        self._last_solution: tuple[float, np.ndarray, np.ndarray] | None = None
        self._spp_inputs: tuple | None = None
        self.n_kin = 9 if (self.opt.mode == "kinematic" and self.opt.dynamics) else 3
        self.x = np.zeros(self.n_kin)
        self.P = np.zeros((self.n_kin, self.n_kin))
        self.amb_index: dict[tuple[str, int], int] = {}
        self._free: list[int] = []
        self.amb_outage: dict[tuple[str, int], int] = {}
        # a serial number per ambiguity state: a slip re-initialises it under the same key, a new arc
        self.amb_serial: dict[tuple[str, int], int] = {}
        self._serials = 0
        self.initialised = False
        self.t_prev = math.nan
        self.rover_slips = SlipDetector()
        self.base_slips = SlipDetector(gf_threshold_m=BASE_GF_SLIP_THRESHOLD_M, gf_drift_m_s=BASE_GF_DRIFT_M_S)
        self.consecutive_fixes = 0
        self.last_fix: tuple[PartialFix, np.ndarray, np.ndarray] | None = None
        self._base_checked_time = math.nan
        self._base_ok = True
        self._base_msg = ""

    # -----------------------------------------------------------------------------------------
    # state bookkeeping

    def reset(self) -> None:
        self.__init__(self.nav, self.base_position_m, self.opt, self.base_is_vrs)

    def _new_amb(self, key, value, var) -> int:
        i = self._new_state(value, var)
        self.amb_index[key] = i
        self.amb_outage[key] = 0
        self._serials += 1
        self.amb_serial[key] = self._serials
        return i

    def _new_ion(self, sat: str, var: float, t: float) -> int:
        i = self._new_state(0.0, var)
        self.ion_index[sat] = i
        self.ion_seen[sat] = t
        return i

    def _drop_ion(self, sat: str) -> None:
        i = self.ion_index.pop(sat, None)
        self.ion_seen.pop(sat, None)
        if i is not None:
            self._free_state(i)

    def _new_state(self, value, var) -> int:
        if self._free:
            i = self._free.pop()
        else:
            i = len(self.x)
            self.x = np.append(self.x, 0.0)
            P = np.zeros((i + 1, i + 1))
            P[:i, :i] = self.P
            self.P = P
        self.x[i] = value
        self.P[i, :] = 0.0
        self.P[:, i] = 0.0
        self.P[i, i] = var
        return i

    def _free_state(self, i: int) -> None:
        self.x[i] = 0.0
        self.P[i, :] = 0.0
        self.P[:, i] = 0.0
        self._free.append(i)

    def _drop_amb(self, key) -> None:
        i = self.amb_index.pop(key, None)
        self.amb_outage.pop(key, None)
        self.amb_serial.pop(key, None)
        if i is not None:
            self._free_state(i)

    # -----------------------------------------------------------------------------------------

    def step(self, rover: EpochObs, base: EpochObs | None) -> RtkSolution:
        """Process one rover epoch with the latest base epoch (None when there is none).

        The age of corrections is rover time minus base time; over `max_age_s` the status is SINGLE.
        """
        if not np.isfinite(rover.time):
            return RtkSolution(math.nan, Status.NONE, np.full(3, np.nan), np.full((3, 3), np.nan),
                               message="rover epoch without a valid time")
        rover = rover.sanitised()
        if base is not None:
            base = base.sanitised() if np.isfinite(base.time) else None
        try:
            # Small matrices: BLAS threads cost far more than they save (15x slower on 2 busy cores).
            with _blas_controller().limit(limits=1, user_api="blas"):
                return self._step(rover, base)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError, AmbiguityError) as exc:
            # Numbers that break the filter: restart it and say so; the next epoch starts afresh.
            self.reset()
            spp = solve_spp(rover, self.nav, self._spp_options())
            return self._single(rover.time, spp, f"filter reset after numerical failure: {exc}")

    def _spp_options(self) -> SppOptions:
        o = self.opt.spp
        o.systems = tuple(self.opt.systems)
        return o

    def _single(self, t, spp: SppResult, msg: str, age=math.nan) -> RtkSolution:
        if spp.ok and not spp.converged and self._spp_inputs is not None:
            rover, sp_rover, initial = self._spp_inputs
            spp = solve_spp(rover, self.nav, self._spp_options(), initial_m=initial, sat_positions=sp_rover)
        if spp.ok:
            return RtkSolution(t, Status.SINGLE, spp.position_m, spp.covariance_m2, spp.n_used, age_s=age,
                               message=msg if not spp.message else f"{msg}; {spp.message}")
        return RtkSolution(t, Status.NONE, np.full(3, np.nan), np.full((3, 3), np.nan), 0, age_s=age,
                           message=f"{msg}; {spp.message}")

    def _step(self, rover: EpochObs, base: EpochObs | None) -> RtkSolution:
        opt = self.opt
        t = rover.time
        # satellite states once per receiver and epoch, shared by SPP, RTK and the Doppler velocity
        sp_rover = satellite_positions(self.nav, rover.sats, t, first_code(rover))
        # From the filter's position (within metres of the code solution) two SPP steps are exact to a
        # fraction of a millimetre, all RTK needs of it (a prior of 30 m, a 30 m consistency check); a
        # SINGLE solution, which reports the SPP itself, iterates it to convergence (see `_single`).
        initial = self.x[:3].copy() if self.initialised else None
        self._spp_inputs = (rover, sp_rover, initial)
        spp = solve_spp(rover, self.nav, self._spp_options(), initial_m=initial, sat_positions=sp_rover,
                        steps=ROVER_SPP_STEPS if initial is not None else None)
        if not spp.ok and self.initialised:
            # the filter's position may be the problem
            spp = solve_spp(rover, self.nav, self._spp_options(), sat_positions=sp_rover)
        if base is None:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, "no base observations")
        age = t - base.time
        if not np.isfinite(age) or age < -0.5 or age > opt.max_age_s:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, f"corrections stale: age {age:.1f} s over {opt.max_age_s:.1f} s", age)
        if not spp.ok and not self.initialised:
            return self._single(t, spp, "no rover position to start from", age)
        # Base satellites with the rover's ephemeris selection (both ends use the same issue of data).
        sp_base = satellite_positions(self.nav, base.sats, base.time, first_code(base), t_select=t)
        # The base's coordinates must be consistent with its data (checked once per base epoch).
        if base.time != self._base_checked_time:
            self._base_checked_time = base.time
            # its own SPP selects ephemerides at its own time: the same states when that is the same choice
            same_selection = math.floor(base.time / SELECTION_CACHE_S) == math.floor(t / SELECTION_CACHE_S)
            bspp = solve_spp(base, self.nav, self._spp_options(), initial_m=self.base_position_m,
                             sat_positions=sp_base if same_selection else None, steps=BASE_CHECK_SPP_STEPS)
            if bspp.ok:
                d = float(np.linalg.norm(bspp.position_m - self.base_position_m))
                self._base_ok = d <= BASE_POSITION_TOLERANCE_M
                self._base_msg = f"base position inconsistent with base data by {d:.0f} m"
            else:
                self._base_ok, self._base_msg = True, ""
        if not self._base_ok:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, self._base_msg, age)
        ref_pos = spp.position_m if spp.ok else self.x[:3]
        baseline = float(np.linalg.norm(ref_pos - self.base_position_m))
        if baseline > opt.max_baseline_m:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, f"baseline {baseline / 1e3:.0f} km beyond {opt.max_baseline_m / 1e3:.0f} km", age)

        self._time_update(t, spp)
        sol = self._measurement_update(rover, base, spp, age, baseline, sp_rover, sp_base)
        return sol

    # -----------------------------------------------------------------------------------------
    # time update

    def _time_update(self, t: float, spp: SppResult, advance_only: bool = False) -> None:
        dt = t - self.t_prev if np.isfinite(self.t_prev) else math.inf
        self.t_prev = t
        nk = self.n_kin
        # ambiguity random walk
        if np.isfinite(dt) and dt > 0:
            for i in self.amb_index.values():
                self.P[i, i] += AMBIGUITY_PROCESS_SIGMA_CYC**2 * dt
            q_ion = (IONO_PROCESS_FRACTION_PER_SQRT_S * self._iono_sigma_now) ** 2 * dt
            for i in self.ion_index.values():
                self.P[i, i] += q_ion
        if advance_only and not self.initialised:
            return
        restart = (not self.initialised) or dt > MAX_PREDICTION_GAP_S or dt <= 0
        if self.opt.mode == "static" and not restart:
            return
        if self.opt.mode == "kinematic" and self.n_kin == 3 or restart:
            # white position (RTKLIB's 'dynamics off'): start from SPP every epoch
            if not spp.ok:
                if not self.initialised:
                    return
                if restart or self.n_kin == 3:
                    # no fresh position: keep the old one with a generous uncertainty
                    self.P[:3, :] = 0.0
                    self.P[:, :3] = 0.0
                    self.P[:3, :3] = np.eye(3) * INIT_POSITION_SIGMA_M**2
                    return
            else:
                self.x[:3] = spp.position_m
                self.P[:nk, :] = 0.0
                self.P[:, :nk] = 0.0
                self.P[:3, :3] = np.eye(3) * INIT_POSITION_SIGMA_M**2
                if nk == 9:
                    self.x[3:9] = 0.0
                    self.P[3:6, 3:6] = np.eye(3) * INIT_VELOCITY_SIGMA_M_S**2
                    self.P[6:9, 6:9] = np.eye(3) * INIT_ACCELERATION_SIGMA_M_S2**2
                self.initialised = True
                return
        if nk == 9:
            F = np.eye(9)
            F[0:3, 3:6] = np.eye(3) * dt
            F[0:3, 6:9] = np.eye(3) * 0.5 * dt * dt
            F[3:6, 6:9] = np.eye(3) * dt
            self.x[:9] = F @ self.x[:9]
            Pk = self.P[:9, :9]
            Pka = self.P[:9, 9:]
            self.P[:9, :9] = F @ Pk @ F.T
            self.P[:9, 9:] = F @ Pka
            self.P[9:, :9] = self.P[:9, 9:].T
            # white-jerk noise on acceleration, in local ENU then rotated to ECEF
            _, R = receiver_frame(self.x[:3])
            q = R.T @ np.diag([self.opt.accel_sigma_h**2, self.opt.accel_sigma_h**2, self.opt.accel_sigma_v**2]) @ R
            # continuous white jerk integrated over dt: the exact discrete Q of the PVA model
            self.P[6:9, 6:9] += q * dt
            self.P[3:6, 3:6] += q * dt**3 / 3.0
            self.P[0:3, 0:3] += q * dt**5 / 20.0
            self.P[3:6, 6:9] += q * dt**2 / 2.0
            self.P[6:9, 3:6] += q * dt**2 / 2.0
            self.P[0:3, 6:9] += q * dt**3 / 6.0
            self.P[6:9, 0:3] += q * dt**3 / 6.0
            self.P[0:3, 3:6] += q * dt**4 / 8.0
            self.P[3:6, 0:3] += q * dt**4 / 8.0

    # -----------------------------------------------------------------------------------------
    # measurement update

    def _zero_diff(self, obs: EpochObs, rx_m: np.ndarray, sp):
        """Observed minus modelled (range, troposphere, satellite clock) per satellite and slot [m],
        for phase and code, and the line-of-sight unit vectors and elevations."""
        rng, los = geometric_range(np.where(sp.valid[:, None], sp.position_m, rx_m + 1.0), rx_m)
        llh, rot = receiver_frame(rx_m)
        az, el = azimuth_elevation_from(rx_m, rot, np.where(sp.valid[:, None], sp.position_m, rx_m + np.array([0, 0, 1.0])))
        trop = saastamoinen_m(llh[0], llh[2], el)
        model = rng + trop - SPEED_OF_LIGHT_M_S * sp.clock_s
        phase = obs.phase_cyc * obs.wavelength_m - model[:, None]
        code = obs.code_m - model[:, None]
        return phase, code, los, el

    def _variance(self, el: np.ndarray) -> np.ndarray:
        s = np.maximum(np.sin(el), 0.05)
        return self.opt.phase_sigma_a_m**2 + self.opt.phase_sigma_b_m**2 / s**2

    def _iono_sigma0(self, baseline_m: float) -> float:
        """Prior sigma [m] of the single-difference (rover - base) vertical ionospheric delay on the
        first frequency: the user's figure, a network VRS's residual, or growing with the baseline."""
        if self.opt.iono_sigma_m is not None:
            return float(self.opt.iono_sigma_m)
        if self.base_is_vrs:
            return float(self.opt.vrs_iono_sigma_m)
        return IONO_SIGMA_PER_M * baseline_m

    def _measurement_update(self, rover: EpochObs, base: EpochObs, spp: SppResult, age: float,
                            baseline_m: float, sp_rover: SatPositions, sp_base: SatPositions) -> RtkSolution:
        opt = self.opt
        t = rover.time
        # common satellites
        common, ri, bi = np.intersect1d(rover.sats, base.sats, return_indices=True)
        sysmask = np.isin(np.array([s[0] for s in common]), list(opt.systems))
        common, ri, bi = common[sysmask], ri[sysmask], bi[sysmask]
        rslip = self.rover_slips.detect(rover)
        bslip = self.base_slips.detect(base)
        nf = min(opt.n_slots, rover.n_slots, base.n_slots)
        if len(common) == 0:
            return self._float_or_single(t, spp, age, 0, "no satellites common to rover and base")
        ro = rover.take(ri)
        bo = base.take(bi)
        slips = rslip[ri, :nf] | bslip[bi, :nf]
        sp_r = _take(sp_rover, ri)
        sp_b = _take(sp_base, bi)
        valid = sp_r.valid & sp_b.valid
        # same issue of data at both ends, or the orbit error does not cancel
        valid &= sp_r.ephemeris_index == sp_b.ephemeris_index
        phase_b, code_b, _, el_b = self._zero_diff(bo, self.base_position_m, sp_b)
        wl = ro.wavelength_m[:, :nf]
        same_wl = np.isclose(wl, bo.wavelength_m[:, :nf], rtol=0, atol=1e-9)
        sats = [str(s) for s in ro.sats]
        sys_ = np.array([s[0] for s in sats])
        # ionospheric scale of each slot against the system's first frequency: (f1 / f)^2
        mu = (wl / np.array([_first_wavelength(s) for s in sys_])[:, None]) ** 2

        # handle slips: reset those ambiguities, and the satellite's ionosphere when every slot of the
        # base slipped (a VRS whose data for it were re-synthesised steps by the correction).  The rover
        # losing lock (an overbridge, a tunnel) changes its ambiguities, not the atmosphere: the SD
        # ionosphere state is kept, with the uncertainty it has gathered (random walk) over the outage,
        # and the new ambiguities are resolved against it.
        base_all = bslip[bi, :nf].all(axis=1)
        for k, sat in enumerate(sats):
            for f in range(nf):
                if slips[k, f]:
                    self._drop_amb((sat, f))
            if self.iono_active and base_all[k]:
                self._drop_ion(sat)
        # outage bookkeeping
        for key in list(self.amb_outage):
            self.amb_outage[key] += 1
            if self.amb_outage[key] > MAX_AMBIGUITY_OUTAGE_EPOCHS:
                self._drop_amb(key)
        for sat, seen in list(self.ion_seen.items()):
            if not t - seen <= MAX_IONO_OUTAGE_S:
                self._drop_ion(sat)

        # linearisation point: the state's position, or for a white-noise position (kinematic without
        # dynamics, restarted from SPP every epoch) the last solution carried by its velocity, usually
        # within centimetres of where this update lands, so one linearisation serves
        x_rov = self._predicted_position(t)
        phase_r, code_r, los_r, el_r = self._zero_diff(ro, x_rov, sp_r)
        ok_sat = valid & (el_r >= opt.elevation_mask_rad) & np.isfinite(el_b)
        sd_phase = phase_r[:, :nf] - phase_b[:, :nf]
        sd_code = code_r[:, :nf] - code_b[:, :nf]
        ok = ok_sat[:, None] & np.isfinite(sd_phase) & np.isfinite(sd_code) & same_wl & np.isfinite(wl)
        var_sd = (self._variance(el_r) + self._variance(el_b))[:, None] * np.ones((1, nf))
        # ionosphere: switched on for a VRS or a baseline long enough to need it, then kept
        sigma0 = self._iono_sigma0(baseline_m)
        if opt.ionosphere == "estimate" or (opt.ionosphere == "auto" and sigma0 >= IONO_ESTIMATE_MIN_SIGMA_M):
            self.iono_active = True
        self._iono_sigma_now = sigma0
        # initialise missing ambiguities from code (cycles), and missing ionospheres at their prior
        obs_sd_cyc = (ro.phase_cyc[:, :nf] - bo.phase_cyc[:, :nf]) - (ro.code_m[:, :nf] - bo.code_m[:, :nf]) / wl
        for k, f in zip(*np.nonzero(ok)):
            key = (sats[k], int(f))
            if key not in self.amb_index:
                self._new_amb(key, obs_sd_cyc[k, f], INIT_AMBIGUITY_SIGMA_CYC**2)
        if self.iono_active:
            mapping = thin_shell_mapping(el_r)
            for k in np.flatnonzero(ok.any(axis=1)):
                if sats[k] not in self.ion_index:
                    self._new_ion(sats[k], (sigma0 * mapping[k]) ** 2, t)
        groups = self._groups(sats, sys_, ok, el_r, nf)
        n_sat_used = len({k for g in groups for k in g.sats})
        if not groups:
            return self._float_or_single(t, spp, age, 0, "too few common satellites above the mask")
        dd = self._dd_index(groups, sats, nf)
        v, H, R, kind = self._build_rows(dd, sd_phase, sd_code, los_r, wl, mu, var_sd)
        v = v - H[:, :3] @ (self.x[:3] - x_rov)  # innovations against the prior state
        # prefit screening
        S_diag = np.einsum("ij,ij->i", H @ self.P, H) + np.diag(R)
        m = len(dd.k)
        phase_v = v[:m]
        amb_sig2 = self.P[dd.i, dd.i]
        known = amb_sig2 < AMB_KNOWN_SIGMA_CYC**2
        bad_ph = known & (np.abs(phase_v) > np.maximum(PHASE_INNOVATION_SIGMAS * np.sqrt(S_diag[:m]), PHASE_INNOVATION_MIN_M))
        if np.any(bad_ph):
            # a slip: re-initialise the ambiguities involved and rebuild (the reference slipping
            # shows as most of its group's rows failing together)
            for key in self._slipped_keys(bad_ph, dd, sats):
                self._drop_amb(key)
                k = sats.index(key[0])
                self._new_amb(key, obs_sd_cyc[k, key[1]], INIT_AMBIGUITY_SIGMA_CYC**2)
            dd = self._dd_index(groups, sats, nf)
            v, H, R, kind = self._build_rows(dd, sd_phase, sd_code, los_r, wl, mu, var_sd)
            v = v - H[:, :3] @ (self.x[:3] - x_rov)
        keep = ~((kind == 0) & (np.abs(v) > MAX_CODE_INNOVATION_M))
        if not keep.all():
            v, H, R = v[keep], H[keep], R[np.ix_(keep, keep)]
        # With established ambiguities the phases alone place the rover to millimetres: linearise there
        # (a 3-unknown least squares) rather than after a first full update from the SPP prior.
        x_phase = self._phase_position(v, H, R, kind[keep], x_rov)
        if x_phase is not None and np.linalg.norm(x_phase - x_rov) > RELINEARISE_M:
            x_rov = x_phase
            phase_r, code_r, los_r, el_r = self._zero_diff(ro, x_rov, sp_r)
            sd_phase = phase_r[:, :nf] - phase_b[:, :nf]
            sd_code = code_r[:, :nf] - code_b[:, :nf]
            v, H, R, _ = self._build_rows(dd, sd_phase, sd_code, los_r, wl, mu, var_sd)
            if not keep.all():
                v, H, R = v[keep], H[keep], R[np.ix_(keep, keep)]
            v = v - H[:, :3] @ (self.x[:3] - x_rov)
        x_prior, P_prior = self.x.copy(), self.P.copy()
        self._kalman_update(v, H, R)
        # Iterated EKF step: when the update landed more than RELINEARISE_M from the linearisation
        # point (a start from SPP), the troposphere and geometry at the rover are recomputed at the new
        # point and the update redone from the same prior.  A few metres of height error in the
        # linearisation point would otherwise bias the height by millimetres (tropospheric delay
        # changes ~0.3 mm per metre of height).
        if np.linalg.norm(self.x[:3] - x_rov) > RELINEARISE_M:
            x_rov = self.x[:3].copy()
            self.x, self.P = x_prior, P_prior
            phase_r, code_r, los_r, el_r = self._zero_diff(ro, x_rov, sp_r)
            sd_phase = phase_r[:, :nf] - phase_b[:, :nf]
            sd_code = code_r[:, :nf] - code_b[:, :nf]
            v2, H2, R2, _ = self._build_rows(dd, sd_phase, sd_code, los_r, wl, mu, var_sd)
            if not keep.all():
                v2, H2, R2 = v2[keep], H2[keep], R2[np.ix_(keep, keep)]
            v2 = v2 - H2[:, :3] @ (x_prior[:3] - x_rov)
            self._kalman_update(v2, H2, R2)
        # ambiguities and ionospheres seen this epoch are fresh
        for g in groups:
            for k in g.sats:
                key = (sats[k], g.slot)
                if key in self.amb_outage:
                    self.amb_outage[key] = 0
                if sats[k] in self.ion_seen:
                    self.ion_seen[sats[k]] = t
        float_pos = self.x[:3].copy()
        float_cov = self.P[:3, :3].copy()
        sol = RtkSolution(t, Status.FLOAT, float_pos, float_cov, n_sat_used, age_s=age,
                          baseline_m=float(np.linalg.norm(float_pos - self.base_position_m)),
                          velocity_m_s=self.x[3:6].copy() if self.n_kin == 9 else np.full(3, np.nan),
                          message="float")
        if not np.all(np.isfinite(float_pos)) or np.trace(float_cov) > 1e6:
            self.reset()
            return self._single(t, spp, "filter diverged, restarted", age)
        if spp.ok:
            # The float solution must agree with the epoch's own code solution; when it does not, the
            # filter has absorbed bad data: restart it rather than report a confident wrong position.
            gap = float(np.linalg.norm(float_pos - spp.position_m))
            if gap > SPP_CONSISTENCY_M + 5.0 * math.sqrt(max(np.trace(spp.covariance_m2), 0.0)):
                self.reset()
                return self._single(t, spp, f"filter {gap:.0f} m from SPP, restarted", age)
        if opt.ambiguity_resolution:
            self._resolve(sol, dd, sats, sd_phase, los_r, wl, mu, x_rov, el_r)
        else:
            self._confirm_reset()
        if not np.all(np.isfinite(sol.velocity_m_s)):
            # no dynamic model: the velocity (for RMC, odometry) comes from the rover's Dopplers
            sol.velocity_m_s, _ = doppler_velocity(rover, self.nav, sol.position_m, opt.elevation_mask_rad,
                                                   sat_positions=sp_rover)
        self._last_solution = (t, sol.position_m.copy(), np.asarray(sol.velocity_m_s, dtype=float).copy())
        return sol

    def _phase_position(self, v, H, R, kind, x_lin) -> np.ndarray | None:
        """The rover position from the DD phases whose ambiguities are established (the row's sigma from
        the states beyond the position below LINEARISATION_SIGMA_M), by weighted least squares about
        x_lin; None when fewer than LINEARISATION_MIN_ROWS such phases or when they do not agree to
        centimetres."""
        ph = kind == 1
        if np.count_nonzero(ph) < LINEARISATION_MIN_ROWS:
            return None
        Hp = H[ph]
        # the rows' uncertainty from everything but the position (DD ambiguities, DD ionosphere)
        Hn = Hp[:, self.n_kin:]
        var = np.einsum("ij,ij->i", Hn @ self.P[self.n_kin:, self.n_kin:], Hn)
        use = var < LINEARISATION_SIGMA_M**2
        if np.count_nonzero(use) < LINEARISATION_MIN_ROWS:
            return None
        G = Hp[use, :3]
        y = v[ph][use] + G @ (self.x[:3] - x_lin)  # innovation at the linearisation point
        w = 1.0 / np.diag(R)[ph][use]
        A = G.T @ (G * w[:, None])
        try:
            dx = np.linalg.solve(A, G.T @ (w * y))
        except np.linalg.LinAlgError:
            return None
        res = y - G @ dx
        if not np.all(np.isfinite(dx)) or math.sqrt(float(np.mean(res**2))) > LINEARISATION_MAX_RMS_M:
            return None
        return x_lin + dx

    def _predicted_position(self, t: float) -> np.ndarray:
        """Where to linearise this epoch's measurement update (see `_measurement_update`)."""
        last = self._last_solution
        if self.opt.mode == "kinematic" and self.n_kin == 3 and last is not None:
            t0, p0, v0 = last
            dt = t - t0
            if 0.0 < dt <= MAX_LINEARISATION_PREDICTION_S and np.all(np.isfinite(p0)) and np.all(np.isfinite(v0)):
                return p0 + v0 * dt
        return self.x[:3].copy()

    def _amb_known(self, key) -> bool:
        i = self.amb_index.get(key)
        return i is not None and self.P[i, i] < AMB_KNOWN_SIGMA_CYC**2

    def _slipped_keys(self, bad, dd: "_DD", sats):
        """Which ambiguities to reset given failing phase rows: the row's satellite, or the group's
        reference when at least half of its known rows fail."""
        out = set()
        known = self.P[dd.i, dd.i] < AMB_KNOWN_SIGMA_CYC**2
        for g in np.unique(dd.group):
            idx = np.flatnonzero((dd.group == g) & known)
            if len(idx) == 0:
                continue
            nbad = int(np.count_nonzero(bad[idx]))
            if nbad >= max(2, (len(idx) + 1) // 2):
                out.add((sats[dd.ref[idx[0]]], int(dd.f[idx[0]])))
            else:
                out.update((sats[dd.k[r]], int(dd.f[r])) for r in idx if bad[r])
        return out

    def _groups(self, sats, sys_, ok, el, nf) -> list[_Group]:
        # ambiguity variances per satellite and slot (inf where there is no state)
        amb_var = np.full(ok.shape, np.inf)
        diagP = np.diag(self.P)
        for k, f in zip(*np.nonzero(ok)):
            i = self.amb_index.get((sats[k], int(f)))
            if i is not None:
                amb_var[k, f] = diagP[i]
        known = amb_var < AMB_KNOWN_SIGMA_CYC**2
        groups = []
        for s in self.opt.systems:
            in_sys = sys_ == s
            for f in range(nf):
                members = np.flatnonzero(ok[:, f] & in_sys)
                if len(members) < 2:
                    continue
                # reference: highest elevation among satellites with an established ambiguity if any
                est = members[known[members, f]]
                pool = est if len(est) else members
                ref = int(pool[np.argmax(el[pool])])  # the first of equal elevations, as max() takes
                groups.append(_Group([ref] + [int(k) for k in members if k != ref], f))
        return groups

    def _dd_index(self, groups, sats, nf) -> "_DD":
        """The epoch's double differences as index arrays (one entry per non-reference satellite and slot)."""
        ks, refs, fs, gs = [], [], [], []
        for gi, g in enumerate(groups):
            n = len(g.sats) - 1
            ks.extend(g.sats[1:])
            refs.extend([g.sats[0]] * n)
            fs.extend([g.slot] * n)
            gs.extend([gi] * n)
        k = np.array(ks, dtype=int)
        ref = np.array(refs, dtype=int)
        f = np.array(fs, dtype=int)
        amb = np.array([self.amb_index[(sats[a], b)] for a, b in zip(ks, fs)], dtype=int)
        amb_ref = np.array([self.amb_index[(sats[a], b)] for a, b in zip(refs, fs)], dtype=int)
        if self.iono_active:
            ion = np.array([self.ion_index[sats[a]] for a in ks], dtype=int)
            ion_ref = np.array([self.ion_index[sats[a]] for a in refs], dtype=int)
        else:
            ion = ion_ref = None
        return _DD(k, ref, f, np.array(gs, dtype=int), amb, amb_ref, ion, ion_ref)

    def _build_rows(self, dd: "_DD", sd_phase, sd_code, los, wl, mu, var_sd):
        """Innovations, design matrix and covariance of the epoch's DD phase rows then DD code rows.

        The SD ranges were computed at x_rov = self.x[:3], so the linearisation point is the current
        state and the innovations need no position term."""
        nx = len(self.x)
        m = len(dd.k)
        ar = np.arange(m)
        k, ref, f = dd.k, dd.ref, dd.f
        geo = -(los[k] - los[ref])
        H = np.zeros((2 * m, nx))
        H[:m, :3] = geo
        H[m:, :3] = geo
        H[ar, dd.i] = wl[k, f]
        H[ar, dd.iref] = -wl[ref, f]
        if dd.ion is not None:
            # phase advance -mu I, code delay +mu I (SD ionosphere on the first frequency per satellite)
            H[ar, dd.ion] = -mu[k, f]
            H[ar, dd.ion_ref] = mu[ref, f]
            H[m + ar, dd.ion] = mu[k, f]
            H[m + ar, dd.ion_ref] = -mu[ref, f]
        y = np.concatenate((sd_phase[k, f] - sd_phase[ref, f], sd_code[k, f] - sd_code[ref, f]))
        v = y - H[:, 3:] @ self.x[3:]
        same = dd.group[:, None] == dd.group[None, :]
        Rp = np.diag(var_sd[k, f]) + same * var_sd[ref, f][:, None]
        R = np.zeros((2 * m, 2 * m))
        R[:m, :m] = Rp
        R[m:, m:] = Rp * self._code_phase_ratio() ** 2
        kind = np.concatenate((np.ones(m, dtype=int), np.zeros(m, dtype=int)))
        return v, H, R, kind

    def _code_phase_ratio(self) -> float:
        if self.opt.code_phase_ratio is not None:
            return float(self.opt.code_phase_ratio)
        return CODE_PHASE_ERROR_RATIO_WITH_IONOSPHERE if self.iono_active else CODE_PHASE_ERROR_RATIO

    def _kalman_update(self, v, H, R) -> None:
        # only the states the rows touch (and the kinematic ones) enter the products
        active = np.flatnonzero(np.any(H != 0.0, axis=0) | (np.arange(len(self.x)) < self.n_kin))
        Ha = H[:, active]
        PHt = self.P[:, active] @ Ha.T  # (nx, m) = P H^T
        S = Ha @ PHt[active] + R
        K = np.linalg.solve(S, PHt.T).T  # (nx, m)
        self.x = self.x + K @ v
        self.P = self.P - K @ PHt.T
        self.P = 0.5 * (self.P + self.P.T)

    def _resolve(self, sol: RtkSolution, dd: "_DD", sats, sd_phase, los, wl, mu, x_lin, el) -> None:
        """Integer ambiguity resolution on this epoch's DD ambiguities; on success `sol` becomes FIX.

        A fixed solution must leave DD phase residuals at the noise level.  When it does not, one
        satellite's phase is usually at fault (multipath, a slip too small to detect): the worst row
        is left out and the search repeated, up to AR_EXCLUSION_RETRIES times.  When no subset passes
        at all: without the ionosphere in the model the satellite fitting the float worst is left out;
        with it (float residuals then say little, the ionosphere states absorb them) the lowest
        satellite is, as its ionosphere prior is the loosest (partial resolution by elevation).

        With the ionosphere in the model a fix is declared only after CONFIRM_EPOCHS_WITH_IONOSPHERE
        consecutive epochs of agreeing integer decisions (`_confirm`).  A validated partial fix (ratio,
        success rate and phase residuals passed, but too few combinations fixed to pin the position to
        MAX_FIXED_POSITION_SIGMA_M: typically the wide-lane-like combinations first) is such a decision
        too, and counts towards the streak; the fix declared is always a complete one.
        """
        opt = self.opt
        rows = np.arange(len(dd.k))
        n_all = len(rows)
        message = ""
        partial = None  # this epoch's first validated partial fix: (fix, Hc, x_fix, P_fix, rows)
        for _attempt in range(AR_EXCLUSION_RETRIES + 1):
            if len(rows) < opt.min_fix_ambiguities:
                message = message or "float: too few ambiguities to fix"
                break
            result = self._try_fix(dd, rows, sd_phase, los, wl, mu, x_lin)
            if isinstance(result, str):
                message = result
                if self.iono_active:
                    if not result.startswith("float: no ambiguity subset"):
                        break
                    # partial resolution by elevation: the lowest satellite has the loosest ionosphere
                    # and the most multipath; leave it (every slot) out and search again
                    low = dd.k[rows][np.argmin(el[dd.k[rows]])]
                    rows = rows[dd.k[rows] != low]
                    continue
                if not result.startswith("float: no ambiguity subset"):
                    break
                # nothing passed: the satellite fitting the float solution worst is the likely
                # culprit (multipath, an undetected slip); leave it out and search again
                res = self._phase_residuals(dd, rows, sd_phase, los, wl, mu, x_lin, self.x)
                rows = np.delete(rows, int(np.argmax(np.abs(res))))
                continue
            fix, Hc, x_fix, P_fix, res, sigma = result
            worst = int(np.argmax(np.abs(res)))
            if sigma > MAX_FIXED_POSITION_SIGMA_M:
                # A partial fix of a few combinations (wide-lane-like) can pass its tests and still leave
                # the position at float precision: that is not an RTK fix and is not reported as one,
                # but its integers are a decision the next epochs' fixes must agree with.
                message = f"float: fixed subset ({fix.count}) leaves position sigma {sigma * 100:.0f} cm"
                if partial is None and abs(res[worst]) <= MAX_FIXED_PHASE_RESIDUAL_M:
                    partial = (fix, Hc, x_fix, P_fix, rows)
                if not self.iono_active:
                    break
                low = dd.k[rows][np.argmin(el[dd.k[rows]])]
                rows = rows[dd.k[rows] != low]
                continue
            if abs(res[worst]) <= MAX_FIXED_PHASE_RESIDUAL_M:
                count = self._confirm(dd, sats, rows, fix, Hc, x_fix, P_fix)
                need = self._confirm_needed()
                if count >= need:
                    self._accept_fix(sol, fix, Hc, x_fix, P_fix, n_all)
                    sol.fixed_dd = self._fixed_dd(dd, sats, rows, x_fix, P_fix)
                else:
                    self.consecutive_fixes = 0
                    sol.message = f"float: fix candidate {count}/{need} ({fix.count}/{n_all} ambiguities, ratio {fix.ratio:.1f})"
                return
            message = f"float: fixed solution rejected (phase residual {abs(res[worst]) * 100:.1f} cm)"
            # leave the worst satellite out (its reference too if every row of the group is bad)
            rows = np.delete(rows, worst)
        self.consecutive_fixes = 0
        if partial is not None and self._confirm_needed() > 1:
            fix, Hc, x_fix, P_fix, prows = partial
            count = self._confirm(dd, sats, prows, fix, Hc, x_fix, P_fix)
            message = f"{message}; {fix.count} combinations fixed, agreeing over {count} epochs"
        else:
            self._confirm_reset()
        sol.message = message

    def _confirm_needed(self) -> int:
        if self.opt.confirm_epochs is not None:
            return max(1, int(self.opt.confirm_epochs))
        # short baselines: the model is exact to millimetres and a validated fix is declared at once;
        # with residual atmosphere in the model (VRS, medium range) a fix is confirmed over epochs
        return CONFIRM_EPOCHS_WITH_IONOSPHERE if self.iono_active else 1

    def _confirm_reset(self) -> None:
        self._candidate = None
        self._candidate_count = 0

    def _confirm(self, dd: "_DD", sats, rows, fix, Hc, x_fix, P_fix) -> int:
        """Count consecutive epochs whose validated (complete or partial) fixes agree, this one included.

        An epoch's integer decision is kept as integer functionals of the single-difference ambiguity
        states, by satellite and slot: each DD ambiguity its fix determines (conditional sigma below
        CONFIRM_SIGMA_CYC), and the fixed decorrelated combinations themselves (what a partial fix
        determines).  The next epoch agrees when every such functional it can evaluate (its satellites
        still tracked without a slip) and determines has the same integer, and there are at least
        min_fix_ambiguities of them.  An ambiguity re-initialised since (a slip: a new arc under the same
        key) is, like a satellite that has risen since, not comparable: its functionals are left out, and
        the new integer is validated by this epoch's tests alone, against the others' agreement."""
        if self._confirm_needed() <= 1:
            return 1  # declared at once: nothing to compare with
        prev = self._candidate
        agree = False
        if prev is not None:
            keys, C, z = prev
            idx = np.array([self.amb_index[k] if self.amb_serial.get(k) == serial else -1 for k, serial in keys],
                           dtype=int)
            usable = ~np.any((C != 0.0) & (idx < 0)[None, :], axis=1)
            if np.count_nonzero(usable) >= self.opt.min_fix_ambiguities:
                present = idx >= 0
                Cu = C[np.ix_(usable, present)]
                ip = idx[present]
                val = Cu @ x_fix[ip]
                var = np.einsum("ij,jk,ik->i", Cu, P_fix[np.ix_(ip, ip)], Cu)
                det = var < CONFIRM_SIGMA_CYC**2
                agree = (np.count_nonzero(det) >= self.opt.min_fix_ambiguities
                         and bool(np.all(np.abs(val[det] - z[usable][det]) < 0.5)))
        self._candidate_count = self._candidate_count + 1 if agree else 1
        self._candidate = self._decision(dd, sats, rows, Hc, fix.z_fixed, x_fix, P_fix)
        return self._candidate_count

    def _decision(self, dd: "_DD", sats, rows, Hc, z_fixed, x_fix, P_fix):
        """((SD ambiguity key, serial) per column, integer functionals over them (one per row), their
        integers) of a fix: the DD ambiguities it determines, then its fixed combinations."""
        inv = {i: key for key, i in self.amb_index.items()}
        cols = np.flatnonzero(np.any(Hc != 0.0, axis=0))
        keys = [(inv[int(c)], self.amb_serial[inv[int(c)]]) for c in cols]
        pos = {int(c): j for j, c in enumerate(cols)}
        i, iref = dd.i[rows], dd.iref[rows]
        var = P_fix[i, i] + P_fix[iref, iref] - 2.0 * P_fix[i, iref]
        det = np.flatnonzero(var < CONFIRM_SIGMA_CYC**2)
        C_dd = np.zeros((len(det), len(cols)))
        C_dd[np.arange(len(det)), [pos[int(c)] for c in i[det]]] = 1.0
        C_dd[np.arange(len(det)), [pos[int(c)] for c in iref[det]]] = -1.0
        z_dd = np.round(x_fix[i[det]] - x_fix[iref[det]])
        C = np.vstack((C_dd, Hc[:, cols]))
        z = np.concatenate((z_dd, np.asarray(z_fixed, dtype=float)))
        return keys, C, z

    def _try_fix(self, dd: "_DD", rows, sd_phase, los, wl, mu, x_lin):
        opt = self.opt
        i, iref = dd.i[rows], dd.iref[rows]
        idx = np.unique(np.concatenate((i, iref)))
        pos = np.searchsorted(idx, i)
        pos_ref = np.searchsorted(idx, iref)
        n = len(rows)
        D = np.zeros((n, len(idx)))
        D[np.arange(n), pos] = 1.0
        D[np.arange(n), pos_ref] = -1.0
        a_dd = D @ self.x[idx]
        Q_dd = D @ self.P[np.ix_(idx, idx)] @ D.T
        try:
            fix = bounded_partial_fix(a_dd, Q_dd, opt.min_success_rate, opt.ratio_threshold, opt.min_fix_ambiguities)
        except AmbiguityError as exc:
            return f"float: ambiguity covariance unusable ({exc})"
        if fix is None:
            return "float: no ambiguity subset passed ratio and success-rate tests"
        # the constraint Zs^T D a_sd = z on the full state (conditional mean and covariance)
        Hc = np.zeros((fix.count, len(self.x)))
        Hc[:, idx] = fix.Zs.T @ D
        PHt = self.P @ Hc.T
        S = Hc @ PHt
        try:
            K = np.linalg.solve(S, PHt.T).T
        except np.linalg.LinAlgError:
            return "float: fixed-ambiguity constraint singular"
        x_fix = self.x - K @ (Hc @ self.x - fix.z_fixed)
        P_fix = self.P - K @ PHt.T
        # the 3-D position sigma of the fixed solution (a partial fix may leave it at float precision)
        sigma = math.sqrt(max(float(np.trace(P_fix[:3, :3])), 0.0))
        return fix, Hc, x_fix, P_fix, self._phase_residuals(dd, rows, sd_phase, los, wl, mu, x_lin, x_fix), sigma

    @staticmethod
    def _phase_residuals(dd: "_DD", rows, sd_phase, los, wl, mu, x_lin, x) -> np.ndarray:
        """DD phase residuals [m] of a state x, the rows' SD phases formed at the linearisation point."""
        dx = x[:3] - x_lin
        k, ref, f = dd.k[rows], dd.ref[rows], dd.f[rows]
        y = sd_phase[k, f] - sd_phase[ref, f]
        pred = -(los[k] - los[ref]) @ dx + wl[k, f] * x[dd.i[rows]] - wl[ref, f] * x[dd.iref[rows]]
        if dd.ion is not None:
            pred = pred - mu[k, f] * x[dd.ion[rows]] + mu[ref, f] * x[dd.ion_ref[rows]]
        return y - pred

    def _fixed_dd(self, dd: "_DD", sats, rows, x_fix, P_fix) -> dict[tuple[str, str, int], int]:
        i, iref = dd.i[rows], dd.iref[rows]
        var = P_fix[i, i] + P_fix[iref, iref] - 2.0 * P_fix[i, iref]
        val = x_fix[i] - x_fix[iref]
        return {(sats[dd.k[r]], sats[dd.ref[r]], int(dd.f[r])): int(round(a))
                for r, a, v in zip(rows, val, var) if v < CONFIRM_SIGMA_CYC**2}

    def _accept_fix(self, sol, fix, Hc, x_fix, P_fix, n_all) -> None:
        sol.status = Status.FIX
        sol.position_m = x_fix[:3].copy()
        sol.covariance_m2 = 0.5 * (P_fix[:3, :3] + P_fix[:3, :3].T)
        sol.ratio = float(min(fix.ratio, 999.9))
        sol.success_rate = float(fix.success_rate)
        sol.n_fixed = fix.count
        sol.message = f"fix: {fix.count}/{n_all} ambiguities"
        if self.n_kin == 9:
            sol.velocity_m_s = x_fix[3:6].copy()
        self.consecutive_fixes += 1
        if self.opt.fix_and_hold and self.consecutive_fixes >= HOLD_AFTER_FIXES:
            v = fix.z_fixed - Hc @ self.x
            self._kalman_update(v, Hc, np.eye(fix.count) * HOLD_VARIANCE_CYC2)

    def _float_or_single(self, t, spp, age, n, msg) -> RtkSolution:
        return self._single(t, spp, msg, age)


def bounded_partial_fix(a_hat: np.ndarray, Q: np.ndarray, min_success_rate: float, ratio_threshold: float,
                        min_count: int, max_tries: int = MAX_PARTIAL_FIX_TRIES) -> PartialFix | None:
    """Partial ambiguity resolution with a bounded cost (the policy of `augnet.gnss.ambiguity.partial_fix`,
    built from its LAMBDA pieces): in the decorrelated L^T D L ordering, take the largest trailing block
    whose bootstrapped success rate reaches `min_success_rate`, search it, and accept it if the ratio
    test passes; otherwise drop the worst-determined leading ambiguity and retry, at most `max_tries`
    searches.  The full set is searched first when it qualifies.
    """
    n = a_hat.shape[0]
    if n < max(min_count, 1):
        return None
    Q = 0.5 * (Q + Q.T)
    L, D = ldl_lapack(Q)
    L, D, Z = reduce(L, D)
    zs = Z.T @ a_hat
    # success rates of every trailing block at once: products of the per-ambiguity factors
    # 2 Phi(1 / (2 sqrt(d))) - 1 (`augnet.gnss.ambiguity.bootstrap_success_rate` of one ambiguity)
    factors = np.array([2.0 * (0.5 * (1.0 + math.erf(1.0 / (2.0 * math.sqrt(d)) / math.sqrt(2.0)))) - 1.0 for d in D])
    tail = np.cumprod(factors[::-1])[::-1]
    starts = [k for k in range(0, n - min_count + 1) if tail[k] >= min_success_rate]
    for start in starts[:max_tries]:
        # A float solution biased by unmodelled errors (ionosphere on a long baseline, multipath) is
        # far from every integer: its bootstrapped norm fails a chi-square test, and the search,
        # whose ellipsoid that norm sizes, would only burn seconds to fail the ratio test anyway.
        q_boot, rms_frac = _bootstrapped_norm(L[start:, start:], D[start:], zs[start:])
        # Both tests, because after fix-and-hold the covariance is far below the true (time-correlated)
        # error and the chi-square test alone would refuse floats that sit a few hundredths of a cycle
        # from their integers.
        if q_boot > chi2_quantile(n - start, FLOAT_CONSISTENCY_FALSE_ALARM) and rms_frac > BIASED_FLOAT_RMS_CYC:
            continue
        cand, norms = search(L[start:, start:], D[start:], zs[start:], 2)
        ratio = float(norms[1] / norms[0]) if norms[0] > 0 else math.inf
        if ratio >= ratio_threshold:
            return PartialFix(Zs=Z[:, start:], z_fixed=cand[0], ratio=ratio, success_rate=float(tail[start]))
    return None


def ldl_lapack(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`augnet.gnss.ambiguity.ldl` (Q = L^T diag(D) L, L unit lower triangular, factored from the last
    index) through LAPACK's Cholesky: with J the order reversal, J Q J = C C^T gives Q = U U^T for the
    upper triangular U = J C J, so D = diag(U)^2 and L = diag(U)^-1 U^T.  Equal to rounding, and
    two orders of magnitude faster than the rank-one downdates for 30-80 ambiguities."""
    Q = np.asarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
        raise AmbiguityError(f"covariance must be square, got {Q.shape}")
    if not np.all(np.isfinite(Q)):
        raise AmbiguityError("covariance is not positive definite")
    try:
        C = np.linalg.cholesky(Q[::-1, ::-1])
    except np.linalg.LinAlgError:
        raise AmbiguityError("covariance is not positive definite") from None
    U = C[::-1, ::-1]
    u = np.diag(U).copy()
    return U.T / u[:, None], u * u


@njit(cache=True)
def _bootstrapped_norm(L: np.ndarray, D: np.ndarray, zs: np.ndarray):
    """(squared distance, RMS conditional fraction [cycles]) of the integer bootstrapping (sequential
    conditional rounding) solution from the float ambiguities, in the metric of their covariance
    L^T diag(D) L (last index first)."""
    n = len(D)
    z = np.zeros(n)
    zb = np.zeros(n)
    dist = 0.0
    for k in range(n - 1, -1, -1):
        acc = 0.0
        for j in range(k + 1, n):
            acc += (z[j] - zb[j]) * L[j, k]
        zb[k] = zs[k] + acc
        z[k] = np.round(zb[k])
        dist += (zb[k] - z[k]) ** 2 / D[k]
    return dist, np.sqrt(np.mean((zb - z) ** 2))


def _take(sp: SatPositions, idx) -> SatPositions:
    """The satellite states of a subset of an epoch's satellites."""
    return SatPositions(*(a[idx] for a in sp))


_BLAS_CONTROLLER: ThreadpoolController | None = None


def _blas_controller() -> ThreadpoolController:
    global _BLAS_CONTROLLER
    if _BLAS_CONTROLLER is None:
        _BLAS_CONTROLLER = ThreadpoolController()
    return _BLAS_CONTROLLER


def _block_diag(blocks: list[np.ndarray]) -> np.ndarray:
    n = sum(b.shape[0] for b in blocks)
    R = np.zeros((n, n))
    i = 0
    for b in blocks:
        m = b.shape[0]
        R[i:i + m, i:i + m] = b
        i += m
    return R
