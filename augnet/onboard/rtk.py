"""Real-time kinematic positioning: an extended Kalman filter on double differences, with integer
ambiguity resolution (LAMBDA, partial fixing, ratio test and bootstrapped success rate), fix
confirmation and fix-and-hold.

State (`StateLayout`): rover ECEF position (and velocity and acceleration when the dynamic model is on),
then one *single-difference* (rover minus base) carrier ambiguity per satellite and frequency slot, in
cycles, and with the ionosphere in the model one SD ionospheric delay per satellite.  Measurements are
double differences (per system and slot, against that group's highest satellite) of phase and code,
formed in the measurement model (`double_difference.py`) so satellites rise and set and the reference
changes without touching the state.

Atmosphere.  The troposphere model is applied at each receiver.  On a short baseline the DD ionosphere
is millimetres and is not modelled: the filter fixes from the first epoch.  Against a network VRS
(RINEX MARKER TYPE NON_PHYSICAL, RTCM DF141 = 1) or a longer baseline the filter is
*ionosphere-weighted* (`ionosphere_prior.py`; against a physical base its prior is learned from the fixed
satellites) and code is weighted down, since the base's multipath is correlated over minutes.  Aged
corrections (a 30 s base) add a per-satellite error to the DD covariance (`correction_age.py`).  No relative zenith troposphere state: over a minute it cannot be told from the
height (docs/decisions/0080-rtk-model-and-validation.md).

Validation (`_resolve`).  Partial fixing under one `FixPolicy` (`augnet.gnss.ambiguity`), a fixed
position sigma <= MAX_FIXED_POSITION_SIGMA_M, DD phase residuals <= MAX_FIXED_PHASE_RESIDUAL_M after
fixing (else the worst satellite is left out and the search repeated; with the ionosphere estimated, the
lowest satellite), and with the ionosphere in the model a fix is declared only when consecutive epochs'
validated integer decisions agree (`FixConfirmation`).  The rover losing lock keeps its SD ionosphere
states, so new ambiguities are fixed against them.  Fix-and-hold after HOLD_AFTER_FIXES declared fixes.
The covariance of a fixed solution is the float covariance conditioned on the fixed combinations, so it
carries the estimated ionosphere's uncertainty.

Status per epoch (RTKLIB's Q codes so tools compare): FIX (1) when a validated integer set is
applied, FLOAT (2), SINGLE (5) when the rover falls back to SPP (no or stale corrections, base
inconsistent, filter diverged), NONE (0) when not even SPP is possible.  `step` never raises on
data; each solution carries a message saying why it is what it is.

Settings: `RtkOptions` (one table; docs/options/rtk.md is generated from it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Sequence

import numpy as np
from threadpoolctl import ThreadpoolController

from augnet.gnss.ambiguity import AmbiguityError, FixedIntegers, FixPolicy, PartialFix, partial_fix
from augnet.gnss.ambiguity import BIASED_FLOAT_FALSE_ALARM
from augnet.gnss.antex import AntennaSetup
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.fix_confirmation import FixConfirmation, IntegerDecision
from augnet.gnss.state_layout import StateLayout
from augnet.onboard import correction_age, ionosphere_prior
from augnet.onboard.correction_bound import DDGeometry
from augnet.onboard.cycleslip import BASE_GF_DRIFT_M_S, BASE_GF_SLIP_THRESHOLD_M, BASE_MAX_ARC_GAP_S, SlipDetector
from augnet.onboard.double_difference import (
    AMB_KNOWN_SIGMA_CYC,
    DDIndex,
    Rows,
    SingleDifferences,
    ZeroDifferences,
    choose_groups,
    dd_index,
    dd_rows,
    first_wavelength,
    phase_residuals,
    phase_variance,
    single_differences,
    slipped_keys,
    zero_differences,
)
from augnet.onboard.motion import predict_pva
from augnet.onboard.observations import LLI_SLIP, EpochObs
from augnet.onboard.spp import (
    SELECTION_CACHE_S,
    SatPositions,
    SppOptions,
    SppResult,
    doppler_velocity,
    first_code,
    satellite_positions,
    solve_spp,
)
from augnet.options import setting


class Status(IntEnum):
    NONE = 0
    FIX = 1
    FLOAT = 2
    SINGLE = 5


SOLUTION_STATUS_NAMES = {Status.NONE: "none", Status.FIX: "fix", Status.FLOAT: "float", Status.SINGLE: "single"}

# --- internal constants (not settings: the model's own figures) -----------------------------------
# Code noise over phase noise with a short-baseline model (RTKLIB's default eratio1 = 100).
CODE_PHASE_ERROR_RATIO = 100.0
# ... and with the ionosphere estimated (VRS, medium baselines): code then also carries the base's (for
# a VRS, the master station's) multipath, correlated over minutes, which a filter treating code as white
# noise would trust too much.  RTKLIB EX's default (demo5 eratio1); docs/decisions/0080.
CODE_PHASE_ERROR_RATIO_WITH_IONOSPHERE = 300.0
# Initial standard deviations of new states.
INIT_POSITION_SIGMA_M = 30.0
INIT_VELOCITY_SIGMA_M_S = 10.0
INIT_ACCELERATION_SIGMA_M_S2 = 10.0
INIT_AMBIGUITY_SIGMA_CYC = 30.0
# Random-walk process noise of a single-difference ambiguity [cycles / sqrt(s)].
AMBIGUITY_PROCESS_SIGMA_CYC = 1e-4
# The base's own SPP must agree with its given coordinates within this [m], or the coordinates (or
# the base data) are wrong and a "fixed" rover would be wrong by the same amount.
BASE_POSITION_TOLERANCE_M = 100.0
# SPP steps from a known start: the first lands within a millimetre of the converged solution when the
# start is within a few hundred metres (anything farther fails the checks anyway); the second makes the
# step itself a small number.
BASE_CHECK_SPP_STEPS = 2
ROVER_SPP_STEPS = 2
# Prefit screening: code DD innovations beyond this [m] are blunders; a phase DD whose ambiguity is
# established (double_difference.AMB_KNOWN_SIGMA_CYC) and whose innovation exceeds
# max(PHASE_INNOVATION_SIGMAS * sigma, PHASE_INNOVATION_MIN_M) is a slip the detectors missed.
MAX_CODE_INNOVATION_M = 30.0
PHASE_INNOVATION_SIGMAS = 6.0
PHASE_INNOVATION_MIN_M = 0.10
# Range fault (issue 15, decision 0253): a DD whose code innovation is beyond this many code sigmas and whose
# phase innovation agrees with it within as many is a jump of the range, not of the ambiguity: a
# satellite clock step or an orbit fault seen between the base epoch and the rover epoch (the VRS epoch
# used is ~1 s older). A slip moves the phase alone; re-initialising the ambiguity from code, as for a slip,
# leaves the jump in the row, and the filter took it in (100 ns step: float bias ~1 m, decision 0252).
RANGE_FAULT_CODE_SIGMAS = 4.0
# A white-noise position linearised at the last solution carried by its velocity (`_predicted_position`) is
# that good: a train accelerates or brakes at most ~1.5 m/s^2 (emergency braking; 2 taken) and the Doppler
# velocity is good to ~5 cm/s, so the prediction is off by at most 0.5 a dt^2 + dv dt [m], taken as its sigma.
PREDICTION_ACCEL_M_S2 = 2.0
PREDICTION_VELOCITY_SIGMA_M_S = 0.05
# The satellite then stays out of the RTK for this long [s]: the centre's integrity monitor excludes a
# satellite fault within an epoch and the VRS omits it within its latency (~1-2 s); the hold covers that
# with margin, and after it a satellite the VRS still carries (a local event) re-enters with a new ambiguity.
RANGE_FAULT_HOLD_S = 30.0
# Phase observations of a satellite not updated for more epochs than this lose their ambiguity.
MAX_AMBIGUITY_OUTAGE_EPOCHS = 5
# Fix-and-hold: after this many consecutive fixes the integers are fed back into the float filter as
# pseudo-observations with this variance [cycles^2] (RTKLIB's VAR_HOLDAMB is 0.001 cycle^2 as well).
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
# A fixed solution must have a 3-D position sigma below this [m]: a fix that only pins a few ambiguity
# combinations leaves decimetres and is still a float solution; 3 cm keeps the vertical sigma of a fix
# under ~2.5 cm, what a 4 cm vertical 95 % figure needs.
MAX_FIXED_POSITION_SIGMA_M = 0.03
# Partial ambiguity resolution tries at most this many nested subsets per epoch: each integer search
# costs up to ~0.5 s on a poor float solution, and a rover must keep up with 1 Hz.
MAX_PARTIAL_FIX_TRIES = 8
# The float position may differ from the epoch's SPP by the SPP's error; beyond this [m] plus five
# SPP sigmas the filter has gone wrong.
SPP_CONSISTENCY_M = 30.0
# A float position covariance trace beyond this [m^2] means the filter diverged.
MAX_FLOAT_COVARIANCE_TRACE_M2 = 1e6
# Fixed solutions whose DD phase residuals exceed this [m] are rejected (wrong fix).
MAX_FIXED_PHASE_RESIDUAL_M = 0.05
# ... plus this many sigmas of the row's error from aged corrections (correction_age; 3: a 0.3 % false alarm
# per row when the age dominates).
AGE_RESIDUAL_SIGMAS = 3.0
# With the ionosphere in the model, a validated fix is declared only when the same integers have been
# found in this many consecutive epochs (a biased float can pass one epoch's tests by chance).
CONFIRM_EPOCHS_WITH_IONOSPHERE = 3
# The message of an epoch where no ambiguity subset passed (the cue to leave a satellite out).
NO_SUBSET_MESSAGE = "float: no ambiguity subset passed ratio and success-rate tests"


@dataclass
class RtkOptions:
    """The onboard RTK's settings: one table (docs/options/rtk.md, `augnet rtk --opt NAME=VALUE`)."""

    mode: str = setting("kinematic", doc="rover motion model", choices=("kinematic", "static"),
                        source="RTKLIB pos1-posmode")
    dynamics: bool = setting(False, doc="kinematic only: position-velocity-acceleration model (else a white "
                             "position restarted from SPP every epoch)", source="RTKLIB pos1-dynamics")
    elevation_mask_rad: float = setting(math.radians(15.0), unit="rad", doc="satellites below are not used",
                                        source="RTKLIB pos1-elmask (15 deg)")
    systems: Sequence[str] = setting(("G", "E", "C", "J"), doc="GNSS used, comma-separated system letters")
    n_slots: int = setting(2, doc="frequency slots used per system (1: L1/E1/B1I, 2: dual, 3: triple)",
                           source="RTKLIB pos1-frequency")
    phase_sigma_a_m: float = setting(0.003, unit="m", doc="carrier-phase noise a of sigma^2 = a^2 + "
                                     "b^2/sin^2(el), per receiver", source="RTKLIB stats-errphase")
    phase_sigma_b_m: float = setting(0.003, unit="m", doc="carrier-phase noise b (elevation term), per receiver",
                                     source="RTKLIB stats-errphaseel")
    code_phase_ratio: float | None = setting(None, doc="code over phase noise; None: 100, or 300 with the "
                                             "ionosphere estimated", source="RTKLIB stats-eratio1; RTKLIB EX demo5")
    ratio_threshold: float = setting(3.0, doc="ratio test (second best over best squared norm) a fix must pass",
                                     source="RTKLIB pos2-arthres")
    min_success_rate: float = setting(0.999, doc="bootstrapped success rate a fixed subset must reach",
                                      source="Teunissen 1999 (partial ambiguity resolution)")
    min_fix_ambiguities: int = setting(4, doc="fewest ambiguities in a fix, and agreeing functionals in a "
                                       "confirmation (4 fix a position)")
    fix_and_hold: bool = setting(True, doc="feed fixed integers back into the float filter after "
                                 f"{HOLD_AFTER_FIXES} declared fixes", source="RTKLIB pos2-armode=fix-and-hold")
    ambiguity_resolution: bool = setting(True, doc="resolve integer ambiguities (off: float only)")
    max_age_s: float = setting(5.0, unit="s", doc="corrections older than this are stale: SPP instead",
                               source="network RTK practice: under 2 s normally, 5 s at most "
                               "(../shared/design/network-rtk.md)")
    max_baseline_m: float = setting(100_000.0, unit="m", doc="beyond this the RTK model breaks down (and a "
                                    "base position wrong by more cannot be RTK'd against): SPP instead")
    ionosphere: str = setting("auto", doc="SD ionosphere per satellite: auto (for a VRS or beyond ~7 km), "
                              "estimate (always), off (short-baseline model)", choices=("auto", "estimate", "off"))
    iono_sigma_m: float | None = setting(None, unit="m", doc="prior sigma of the SD vertical ionosphere; None: "
                                         "vrs_iono_sigma_m for a VRS, else by iono_prior")
    iono_prior: str = setting("learned", doc="a physical base's SD ionosphere prior: per_km (2 mm per km of "
                              "baseline), learned (per_km until fixes, then the day's level from the fixed "
                              "satellites' DD ionosphere, which may take the ionosphere out of the model; "
                              "ionosphere_prior.LearnedPrior)", choices=("per_km", "learned"),
                              source="docs/decisions/0162")
    vrs_iono_sigma_m: float = setting(0.02, unit="m", doc="prior sigma of the SD vertical ionosphere against a "
                                      "network VRS (the network's interpolation residual)",
                                      source="1-3 cm DD at 30-70 km spacing (network-rtk.md: Tang et al. 2016)")
    confirm_epochs: int | None = setting(None, doc="consecutive agreeing fixes before FIX; None: 1, or 3 with "
                                         "the ionosphere estimated")
    age_variance: bool = setting(True, doc="inflate the DD covariance with the corrections' age (satellite clock "
                                 "drift since the base epoch, common to a satellite's slots, code and phase)",
                                 source="RTKLIB stats-clkstab; docs/decisions/0162")
    tropo_humidity: float = setting(0.7, doc="relative humidity of the Saastamoinen troposphere at both "
                                    "receivers; 0: hydrostatic part only (RTKLIB 2.4.3's relative-mode model)",
                                    source="RTKLIB REL_HUMI 0.7; rtkpos.c zdres (hydrostatic)")
    accel_sigma_h: float = setting(3.0, unit="m/s^2/sqrt(s)", doc="dynamics: horizontal white-jerk process "
                                   "noise (a train brakes at ~1 m/s^2; a road vehicle changes faster)")
    accel_sigma_v: float = setting(1.0, unit="m/s^2/sqrt(s)", doc="dynamics: vertical white-jerk process noise")
    spp: SppOptions = setting(default_factory=SppOptions, doc="the single-point solution's settings (a group)")


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
    # a FIX: every DD ambiguity the fix determines (conditional sigma below
    # augnet.gnss.ambiguity.DETERMINED_SIGMA_CYC), for checks against a truth
    fixed_dd: FixedIntegers = field(default_factory=FixedIntegers)

    @property
    def status_name(self) -> str:
        return SOLUTION_STATUS_NAMES[self.status]


@dataclass
class _CommonEpoch:
    """The satellites common to rover and base at one epoch, with what the measurement model needs of them."""
    t: float
    sats: list[str]
    sys_: np.ndarray  # system letter per satellite
    rover: EpochObs
    base: EpochObs
    sp_rover: SatPositions
    nf: int  # frequency slots used
    valid: np.ndarray  # satellite states usable at both ends, same issue of data
    zd_base: ZeroDifferences
    wl: np.ndarray  # (n, nf) rover wavelengths [m]
    same_wl: np.ndarray  # (n, nf) the base observed the same wavelength
    mu: np.ndarray  # (n, nf) ionospheric scale of each slot against the system's first frequency
    slips: np.ndarray  # (n, nf) a slip at either end
    base_slipped_all: np.ndarray  # (n,) every slot of the base slipped
    base_slips: np.ndarray  # (n, nf) a slip at the base


@dataclass
class _FixAttempt:
    """A fix of some DD rows: the fixed combinations Hc x = fix.z_fixed over the full state, the
    conditioned state, the DD phase residuals it leaves [m] and its 3-D position sigma [m]."""
    fix: PartialFix
    Hc: np.ndarray
    x: np.ndarray
    P: np.ndarray
    residuals: np.ndarray
    sigma_m: float


def fix_policy(opt: RtkOptions) -> FixPolicy:
    """The onboard RTK's ambiguity-fixing policy: the settings' thresholds, at most MAX_PARTIAL_FIX_TRIES
    searches per epoch and biased floats screened out before their search."""
    return FixPolicy(min_success_rate=opt.min_success_rate, ratio_threshold=opt.ratio_threshold,
                     min_count=opt.min_fix_ambiguities, max_tries=MAX_PARTIAL_FIX_TRIES,
                     biased_float_false_alarm=BIASED_FLOAT_FALSE_ALARM)


def _take(sp: SatPositions, idx) -> SatPositions:
    """The satellite states of a subset of an epoch's satellites."""
    return SatPositions(*(a[idx] for a in sp))


_BLAS_CONTROLLER: ThreadpoolController | None = None


def _blas_controller() -> ThreadpoolController:
    global _BLAS_CONTROLLER
    if _BLAS_CONTROLLER is None:
        _BLAS_CONTROLLER = ThreadpoolController()
    return _BLAS_CONTROLLER


class RtkFilter:
    """The rover's RTK engine.  Feed it epochs with `step`; it keeps its own state between them."""

    def __init__(self, nav: NavigationData, base_position_m, options: RtkOptions | None = None,
                 base_is_vrs: bool = False, base_antenna: AntennaSetup | None = None,
                 rover_antenna: AntennaSetup | None = None):
        """`base_antenna`/`rover_antenna`: the receivers' ANTEX calibrations and ARP offsets; with them the base
        position and the solution refer to the markers (RTKLIB's ant1/ant2 settings); None: to the phase
        centres as observed (a VRS has a null antenna at its point, nothing to model)."""
        self.nav = nav
        self.base_antenna = base_antenna
        self.rover_antenna = rover_antenna
        self.opt = options or RtkOptions()
        self.base_position_m = np.asarray(base_position_m, dtype=float)
        # a computed (non-physical) base, a network VRS: its residual atmosphere is modelled
        self.base_is_vrs = bool(base_is_vrs)
        self.n_kin = 9 if (self.opt.mode == "kinematic" and self.opt.dynamics) else 3
        # the base's own GF arcs (the quiet-ionosphere rate's base part): the base's, not the filter's, kept by reset
        self._base_rate = ionosphere_prior.BaseRateHistory()
        self.reset()

    def reset(self) -> None:
        """Forget every estimate: the next epoch starts the filter afresh (same settings, base, ephemerides)."""
        # position [, velocity, acceleration], then ("amb", sat, slot) and ("ion", sat) blocks of one state
        self.layout = StateLayout(np.zeros(self.n_kin), np.zeros((self.n_kin, self.n_kin)), reuse_freed=True)
        self.amb_outage: dict[tuple[str, int], int] = {}  # epochs since each SD ambiguity was last used
        # a serial number per ambiguity state: a slip re-initialises it under the same key, a new arc
        self.amb_serial: dict[tuple[str, int], int] = {}
        self._serials = 0
        self.ion_seen: dict[str, float] = {}  # when each SD ionosphere state was last observed
        self.ion_prior_var: dict[str, float] = {}  # the prior variance each SD ionosphere state has [m^2]
        self._learned = ionosphere_prior.LearnedPrior()
        self.iono_active = False
        self._iono_sigma_now = 0.0
        self.confirmation = FixConfirmation(self.opt.min_fix_ambiguities)
        self.consecutive_fixes = 0
        # the quiet-ionosphere hypothesis (`_resolve_quiet`): the GF rate monitor and its own decision streak
        self._quiet = ionosphere_prior.QuietMonitor(self._base_rate)
        self._quiet_confirmation = FixConfirmation(self.opt.min_fix_ambiguities)
        self._quiet_mode = False
        # the newest base epoch behind the first decision of the current streak (a new fix on aged corrections
        # must agree across a new base epoch), per streak: normal, quiet
        self._streak_first_base = {False: math.nan, True: math.nan}
        self._aged = False  # this epoch's corrections are older than correction_age.MIN_AGE_S
        self._last_solution: tuple[float, np.ndarray, np.ndarray] | None = None
        self._spp_inputs: tuple | None = None
        self.initialised = False
        self.geometry: DDGeometry | None = None
        self.t_prev = math.nan
        self.rover_slips = SlipDetector()
        self.base_slips = SlipDetector(max_gap_s=BASE_MAX_ARC_GAP_S, gf_threshold_m=BASE_GF_SLIP_THRESHOLD_M,
                                       gf_drift_m_s=BASE_GF_DRIFT_M_S)
        self._age_var = None  # this epoch's per-satellite SD variance from the corrections' age [m^2]
        self._base_checked_time = math.nan
        self._base_ok = True
        self._base_msg = ""
        self.range_faults: dict[str, float] = {}  # satellite -> when its range jumped (held out of the RTK)

    # -----------------------------------------------------------------------------------------
    # state bookkeeping

    @property
    def x(self) -> np.ndarray:
        return self.layout.x

    @x.setter
    def x(self, value: np.ndarray) -> None:
        self.layout.x = value

    @property
    def P(self) -> np.ndarray:
        return self.layout.P

    @P.setter
    def P(self, value: np.ndarray) -> None:
        self.layout.P = value

    def amb_state(self, key: tuple[str, int]) -> int | None:
        """The state index of the SD ambiguity of (satellite, slot), None when there is none."""
        return self.layout.get(("amb",) + key)

    def ion_state(self, sat: str) -> int | None:
        """The state index of a satellite's SD ionosphere, None when there is none."""
        return self.layout.get(("ion", sat))

    def _amb_indices(self) -> list[int]:
        return [i for key, i in self.layout.items() if key[0] == "amb"]

    def _ion_indices(self) -> list[int]:
        return [i for key, i in self.layout.items() if key[0] == "ion"]

    def _new_amb(self, key: tuple[str, int], value: float) -> None:
        self.layout.add(("amb",) + key, value, INIT_AMBIGUITY_SIGMA_CYC**2)
        self.amb_outage[key] = 0
        self._serials += 1
        self.amb_serial[key] = self._serials

    def _drop_amb(self, key: tuple[str, int]) -> None:
        self.amb_outage.pop(key, None)
        self.amb_serial.pop(key, None)
        self.layout.remove([("amb",) + key])

    def _new_ion(self, sat: str, var: float, t: float) -> None:
        self.layout.add(("ion", sat), 0.0, var)
        self.ion_seen[sat] = t
        self.ion_prior_var[sat] = var

    def _drop_ion(self, sat: str) -> None:
        self.ion_seen.pop(sat, None)
        self.ion_prior_var.pop(sat, None)
        self.layout.remove([("ion", sat)])

    # -----------------------------------------------------------------------------------------

    def step(self, rover: EpochObs, base: EpochObs | None) -> RtkSolution:
        """Process one rover epoch with the latest base epoch (None when there is none).

        The age of corrections is rover time minus base time; over `max_age_s` the status is SINGLE.
        """
        if not np.isfinite(rover.time):
            return RtkSolution(math.nan, Status.NONE, np.full(3, np.nan), np.full((3, 3), np.nan),
                               message="rover epoch without a valid time")
        rover = rover.sanitised()
        self.geometry = None  # this epoch's DD rows, when it is an RTK epoch (the 4001 bound's gain)
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
        spp = self._rover_spp(rover, sp_rover)
        if base is None:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, "no base observations")
        # an interpolated base epoch (post-processing) is as old as the nearer base epoch it was made from
        age = t - base.time if math.isnan(base.info_age_s) else base.info_age_s
        if not np.isfinite(age) or age < -0.5 or age > opt.max_age_s:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, f"corrections stale: age {age:.1f} s over {opt.max_age_s:.1f} s", age)
        if not spp.ok and not self.initialised:
            return self._single(t, spp, "no rover position to start from", age)
        # Base satellites with the rover's ephemeris selection (both ends use the same issue of data).
        sp_base = satellite_positions(self.nav, base.sats, base.time, first_code(base), t_select=t)
        if base.time != self._base_checked_time:
            self._check_base(base, sp_base, t)
        if not self._base_ok:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, self._base_msg, age)
        ref_pos = spp.position_m if spp.ok else self.x[:3]
        baseline = float(np.linalg.norm(ref_pos - self.base_position_m))
        if baseline > opt.max_baseline_m:
            self._time_update(t, spp, advance_only=True)
            return self._single(t, spp, f"baseline {baseline / 1e3:.0f} km beyond {opt.max_baseline_m / 1e3:.0f} km", age)

        self._time_update(t, spp)
        return self._measurement_update(rover, base, spp, age, baseline, sp_rover, sp_base)

    def _rover_spp(self, rover: EpochObs, sp_rover: SatPositions) -> SppResult:
        """The rover's code solution.  From the filter's position (within metres of the code solution) two
        SPP steps are exact to a fraction of a millimetre, all RTK needs of it (a prior of 30 m, a 30 m
        consistency check); a SINGLE solution, which reports the SPP itself, iterates it to convergence
        (see `_single`)."""
        initial = self.x[:3].copy() if self.initialised else None
        self._spp_inputs = (rover, sp_rover, initial)
        spp = solve_spp(rover, self.nav, self._spp_options(), initial_m=initial, sat_positions=sp_rover,
                        steps=ROVER_SPP_STEPS if initial is not None else None)
        if not spp.ok and self.initialised:
            # the filter's position may be the problem
            spp = solve_spp(rover, self.nav, self._spp_options(), sat_positions=sp_rover)
        return spp

    def _check_base(self, base: EpochObs, sp_base: SatPositions, t: float) -> None:
        """Whether the base's coordinates are consistent with its data (once per base epoch)."""
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

    # -----------------------------------------------------------------------------------------
    # time update

    def _time_update(self, t: float, spp: SppResult, advance_only: bool = False) -> None:
        dt = t - self.t_prev if np.isfinite(self.t_prev) else math.inf
        self.t_prev = t
        if np.isfinite(dt) and dt > 0:
            self._random_walk(dt)
        if advance_only and not self.initialised:
            return
        restart = (not self.initialised) or dt > MAX_PREDICTION_GAP_S or dt <= 0
        if self.opt.mode == "static" and not restart:
            return
        if self.opt.mode == "kinematic" and self.n_kin == 3 or restart:
            if self._restart_position(spp, restart):
                return
        if self.n_kin == 9:
            predict_pva(self.x, self.P, dt, self.opt.accel_sigma_h, self.opt.accel_sigma_v)

    def _random_walk(self, dt: float) -> None:
        """The ambiguities' and ionospheres' random walk over dt [s]."""
        for i in self._amb_indices():
            self.P[i, i] += AMBIGUITY_PROCESS_SIGMA_CYC**2 * dt
        q_ion = ionosphere_prior.process_variance(self._iono_sigma_now, dt)
        for i in self._ion_indices():
            self.P[i, i] += q_ion

    def _restart_position(self, spp: SppResult, restart: bool) -> bool:
        """White position (RTKLIB's 'dynamics off'), or a restart: the kinematic states from SPP.  False
        when the dynamic model is to predict them instead (no fresh SPP on an unbroken PVA filter)."""
        nk = self.n_kin
        if not spp.ok:
            if not self.initialised:
                return True
            if restart or self.n_kin == 3:
                # no fresh position: keep the old one with a generous uncertainty
                self.P[:3, :] = 0.0
                self.P[:, :3] = 0.0
                self.P[:3, :3] = np.eye(3) * INIT_POSITION_SIGMA_M**2
                return True
            return False
        self.x[:3] = spp.position_m
        self.P[:nk, :] = 0.0
        self.P[:, :nk] = 0.0
        self.P[:3, :3] = np.eye(3) * INIT_POSITION_SIGMA_M**2
        if nk == 9:
            self.x[3:9] = 0.0
            self.P[3:6, 3:6] = np.eye(3) * INIT_VELOCITY_SIGMA_M_S**2
            self.P[6:9, 6:9] = np.eye(3) * INIT_ACCELERATION_SIGMA_M_S2**2
        self.initialised = True
        return True

    # -----------------------------------------------------------------------------------------
    # measurement update

    def _measurement_update(self, rover: EpochObs, base: EpochObs, spp: SppResult, age: float,
                            baseline_m: float, sp_rover: SatPositions, sp_base: SatPositions) -> RtkSolution:
        opt = self.opt
        t = rover.time
        ep = self._common_epoch(rover, base, sp_rover, sp_base)
        if ep is None:
            return self._single(t, spp, "no satellites common to rover and base", age)
        self._age_var = correction_age.sd_variance_m2(age, len(ep.sats)) if opt.age_variance else None
        self._aged = bool(np.isfinite(age) and abs(age) >= correction_age.MIN_AGE_S)
        self._watch_ionosphere_rate(ep)
        self._restart_slipped(ep)
        self._expire_states(t)
        # linearisation point: the state's position, or for a white-noise position (kinematic without
        # dynamics, restarted from SPP every epoch) the last solution carried by its velocity, usually
        # within centimetres of where this update lands, so one linearisation serves
        x_rov = self._predicted_position(t)
        sd = self._single_differences(ep, x_rov)
        ok, var_sd = self._usable(ep, sd)
        self._hold_range_faults(t, ep.sats, ok)
        sigma0 = self._switch_ionosphere(baseline_m)
        self._add_states(ep, ok, sd.el, sigma0)
        if opt.iono_prior == "learned" and self.iono_active:
            self._tighten_ionosphere(sigma0, sd.el, ep.sats)
        groups = choose_groups(opt.systems, ep.sys_, ok, sd.el, ep.nf, self._amb_variances(ep.sats, ok))
        if not groups:
            return self._single(t, spp, "too few common satellites above the mask", age)
        dd = self._dd_index(groups, ep.sats)
        faulty = self._range_faulty(ep, dd, sd, x_rov, var_sd)
        if faulty:
            # a satellite whose range jumped: out of this epoch's rows (and held), before any state takes it in
            self.range_faults.update({sat: t for sat in faulty})
            self._hold_range_faults(t, ep.sats, ok)
            groups = choose_groups(opt.systems, ep.sys_, ok, sd.el, ep.nf, self._amb_variances(ep.sats, ok))
            if not groups:
                return self._single(t, spp, "too few common satellites above the mask", age)
            dd = self._dd_index(groups, ep.sats)
        n_sat_used = len({k for g in groups for k in g.sats})
        dd, rows, keep = self._screened_rows(ep, dd, groups, sd, x_rov, var_sd)
        x_rov, sd, rows = self._at_phase_position(ep, dd, rows, sd, x_rov, var_sd, keep)
        x_rov, sd = self._iterated_update(ep, dd, rows, sd, x_rov, var_sd, keep)
        self.geometry = DDGeometry(list(ep.sats), sd.los.copy(), dd.k.copy(), dd.ref.copy(), dd.f.copy(),
                                   dd.group.copy(), var_sd.copy(), np.asarray(ep.mu, float).copy())
        self._mark_observed(groups, ep.sats, t)
        sol = self._float_solution(t, n_sat_used, age)
        failure = self._float_failure(sol, spp)
        if failure:
            self.reset()
            return self._single(t, spp, failure, age)
        if opt.ambiguity_resolution:
            self._resolve(sol, dd, ep, sd, x_rov)
        else:
            self.confirmation.reset()
        if not np.all(np.isfinite(sol.velocity_m_s)):
            # no dynamic model: the velocity (for RMC, odometry) comes from the rover's Dopplers
            sol.velocity_m_s, _ = doppler_velocity(rover, self.nav, sol.position_m, opt.elevation_mask_rad,
                                                   sat_positions=sp_rover)
        self._last_solution = (t, sol.position_m.copy(), np.asarray(sol.velocity_m_s, dtype=float).copy())
        return sol

    def _common_epoch(self, rover: EpochObs, base: EpochObs, sp_rover: SatPositions,
                      sp_base: SatPositions) -> _CommonEpoch | None:
        """The satellites both receivers track in the systems used (None when there are none); runs the
        slip detectors on both receivers' whole epochs."""
        opt = self.opt
        common, ri, bi = np.intersect1d(rover.sats, base.sats, return_indices=True)
        sysmask = np.isin(np.array([s[0] for s in common]), list(opt.systems))
        common, ri, bi = common[sysmask], ri[sysmask], bi[sysmask]
        rslip = self.rover_slips.detect(rover)
        # the rover's phases jumped by the same metres on every frequency against their Dopplers: a range
        # fault in space (cycleslip.py), left out and held like the code-and-phase jump (decision 0253)
        self.range_faults.update({str(s): rover.time for s in rover.sats[self.rover_slips.range_jump]})
        bslip = self.base_slips.detect(base)
        nf = min(opt.n_slots, rover.n_slots, base.n_slots)
        if len(common) == 0:
            return None
        ro = rover.take(ri)
        bo = base.take(bi)
        sp_r = _take(sp_rover, ri)
        sp_b = _take(sp_base, bi)
        valid = sp_r.valid & sp_b.valid
        # same issue of data at both ends, or the orbit error does not cancel
        valid &= sp_r.ephemeris_index == sp_b.ephemeris_index
        zd_base = zero_differences(bo, self.base_position_m, sp_b, self.base_antenna, self.opt.tropo_humidity)
        wl = ro.wavelength_m[:, :nf]
        same_wl = np.isclose(wl, bo.wavelength_m[:, :nf], rtol=0, atol=1e-9)
        sats = [str(s) for s in ro.sats]
        sys_ = np.array([s[0] for s in sats])
        mu = (wl / np.array([first_wavelength(s) for s in sys_])[:, None]) ** 2
        return _CommonEpoch(rover.time, sats, sys_, ro, bo, sp_r, nf, valid, zd_base, wl, same_wl, mu,
                            rslip[ri, :nf] | bslip[bi, :nf], bslip[bi, :nf].all(axis=1), bslip[bi, :nf])

    def _restart_slipped(self, ep: _CommonEpoch) -> None:
        """Drop the ambiguities that slipped, and a satellite's ionosphere when every slot of the base
        slipped (a VRS whose data for it were re-synthesised steps by the correction).  The rover losing
        lock (an overbridge, a tunnel) changes its ambiguities, not the atmosphere: the SD ionosphere state
        is kept, with the uncertainty its random walk has gathered, and new ambiguities are fixed against it."""
        for k, sat in enumerate(ep.sats):
            for f in range(ep.nf):
                if ep.slips[k, f]:
                    self._drop_amb((sat, f))
            if self.iono_active and ep.base_slipped_all[k]:
                self._drop_ion(sat)

    def _expire_states(self, t: float) -> None:
        """Drop ambiguities unused for over MAX_AMBIGUITY_OUTAGE_EPOCHS epochs and ionospheres unobserved
        for over ionosphere_prior.MAX_IONO_OUTAGE_S."""
        for key in list(self.amb_outage):
            self.amb_outage[key] += 1
            if self.amb_outage[key] > MAX_AMBIGUITY_OUTAGE_EPOCHS:
                self._drop_amb(key)
        for sat, seen in list(self.ion_seen.items()):
            if not t - seen <= ionosphere_prior.MAX_IONO_OUTAGE_S:
                self._drop_ion(sat)

    def _usable(self, ep: _CommonEpoch, sd: SingleDifferences) -> tuple[np.ndarray, np.ndarray]:
        """Which SD observations (satellite, slot) enter the model: satellite states valid at both ends,
        above the mask, finite phase and code on the same wavelength; and their SD phase variances [m^2]."""
        ok_sat = ep.valid & (sd.el >= self.opt.elevation_mask_rad) & np.isfinite(ep.zd_base.el)
        ok = ok_sat[:, None] & np.isfinite(sd.phase) & np.isfinite(sd.code) & ep.same_wl & np.isfinite(ep.wl)
        var_sd = (self._phase_variance(sd.el) + self._phase_variance(ep.zd_base.el))[:, None] * np.ones((1, ep.nf))
        return ok, var_sd

    def _single_differences(self, ep: _CommonEpoch, x_rov: np.ndarray) -> SingleDifferences:
        """The epoch's SDs with the rover model evaluated at x_rov."""
        return single_differences(zero_differences(ep.rover, x_rov, ep.sp_rover, self.rover_antenna,
                                                   self.opt.tropo_humidity), ep.zd_base,
                                  ep.nf)

    def _phase_variance(self, el: np.ndarray) -> np.ndarray:
        return phase_variance(el, self.opt.phase_sigma_a_m, self.opt.phase_sigma_b_m)

    def _switch_ionosphere(self, baseline_m: float) -> float:
        """The SD ionosphere's prior sigma0 [m] this epoch; the ionosphere enters the model for a VRS or a
        baseline long enough to need it, and then stays -- unless the learned prior (`iono_prior=learned`) shows
        the day's level too small to matter."""
        opt = self.opt
        sigma0 = ionosphere_prior.iono_sigma0(baseline_m, self.base_is_vrs, opt.iono_sigma_m, opt.vrs_iono_sigma_m)
        estimate = ionosphere_prior.estimate_ionosphere(opt.ionosphere, sigma0)
        if opt.iono_prior == "learned" and opt.iono_sigma_m is None and not self.base_is_vrs and self._learned.known:
            # the day's level from fixed satellites (the per-km prior until then), which takes the ionosphere out
            # of the model whenever it allows (one way: without it nothing more is learned)
            sigma0 = self._learned.sigma0_m(baseline_m)
            estimate = ionosphere_prior.estimate_ionosphere(opt.ionosphere, sigma0)
            if not estimate and self.iono_active:
                for sat in list(self.ion_seen):
                    self._drop_ion(sat)
                self.confirmation.reset()
                self.iono_active = False
        if estimate:
            self.iono_active = True
        self._iono_sigma_now = sigma0
        return sigma0

    def _tighten_ionosphere(self, sigma0: float, el: np.ndarray, sats: list[str]) -> None:
        """SD ionosphere states whose prior is wider than the learned one get a zero pseudo-observation making
        up the difference (1/new = 1/old + 1/extra), as if they had started with it (the centre's way,
        docs/decisions/0103)."""
        m = ionosphere_prior.mapping(el)
        for k, sat in enumerate(sats):
            i = self.ion_state(sat)
            old = self.ion_prior_var.get(sat)
            if i is None or old is None:
                continue
            new = ionosphere_prior.prior_variance(sigma0, m[k])
            if not new < ionosphere_prior.PRIOR_TIGHTER_SHARE * old:
                continue
            extra = 1.0 / (1.0 / new - 1.0 / old)
            H = np.zeros((1, len(self.x)))
            H[0, i] = 1.0
            self._kalman_update(np.array([-self.x[i]]), H, np.array([[extra]]))
            self.ion_prior_var[sat] = new

    def _add_states(self, ep: _CommonEpoch, ok: np.ndarray, el: np.ndarray, sigma0: float) -> None:
        """New SD ambiguities from code (cycles) for usable observations without one, and new SD
        ionospheres at their prior."""
        for k, f in zip(*np.nonzero(ok)):
            key = (ep.sats[k], int(f))
            if self.amb_state(key) is None:
                self._new_amb(key, self._sd_code_cycles(ep, k, f))
        if self.iono_active:
            mapping = ionosphere_prior.mapping(el)
            for k in np.flatnonzero(ok.any(axis=1)):
                if self.ion_state(ep.sats[k]) is None:
                    self._new_ion(ep.sats[k], ionosphere_prior.prior_variance(sigma0, mapping[k]), ep.t)

    def _sd_code_cycles(self, ep: _CommonEpoch, k: int, f: int) -> float:
        """An SD ambiguity's code-derived start value [cycles]: SD phase minus SD code over the wavelength."""
        ro, bo = ep.rover, ep.base
        return (ro.phase_cyc[k, f] - bo.phase_cyc[k, f]) - (ro.code_m[k, f] - bo.code_m[k, f]) / ep.wl[k, f]

    def _amb_variances(self, sats: list[str], ok: np.ndarray) -> np.ndarray:
        """Variance [cycles^2] of each usable SD ambiguity (inf where there is no state)."""
        amb_var = np.full(ok.shape, np.inf)
        diagP = np.diag(self.P)
        for k, f in zip(*np.nonzero(ok)):
            i = self.amb_state((sats[k], int(f)))
            if i is not None:
                amb_var[k, f] = diagP[i]
        return amb_var

    def _dd_index(self, groups, sats: list[str]) -> DDIndex:
        return dd_index(groups, lambda k, f: self.layout.index(("amb", sats[k], f)),
                        (lambda k: self.layout.index(("ion", sats[k]))) if self.iono_active else None)

    def _rows(self, ep: _CommonEpoch, dd: DDIndex, sd: SingleDifferences, var_sd: np.ndarray,
              keep: np.ndarray | None) -> Rows:
        """The DD rows at the SDs' linearisation point, those of `keep` only (None: all)."""
        return dd_rows(dd, sd, ep.wl, ep.mu, var_sd, self.x, self._code_phase_ratio(), self._age_var).select(keep)

    def _hold_range_faults(self, t: float, sats: list[str], ok: np.ndarray) -> None:
        """Satellites whose range jumped within RANGE_FAULT_HOLD_S are not usable (`ok` cleared in place)."""
        for sat, t_fault in list(self.range_faults.items()):
            if not t - t_fault <= RANGE_FAULT_HOLD_S:
                del self.range_faults[sat]
            elif sat in sats:
                ok[sats.index(sat), :] = False

    def _range_faulty(self, ep: _CommonEpoch, dd: DDIndex, sd: SingleDifferences, x_rov: np.ndarray,
                      var_sd: np.ndarray) -> set[str]:
        """Satellites whose range jumped against the prior state: a DD whose code innovation is beyond
        RANGE_FAULT_CODE_SIGMAS code sigmas and whose phase innovation agrees with it within as many (a slip
        moves the phase alone, code multipath the code alone; an ambiguity the slip detectors restarted from
        code carries the code's innovation, so the test holds for it too). Attributed like slips (the row's
        satellite, or the group's reference when half its rows jump together)."""
        rows = self._rows(ep, dd, sd, var_sd, None).about(self.x[:3], x_rov)
        m = len(dd.k)
        Hc = rows.H[m:]
        dt = self._prediction_dt(ep.t)
        if dt is None:
            S_code = np.einsum("ij,ij->i", Hc @ self.P, Hc) + np.diag(rows.R)[m:]
        else:
            # linearised at the carried solution: its error, not the white state's 30 m, is the position's part
            nk = self.n_kin
            sig = 0.5 * PREDICTION_ACCEL_M_S2 * dt**2 + PREDICTION_VELOCITY_SIGMA_M_S * dt
            S_code = (np.einsum("ij,ij->i", Hc[:, nk:] @ self.P[nk:, nk:], Hc[:, nk:]) + np.diag(rows.R)[m:]
                      + np.sum(Hc[:, :3] ** 2, axis=1) * sig**2)
        v_ph, v_code = rows.v[:m], rows.v[m:]
        s_code = RANGE_FAULT_CODE_SIGMAS * np.sqrt(S_code)
        jump = (np.abs(v_code) > s_code) & (np.abs(v_code - v_ph) <= s_code)
        if not np.any(jump):
            return set()
        return {sat for sat, _ in slipped_keys(jump, dd, np.ones(m, bool), ep.sats)}

    def _screened_rows(self, ep: _CommonEpoch, dd: DDIndex, groups, sd: SingleDifferences, x_rov: np.ndarray,
                       var_sd: np.ndarray) -> tuple[DDIndex, Rows, np.ndarray]:
        """Prefit screening of the DD rows against the prior state: a phase row with an established
        ambiguity and an innovation beyond max(PHASE_INNOVATION_SIGMAS sigma, PHASE_INNOVATION_MIN_M) is a
        slip the detectors missed (its ambiguities are restarted and the rows rebuilt); code rows beyond
        MAX_CODE_INNOVATION_M are blunders (left out).  Returns the DD index, the rows kept and which."""
        rows = self._rows(ep, dd, sd, var_sd, None).about(self.x[:3], x_rov)
        S_diag = np.einsum("ij,ij->i", rows.H @ self.P, rows.H) + np.diag(rows.R)
        m = len(dd.k)
        known = self.P[dd.i, dd.i] < AMB_KNOWN_SIGMA_CYC**2
        bad_ph = known & (np.abs(rows.v[:m]) > np.maximum(PHASE_INNOVATION_SIGMAS * np.sqrt(S_diag[:m]),
                                                          PHASE_INNOVATION_MIN_M))
        if np.any(bad_ph):
            # a slip: re-initialise the ambiguities involved and rebuild (the reference slipping shows as
            # most of its group's rows failing together)
            for key in slipped_keys(bad_ph, dd, known, ep.sats):
                self._drop_amb(key)
                self._new_amb(key, self._sd_code_cycles(ep, ep.sats.index(key[0]), key[1]))
            dd = self._dd_index(groups, ep.sats)
            rows = self._rows(ep, dd, sd, var_sd, None).about(self.x[:3], x_rov)
        keep = ~((rows.kind == 0) & (np.abs(rows.v) > MAX_CODE_INNOVATION_M))
        return dd, rows.select(keep), keep

    def _at_phase_position(self, ep: _CommonEpoch, dd: DDIndex, rows: Rows, sd: SingleDifferences,
                           x_rov: np.ndarray, var_sd: np.ndarray, keep: np.ndarray):
        """With established ambiguities the phases alone place the rover to millimetres: the rows
        linearised there (a 3-unknown least squares) when that is over RELINEARISE_M from x_rov, rather
        than after a first full update from the SPP prior.  Returns (x_rov, SDs, rows), changed or not."""
        x_phase = self._phase_position(rows, x_rov)
        if x_phase is None or not np.linalg.norm(x_phase - x_rov) > RELINEARISE_M:
            return x_rov, sd, rows
        sd = self._single_differences(ep, x_phase)
        return x_phase, sd, self._rows(ep, dd, sd, var_sd, keep).about(self.x[:3], x_phase)

    def _iterated_update(self, ep: _CommonEpoch, dd: DDIndex, rows: Rows, sd: SingleDifferences,
                         x_rov: np.ndarray, var_sd: np.ndarray, keep: np.ndarray):
        """The Kalman update with `rows`, redone once from the same prior linearised at the updated position
        when that landed more than RELINEARISE_M from x_rov (a start from SPP): a few metres of height error
        in the linearisation point would otherwise bias the height by millimetres (the tropospheric delay
        changes ~0.3 mm per metre of height).  Returns the final linearisation point and its SDs."""
        x_prior, P_prior = self.x.copy(), self.P.copy()
        self._kalman_update(rows.v, rows.H, rows.R)
        if np.linalg.norm(self.x[:3] - x_rov) > RELINEARISE_M:
            x_rov = self.x[:3].copy()
            self.x, self.P = x_prior, P_prior
            sd = self._single_differences(ep, x_rov)
            rows = self._rows(ep, dd, sd, var_sd, keep).about(x_prior[:3], x_rov)
            self._kalman_update(rows.v, rows.H, rows.R)
        return x_rov, sd

    def _mark_observed(self, groups, sats: list[str], t: float) -> None:
        """The ambiguities and ionospheres seen this epoch are fresh."""
        for g in groups:
            for k in g.sats:
                key = (sats[k], g.slot)
                if key in self.amb_outage:
                    self.amb_outage[key] = 0
                if sats[k] in self.ion_seen:
                    self.ion_seen[sats[k]] = t

    def _float_solution(self, t: float, n_sat_used: int, age: float) -> RtkSolution:
        float_pos = self.x[:3].copy()
        return RtkSolution(t, Status.FLOAT, float_pos, self.P[:3, :3].copy(), n_sat_used, age_s=age,
                           baseline_m=float(np.linalg.norm(float_pos - self.base_position_m)),
                           velocity_m_s=self.x[3:6].copy() if self.n_kin == 9 else np.full(3, np.nan),
                           message="float")

    @staticmethod
    def _float_failure(sol: RtkSolution, spp: SppResult) -> str:
        """Why the float solution cannot be trusted (the filter is then restarted), or ''."""
        if not np.all(np.isfinite(sol.position_m)) or np.trace(sol.covariance_m2) > MAX_FLOAT_COVARIANCE_TRACE_M2:
            return "filter diverged, restarted"
        if spp.ok:
            # The float solution must agree with the epoch's own code solution; when it does not, the
            # filter has absorbed bad data.
            gap = float(np.linalg.norm(sol.position_m - spp.position_m))
            if gap > SPP_CONSISTENCY_M + 5.0 * math.sqrt(max(np.trace(spp.covariance_m2), 0.0)):
                return f"filter {gap:.0f} m from SPP, restarted"
        return ""

    def _phase_position(self, rows: Rows, x_lin: np.ndarray) -> np.ndarray | None:
        """The rover position from the DD phases whose ambiguities are established (the row's sigma from
        the states beyond the position below LINEARISATION_SIGMA_M), by weighted least squares about
        x_lin; None when fewer than LINEARISATION_MIN_ROWS such phases or when they do not agree to
        centimetres."""
        ph = rows.kind == 1
        if np.count_nonzero(ph) < LINEARISATION_MIN_ROWS:
            return None
        Hp = rows.H[ph]
        # the rows' uncertainty from everything but the position (DD ambiguities, DD ionosphere)
        Hn = Hp[:, self.n_kin:]
        var = np.einsum("ij,ij->i", Hn @ self.P[self.n_kin:, self.n_kin:], Hn)
        use = var < LINEARISATION_SIGMA_M**2
        if np.count_nonzero(use) < LINEARISATION_MIN_ROWS:
            return None
        G = Hp[use, :3]
        y = rows.v[ph][use] + G @ (self.x[:3] - x_lin)  # innovation at the linearisation point
        w = 1.0 / np.diag(rows.R)[ph][use]
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
        dt = self._prediction_dt(t)
        if dt is not None:
            _, p0, v0 = self._last_solution
            return p0 + v0 * dt
        return self.x[:3].copy()

    def _prediction_dt(self, t: float) -> float | None:
        """How far [s] the last solution is carried to t to linearise at (None: linearised at the state)."""
        last = self._last_solution
        if self.opt.mode == "kinematic" and self.n_kin == 3 and last is not None:
            t0, p0, v0 = last
            dt = t - t0
            if 0.0 < dt <= MAX_LINEARISATION_PREDICTION_S and np.all(np.isfinite(p0)) and np.all(np.isfinite(v0)):
                return dt
        return None

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

    # -----------------------------------------------------------------------------------------
    # integer ambiguity resolution

    def _watch_ionosphere_rate(self, ep: _CommonEpoch) -> None:
        """Feed the quiet-ionosphere monitor this epoch's geometry-free phase (GPS L1 - L2 [m]): the rover's, the
        SD, and the base's own at a measured base epoch."""
        if ep.nf < 2:
            return
        ro, bo = ep.rover, ep.base
        use = (ep.sys_ == "G") & ep.same_wl[:, :2].all(axis=1)
        g_rov = np.where(use, ro.phase_cyc[:, 0] * ep.wl[:, 0] - ro.phase_cyc[:, 1] * ep.wl[:, 1], np.nan)
        g_base = np.where(use, bo.phase_cyc[:, 0] * bo.wavelength_m[:, 0] - bo.phase_cyc[:, 1] * bo.wavelength_m[:, 1],
                          np.nan)
        base_broken = ep.base_slips[:, :2].any(axis=1)
        if math.isnan(bo.newest_epoch_s) and math.isnan(bo.info_age_s):
            self._base_rate.update(bo.time, ep.sats, g_base, base_broken)
        else:
            self._base_rate.break_arcs(ep.sats, base_broken)
        self._quiet.update(ep.t, ep.sats, g_rov - g_base, ep.slips[:, :2].any(axis=1), g_rov)

    def observe_base_history(self, base: EpochObs) -> None:
        """A measured base epoch before the rover's first (post-processing: the base file's past), for the base's
        part of the quiet-ionosphere rate; its LLI carries its slips (`base_interpolation.flag_slips`)."""
        if base.n_slots < 2:
            return
        b = base.sanitised()
        sats = [str(s) for s in b.sats]
        use = np.array([s[0] == "G" for s in sats], dtype=bool)
        gf = np.where(use, b.phase_cyc[:, 0] * b.wavelength_m[:, 0] - b.phase_cyc[:, 1] * b.wavelength_m[:, 1], np.nan)
        self._base_rate.update(b.time, sats, gf, ((b.lli[:, :2] & LLI_SLIP) != 0).any(axis=1))

    def _quiet_applies(self, ep: _CommonEpoch) -> bool:
        """Whether to try the quiet-ionosphere hypothesis this epoch: the ionosphere in the model on the per-km
        prior of a physical base, the learned level not known yet.  (Its fix is declared only once the GF rate
        says the night is quiet, `_quiet_rate_ok`; its decisions agree or not whatever the rate.)"""
        opt = self.opt
        return (self.iono_active and opt.iono_prior == "learned" and opt.iono_sigma_m is None
                and not self.base_is_vrs and not self._learned.known and self.consecutive_fixes == 0)

    def _quiet_rate_ok(self, ep: _CommonEpoch) -> bool:
        """The GF rate of the satellites above the mask says the DD ionosphere is quiet (QuietMonitor.quiet)."""
        el = ep.zd_base.el
        return self._quiet.quiet(ep.t, ep.sats, np.where(el >= self.opt.elevation_mask_rad, el, np.nan))

    def _resolve(self, sol: RtkSolution, dd: DDIndex, ep: _CommonEpoch, sd: SingleDifferences,
                 x_lin: np.ndarray) -> None:
        """Integer ambiguity resolution (`_resolve_with`), first under the quiet-ionosphere hypothesis when it
        applies: the DD ionosphere tightened to QUIET_SIGMA_M (a pseudo-observation on a copy of the state), its
        own streak of agreeing decisions, and a fix kept only when it passes its own check (ratio, residuals, and
        its DD ionosphere within QUIET_CHECK_SIGMAS of that prior, `_quiet_consistent`); otherwise the state
        is restored and the normal prior decides."""
        if dd.ion is None or not self._quiet_applies(ep):
            self._quiet_confirmation.reset()
            self._resolve_with(sol, dd, ep, sd, x_lin)
            return
        x0, P0, conf0 = self.x.copy(), self.P.copy(), self.confirmation
        self._tight_ionosphere(dd, ep)
        self.confirmation, self._quiet_mode = self._quiet_confirmation, True
        try:
            self._resolve_with(sol, dd, ep, sd, x_lin)
        finally:
            self.confirmation, self._quiet_mode = conf0, False
        if sol.status == Status.FIX:
            sol.message = f"{sol.message} (quiet ionosphere)"
            return
        quiet_msg = sol.message
        self.x, self.P = x0, P0
        self._resolve_with(sol, dd, ep, sd, x_lin)
        if sol.status != Status.FIX:
            sol.message = f"{sol.message}; quiet hypothesis: {quiet_msg}"

    def _tight_ionosphere(self, dd: DDIndex, ep: _CommonEpoch) -> None:
        """The SD ionosphere states of this epoch's rows pulled to the quiet prior (zero, QUIET_SIGMA_M x M)."""
        ks = np.unique(np.concatenate((dd.k, dd.ref)))
        states = [self.ion_state(ep.sats[k]) for k in ks]
        keep = np.array([i is not None for i in states], dtype=bool)
        if not keep.any():
            return
        idx = np.array([i for i in states if i is not None])
        var = ionosphere_prior.prior_variance(ionosphere_prior.QUIET_SIGMA_M,
                                              ionosphere_prior.mapping(ep.zd_base.el[ks[keep]]))
        # one update with independent rows: the same as one satellite at a time, in one product
        H = np.zeros((len(idx), len(self.x)))
        H[np.arange(len(idx)), idx] = 1.0
        self._kalman_update(-self.x[idx], H, np.diag(np.broadcast_to(var, idx.shape).astype(float)))

    def _quiet_consistent(self, dd: DDIndex, ep: _CommonEpoch, rows: np.ndarray, attempt: "_FixAttempt") -> bool:
        """A quiet fix's own check: every fixed row's DD ionosphere within QUIET_CHECK_SIGMAS of the quiet prior."""
        el = ep.zd_base.el
        m = np.hypot(ionosphere_prior.mapping(el[dd.k[rows]]), ionosphere_prior.mapping(el[dd.ref[rows]]))
        ion = attempt.x[dd.ion[rows]] - attempt.x[dd.ion_ref[rows]]
        return bool(np.all(np.abs(ion) <= ionosphere_prior.QUIET_CHECK_SIGMAS * ionosphere_prior.QUIET_SIGMA_M * m))

    def _resolve_with(self, sol: RtkSolution, dd: DDIndex, ep: _CommonEpoch, sd: SingleDifferences,
                      x_lin: np.ndarray) -> None:
        """Integer ambiguity resolution on this epoch's DD ambiguities; on success `sol` becomes FIX.

        A fixed solution must leave DD phase residuals at the noise level.  When it does not, one
        satellite's phase is usually at fault (multipath, a slip too small to detect): the worst row
        is left out and the search repeated, up to AR_EXCLUSION_RETRIES times.  When no subset passes
        at all: without the ionosphere in the model the satellite fitting the float worst is left out;
        with it (float residuals then say little, the ionosphere states absorb them) the lowest
        satellite is, as its ionosphere prior is the loosest and its multipath the largest (partial
        resolution by elevation).

        With the ionosphere in the model a fix is declared only after consecutive epochs of agreeing
        integer decisions (`_confirm`).  A validated partial fix (ratio, success rate and phase residuals
        passed, but too few combinations fixed to pin the position to MAX_FIXED_POSITION_SIGMA_M:
        typically the wide-lane-like combinations first) is such a decision too, and counts towards the
        streak; the fix declared is always a complete one.
        """
        rows = np.arange(len(dd.k))
        n_all = len(rows)
        message = ""
        partial: tuple[_FixAttempt, np.ndarray] | None = None  # this epoch's first validated partial fix
        for _attempt in range(AR_EXCLUSION_RETRIES + 1):
            if len(rows) < self.opt.min_fix_ambiguities:
                message = message or "float: too few ambiguities to fix"
                break
            result = self._try_fix(dd, rows, ep, sd, x_lin)
            if isinstance(result, str):
                message = result
                if result != NO_SUBSET_MESSAGE:
                    break
                if self.iono_active:
                    rows = _without_lowest(dd, rows, sd.el)
                else:
                    # the satellite fitting the float solution worst is the likely culprit (multipath, an
                    # undetected slip)
                    res = phase_residuals(dd, rows, sd, ep.wl, ep.mu, x_lin, self.x)
                    rows = np.delete(rows, int(np.argmax(np.abs(res))))
                continue
            max_sigma, max_res = self._fixed_limits(dd, rows, sd)
            worst = int(np.argmax(np.abs(result.residuals) / max_res))
            residual_ok = abs(result.residuals[worst]) <= max_res[worst]
            if result.sigma_m > max_sigma:
                # A partial fix of a few combinations (wide-lane-like) can pass its tests and still leave
                # the position at float precision: that is not an RTK fix and is not reported as one,
                # but its integers are a decision the next epochs' fixes must agree with.
                message = f"float: fixed subset ({result.fix.count}) leaves position sigma {result.sigma_m * 100:.0f} cm"
                if partial is None and residual_ok:
                    partial = (result, rows)
                if not self.iono_active:
                    break
                rows = _without_lowest(dd, rows, sd.el)
                continue
            if residual_ok:
                self._declare_or_confirm(sol, dd, ep, rows, result, n_all)
                return
            message = f"float: fixed solution rejected (phase residual {abs(result.residuals[worst]) * 100:.1f} cm)"
            # leave the worst satellite out (its reference too if every row of the group is bad)
            rows = np.delete(rows, worst)
        self.consecutive_fixes = 0
        if partial is not None and self._confirm_needed() > 1:
            attempt, prows = partial
            count = self._confirm(dd, prows, attempt, ep)
            message = f"{message}; {attempt.fix.count} combinations fixed, agreeing over {count} epochs"
        else:
            self.confirmation.reset()
        sol.message = message

    def _fixed_limits(self, dd: DDIndex, rows: np.ndarray, sd: SingleDifferences) -> tuple[float, np.ndarray]:
        """The largest 3-D position sigma [m] and DD phase residuals [m] (per row) a fixed solution of `rows`
        may have: MAX_FIXED_POSITION_SIGMA_M and MAX_FIXED_PHASE_RESIDUAL_M, grown by what aged corrections
        alone give a fixed solution (the position covariance (G^T A^-1 G)^-1 of the age's DD covariance A,
        the rows' own age sigma times AGE_RESIDUAL_SIGMAS): the age is no reason to doubt integers already
        fixed.  Only while a declared fix continues: a new fix needs the limits themselves (with a 30 s base a
        1 Hz rover reuses each base epoch's noise 30 times, and the float grows overconfident between base
        epochs: at 144 km relaxed limits let 6-of-14 partial fixes 80 cm off through, docs/decisions/0162)."""
        if self._age_var is None or not np.any(self._age_var > 0.0) or self.consecutive_fixes == 0:
            return MAX_FIXED_POSITION_SIGMA_M, np.full(len(rows), MAX_FIXED_PHASE_RESIDUAL_M)
        k, ref = dd.k[rows], dd.ref[rows]
        A = correction_age.dd_covariance(k, ref, self._age_var)
        max_res = np.sqrt(MAX_FIXED_PHASE_RESIDUAL_M**2 + AGE_RESIDUAL_SIGMAS**2 * np.diag(A))
        # one slot's rows (the others carry the same age error): the age-only fixed position covariance
        f0 = np.bincount(dd.f[rows]).argmax()
        sel = dd.f[rows] == f0
        G = -(sd.los[k[sel]] - sd.los[ref[sel]])
        try:
            Ai = np.linalg.inv(A[np.ix_(sel, sel)])
            age_var = float(np.trace(np.linalg.inv(G.T @ Ai @ G)))
        except np.linalg.LinAlgError:
            age_var = 0.0
        return math.sqrt(MAX_FIXED_POSITION_SIGMA_M**2 + max(age_var, 0.0)), max_res

    def _declare_or_confirm(self, sol: RtkSolution, dd: DDIndex, ep: _CommonEpoch, rows: np.ndarray,
                            attempt: _FixAttempt, n_all: int) -> None:
        """A validated complete fix: declared when its decision has agreed long enough, else a candidate."""
        count = self._confirm(dd, rows, attempt, ep)
        need = self._confirm_needed()
        spans = self._spans_base_epochs(ep, need)
        quiet_ok = not self._quiet_mode or self._quiet_consistent(dd, ep, rows, attempt)
        rate_ok = not self._quiet_mode or self._quiet_rate_ok(ep)
        if count >= need and spans and quiet_ok and rate_ok:
            self._accept_fix(sol, attempt, n_all)
            # not from a partial quiet fix: its DD ionosphere was pulled to zero by the quiet prior itself, and a
            # level learned from it took the unfixed satellites' ionosphere out (UPC2 05:40, decision 0221)
            if (self.opt.iono_prior == "learned" and dd.ion is not None
                    and not (self._quiet_mode and attempt.fix.count < n_all)):
                r = rows[dd.f[rows] == 0]
                el = ep.zd_base.el
                m = np.hypot(ionosphere_prior.mapping(el[dd.k[r]]), ionosphere_prior.mapping(el[dd.ref[r]]))
                self._learned.learn_fixed(ep.t, (attempt.x[dd.ion[r]] - attempt.x[dd.ion_ref[r]]) / m)
            keys = [(ep.sats[dd.k[r]], ep.sats[dd.ref[r]], int(dd.f[r])) for r in rows]
            sol.fixed_dd = FixedIntegers.determined(keys, attempt.x, attempt.P, dd.i[rows], dd.iref[rows])
        else:
            self.consecutive_fixes = 0
            fix = attempt.fix
            sol.message = f"float: fix candidate {count}/{need} ({fix.count}/{n_all} ambiguities, ratio {fix.ratio:.1f})"
            if count >= need and not spans:
                sol.message += ", waiting for a new base epoch"
            if not quiet_ok:
                sol.message += ", DD ionosphere beyond the quiet prior"
                self.confirmation.reset()
            elif not rate_ok:
                sol.message += ", GF rate not quiet (yet)"

    def _spans_base_epochs(self, ep: _CommonEpoch, need: int) -> bool:
        """Whether a new fix's streak of agreeing decisions spans two base epochs, as it must on aged
        corrections when a streak is needed at all: a 1 Hz rover reuses (or interpolates between) each 30 s base
        epoch, so decisions within one base epoch share its errors and agree without proving anything."""
        if need <= 1 or not self._aged or self.consecutive_fixes > 0:
            return True
        return ep.base.newest_time != self._streak_first_base[self._quiet_mode]

    def _confirm_needed(self) -> int:
        """Consecutive agreeing decisions a fix needs: the setting, else 1 for a short baseline (the model is
        exact to millimetres) and CONFIRM_EPOCHS_WITH_IONOSPHERE with residual atmosphere in the model."""
        if self.opt.confirm_epochs is not None:
            return max(1, int(self.opt.confirm_epochs))
        return CONFIRM_EPOCHS_WITH_IONOSPHERE if self.iono_active else 1

    def _confirm(self, dd: DDIndex, rows: np.ndarray, attempt: _FixAttempt, ep: _CommonEpoch) -> int:
        """The length of the streak of agreeing decisions this validated (complete or partial) fix ends (and
        the newest base epoch behind the streak's first decision noted)."""
        if self._confirm_needed() <= 1:
            return 1  # declared at once: nothing to compare with
        count = self._observe(dd, rows, attempt)
        if count <= 1:
            self._streak_first_base[self._quiet_mode] = ep.base.newest_time
        return count

    def _observe(self, dd: DDIndex, rows: np.ndarray, attempt: _FixAttempt) -> int:
        key_of = {i: key for key, i in self.layout.items()}

        def identity(i: int):  # an SD ambiguity state's (satellite, slot) and arc serial
            key = key_of[i][1:]
            return key, self.amb_serial[key]

        def index_of(ident) -> int:
            key, serial = ident
            return self.amb_state(key) if self.amb_serial.get(key) == serial else -1

        decision = IntegerDecision.from_fix(identity, dd.i[rows], dd.iref[rows], attempt.Hc, attempt.fix.z_fixed,
                                            attempt.x, attempt.P)
        return self.confirmation.observe(decision, index_of, attempt.x, attempt.P)

    def _try_fix(self, dd: DDIndex, rows: np.ndarray, ep: _CommonEpoch, sd: SingleDifferences,
                 x_lin: np.ndarray) -> _FixAttempt | str:
        """A partial fix of the DD ambiguities of `rows` and the state conditioned on it, or why not."""
        i, iref = dd.i[rows], dd.iref[rows]
        idx = np.unique(np.concatenate((i, iref)))
        n = len(rows)
        D = np.zeros((n, len(idx)))  # SD -> DD
        D[np.arange(n), np.searchsorted(idx, i)] = 1.0
        D[np.arange(n), np.searchsorted(idx, iref)] = -1.0
        a_dd = D @ self.x[idx]
        Q_dd = D @ self.P[np.ix_(idx, idx)] @ D.T
        try:
            fix = partial_fix(a_dd, Q_dd, fix_policy(self.opt))
        except AmbiguityError as exc:
            return f"float: ambiguity covariance unusable ({exc})"
        if fix is None:
            return NO_SUBSET_MESSAGE
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
        return _FixAttempt(fix, Hc, x_fix, P_fix, phase_residuals(dd, rows, sd, ep.wl, ep.mu, x_lin, x_fix), sigma)

    def _accept_fix(self, sol: RtkSolution, attempt: _FixAttempt, n_all: int) -> None:
        fix, x_fix, P_fix = attempt.fix, attempt.x, attempt.P
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
            v = fix.z_fixed - attempt.Hc @ self.x
            self._kalman_update(v, attempt.Hc, np.eye(fix.count) * HOLD_VARIANCE_CYC2)


def _without_lowest(dd: DDIndex, rows: np.ndarray, el: np.ndarray) -> np.ndarray:
    """`rows` without every row (each slot) of their lowest satellite: partial resolution by elevation,
    the lowest satellite having the loosest ionosphere and the most multipath."""
    low = dd.k[rows][np.argmin(el[dd.k[rows]])]
    return rows[dd.k[rows] != low]
