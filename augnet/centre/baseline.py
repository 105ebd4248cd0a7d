"""Ambiguity resolution on one baseline between two reference stations with known coordinates.

The station coordinates are surveyed, so the network solves ambiguities and atmosphere, not positions.
Per epoch (network-rtk.md, "the network engine"):

1. Geometry at each station: satellite positions at transmission (Sagnac included), satellite clocks and
   the receiver clock from the code, so g = rho - c*dts is right to the millimetre.
2. Cycle slips per station and satellite: loss-of-lock flags, geometry-free phase jumps, gaps. A slip
   restarts that satellite's ambiguities (its ionosphere state carries on).
3. A Kalman filter on the double differences (DD) of code and phase on both frequencies, ionosphere
   weighted: states are the residual zenith wet delay of each station (with a prior on their difference),
   and per satellite the between-station single-difference (SD) slant ionosphere on f1 (a random walk with
   a wide prior in ppm of the baseline length, vertical, mapped with the elevation: a storm's, so that no
   state is ever pulled by a prior the day disproves), the SD ambiguities on f1 and f2, and the SD code and
   phase multipath on f1 and f2 (first-order Gauss-Markov: static-station multipath is correlated over
   minutes, and a white-noise model made the float covariance several times too optimistic). This is the
   uncombined equivalent of Melbourne-Wuebbena wide-lane fixing followed by ionosphere-free narrow-lane
   fixing, and it uses the ionosphere prior in addition, which is what rejects the near-equivalent integer
   pairs (e.g. N1 + 7, Nw - 2 on GPS L1/L2; (3, 4) on Galileo E1/E5a) that the ionosphere-free phase alone
   cannot tell apart.
4. LAMBDA with partial fixing on the DD ambiguities (both frequencies, wide-lane pre-transform), ratio
   test and bootstrapped success rate, the float solution conditioned on the ionosphere prior in force (DD
   ionosphere is ~1-4 ppm of the baseline on a quiet day, network-rtk.md: the quiet default, raised by the
   ionosphere's rate measured from the SD geometry-free phase before anything is committed, then the day's
   level learned from the fixed satellites of the whole network, or, where tighter, the network's single-layer
   ionosphere model's prediction, centred on the vertical TEC times the stations' mapping-function difference)
   and on the network's ionosphere hints
   (other baselines' fixed satellites, `network.py`) when there are any; a DD ambiguity is fixed when the
   conditioned solution pins it to an integer and the same integer has come out on several consecutive
   epochs (fewer when the success rate is very high); a wide lane pinned on its own is held while its
   narrow lane is open; fixed ones are held as tight constraints (fix and hold), a new satellite is fixed
   against the held ones, and fixed ones are released when the phase residuals stop supporting them.
5. With the integers known, the DD phase residuals on f1 and f2 split into the dispersive part (DD slant
   ionosphere on f1) and the non-dispersive part (DD troposphere beyond the model plus orbit error): the
   corrections the network interpolates.

SD ambiguities carry the SD receiver phase bias, common to one system's satellites, so only their DD are
integers; fixed values are kept as DD integers against each system's reference satellite and re-referenced
when the reference changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.observations import StationEpoch
from augnet.centre.satellite_geometry import SatelliteGeometry, satellite_geometry
from augnet.gnss import combinations as comb
from augnet.gnss.ambiguity import AmbiguityError, partial_fix
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.ionosphere import thin_shell_mapping

C = SPEED_OF_LIGHT_M_S
FREQS = 2  # dual-frequency network processing
# Per-satellite state block: SD ionosphere on f1 [m], SD ambiguities N1, N2 [cycles], then (when modelled) SD
# code multipath on f1 and f2 [m] and SD phase multipath on f1 and f2 [m]; offsets within the block.
_IONO, _N1 = 0, 1


@dataclass(frozen=True)
class BaselineConfig:
    elevation_mask_deg: float = 10.0
    # Reference satellite: the highest one, kept while it stays above this elevation.
    ref_min_elevation_deg: float = 20.0
    # Undifferenced noise sigma^2(el) = s^2 + s^2 / sin^2(el) (RTKLIB's a = b form) for phase and code: s =
    # sigma_zenith / sqrt(2), here 3 mm and 0.3 m at zenith, a geodetic station's figures (network-rtk.md).
    phase_sigma_m: float = 0.0021
    code_sigma_m: float = 0.21
    code_correlation_inflation: float = 1.0  # scales the whole code sigma (white and multipath)
    # Multipath: this share of the variance is not white but a first-order Gauss-Markov (AR(1)) process per
    # station, satellite and signal with a correlation time of minutes (a static antenna). The filter
    # carries it as states per satellite and frequency (the SD of the two stations'), for code and for
    # phase, so that averaging buys what it really buys: a minute of code is still about one sample of its
    # multipath, and the ionosphere-free phase (which amplifies phase multipath ~3x, to ~1 cm in a DD)
    # does not separate the near-equivalent integer pairs (GPS (4, 5): 5 cm, BDS B1I/B3I (4, 5): 3.6 cm,
    # Galileo E1/E5a (3, 4): 6 mm) within seconds. With white-noise weights the float covariance was
    # several times too optimistic after a minute, the success rate meant little, and the ratio test let
    # wrong integers through (Galileo (3, 4), a low BDS GEO (-4, -5)). Share 0 gives the white model.
    code_multipath_share: float = 0.5
    code_multipath_tau_s: float = 120.0
    phase_multipath_share: float = 0.3
    phase_multipath_tau_s: float = 120.0
    # Residual zenith wet delay: prior and random walk (a few mm to a cm per sqrt(hour)).
    zwd_prior_sigma_m: float = 0.10
    # ... and of the difference between the two stations' (a few cm over tens of km: the wet field is
    # smooth), which is what the DD troposphere depends on.
    zwd_relative_prior_sigma_m: float = 0.03
    zwd_random_walk_m2_s: float = 2.0e-8
    # SD ionosphere: prior and random walk in parts per million of the baseline length, vertical, mapped to
    # slant with the single-layer mapping function at `iono_shell_height_km` (a satellite at 15 degrees sees
    # ~2.5 times the zenith's difference); None: the same slant figure at every elevation. The prior is
    # what separates the wide-lane candidates (one wide-lane cycle with the ionosphere-free phase kept is
    # 0.57-0.8 m of DD ionosphere), so it must be the day's: a quiet mid-latitude day gives DD 1-4 ppm
    # (network-rtk.md); the simulator's quiet day gives 0.9-1.5 ppm RMS per station pair in these units.
    # The baseline then moves it to what its fixed satellites show (`iono_prior_adapt`): the day's level.
    iono_prior_ppm: float = 1.5
    iono_prior_min_m: float = 0.01
    iono_rate_ppm_sqrt_s: float = 0.05
    iono_shell_height_km: float | None = 350.0
    iono_prior_adapt: float = 1.2  # the day's prior: this times the RMS seen on fixed satellites (0: off)
    iono_prior_adapt_tau_s: float = 300.0
    # The day's level replaces the default prior, lower or higher, once this many satellites are fixed; it is
    # the RMS's one-sided 95 % upper bound (chi-square, one degree of freedom per fixed satellite: the
    # satellites fixed first are the ones the default prior agreed with, a sample biased low), never below
    # the floor. Satellites already in the filter get the tighter prior as an ionosphere pseudo-observation
    # in the integer decision (`_fix`), not in the state. On the simulator's quiet day the fixed satellites
    # show 0.2-0.7 ppm (rising to 0.55-0.67 over ten minutes as the low ones join), a moderate day 1.0-1.6.
    iono_day_min_sats: int = 4
    iono_day_floor_ppm: float = 0.7
    # The filter's own SD ionosphere prior [ppm]: wide enough for a storm. The prior in force (the default, the
    # measured activity's or the day's level) enters the integer decision only, as a DD ionosphere
    # pseudo-observation making up the difference (`_prior_hints`): a state that took 1.5 ppm on a storm day
    # has already pulled its ambiguities along the ionosphere's near-null direction (towards the wrong wide lane
    # and the (4, 5)-type pairs), and no variance added later undoes that.
    iono_state_prior_ppm: float = 10.0
    # Ionosphere activity from the SD geometry-free phase (`_measure_activity`): increments over this lag, the
    # smoothing and the increments needed before the rate counts
    activity_lag_s: float = 10.0
    activity_tau_epochs: float = 30.0
    activity_min_samples: int = 40
    # What the activity says about the prior: an ionosphere that moves fast is seldom flat. Before the day's level
    # is known the prior in force is raised to this many ppm per ppm/sqrt(s) of measured rate (0: off), and
    # nothing is fixed before the rate is known. The simulator's levels (network-70km, 50 km baselines) move at
    # 0-0.02 (quiet, moderate), 0.02-0.05 (active) and 0.065-0.10 (storm) ppm/sqrt(s), with fixed satellites
    # showing 0.6, 1.5-3.4, 4-11 and 7-15 ppm: 150 keeps the quiet default and covers the others; a network in
    # service should fit it to its own history.
    iono_activity_ppm_per_rate: float = 150.0
    # The random walk of the SD ionosphere states: the configured rate or this times the measured one
    activity_rate_margin: float = 1.5
    # Initial SD ambiguity sigma [cycles]: set from code, so a few hundred cycles covers anything.
    amb_prior_sigma_cyc: float = 300.0
    # Satellites below this elevation stay float (their corrections are not produced): at 10-15 degrees the
    # code multipath leaves the wide lane uncertain, and near-equivalent integer pairs (Galileo E1/E5a
    # dN = (3, 4): 6 mm in the ionosphere-free phase, 0.57 m of DD ionosphere) pass the ratio test there.
    fix_min_elevation_deg: float = 15.0
    # LAMBDA validation and confirmation.
    fix_ratio: float = 2.0
    fix_min_success_rate: float = 0.9999
    fix_min_count: int = 4
    # With this many DD ambiguities already held, a new satellite's pair may be fixed on its own.
    fix_min_count_held: int = 2
    fix_confirm_epochs: int = 5
    # ... fewer when the fixed block's bootstrapped success rate is this high.
    fix_confirm_epochs_sure: int = 2
    fix_sure_success_rate: float = 0.999999
    # DD ambiguities still this uncertain [cycles] stay out of the integer search (they cannot be fixed
    # yet and only make the decorrelation slower).
    search_max_sigma_cyc: float = 5.0
    pinned_sigma_cyc: float = 0.05  # conditioned DD ambiguity sigma at which it counts as pinned
    hold_sigma_cyc: float = 0.001  # applied once per newly fixed ambiguity (they have no process noise)
    # A fixed DD whose post-fit phase residual stays above this for `release_epochs` is released.
    release_residual_m: float = 0.04
    release_epochs: int = 3
    # An arc restarts after a gap longer than this [s].
    max_gap_s: float = 30.0
    # Ionosphere hints from the network (NetworkSolver): a satellite fixed on other baselines gives, through a
    # linear model of the DD ionosphere over the network (a gradient per satellite pair), a prediction for this
    # baseline. Its error grows with the distance between the baselines' midpoints: this many ppm of the
    # baseline length per 100 km of that distance, times the mapping sqrt(M_s^2 + M_ref^2); the simulator's
    # quiet day shows 0.23 ppm RMS (0.6 max) at 50 km (0.45 ppm per 100 km), so 0.8 leaves room.
    iono_hints: bool = True
    # ... and, from baselines with no station in common, their float ionosphere where the satellite is not
    # fixed there either (independent data: the two baselines' code together pin the ionosphere better)
    iono_hints_float: bool = True
    iono_hint_ppm_per_100km: float = 0.8
    iono_hint_max_distance_km: float = 150.0
    # The network's single-layer ionosphere model (`network.py`, `ionosphere_model`): the DD ionosphere of a
    # satellite low at both stations holds a term the zero-mean prior ignores, the vertical TEC times the
    # difference of the two stations' mapping functions (up to ~10 cm at 15 degrees on the quiet day); fitted
    # over the fixed satellites, it centres the prior of the satellites not yet fixed, whose spread is then
    # the model's residual level (its 95 % upper bound times `iono_prior_adapt`, never below this floor)
    # instead of the day's. The floor stands to the quiet day's residual RMS after the model (0.41 ppm, the
    # simulator's truth on network-70km) as the day's floor (0.7) to its RMS around zero (0.56): 1.2-1.25
    # times it. 0 ppm: no model.
    iono_model_floor_ppm: float = 0.5
    iono_model_min_dd: int = 8  # fixed DD ionospheres the network needs before it fits the model
    # The model's prediction replaces the day's prior only where its variance is below this share of the day's:
    # a one-parameter fit to the same satellites pays for itself only where the mapping term is a large part of
    # the DD ionosphere. Measured (network-70km, truth): quiet day, satellites at 15-20 degrees, the prediction
    # misses by 7.4 cm RMS against 9.2 cm for zero, at a sigma 20 % below the day's; on a storm it is 2-4 %
    # tighter and less well calibrated (|error| / sigma RMS 1.04 against 0.84 above 30 degrees).
    iono_model_max_variance_share: float = 0.8
    # Time constant of the smoothing of DD residuals [s]: the DD ionosphere from the geometry-free phase
    # carries ~2x the phase noise (1-2 cm at low elevation) while the ionosphere itself changes by
    # millimetres per minute over a network baseline; 30 s removes most noise for a few mm of lag.
    residual_smoothing_s: float = 30.0


@dataclass
class _Track:
    """What the baseline remembers about one satellite."""

    t_last: float = -math.inf
    gf_a: float = math.nan
    gf_b: float = math.nan
    epochs: int = 0
    candidate: list = field(default_factory=lambda: [None, None, None])  # per table: N1, N2, wide lane
    streak: list = field(default_factory=lambda: [0, 0, 0])
    bad_streak: int = 0
    sd_gf: list = field(default_factory=list)  # recent (t, SD geometry-free phase [m]) of the current arc

    def reset_decisions(self) -> None:
        """Forget the integer candidates and their confirmation counts."""
        self.candidate, self.streak = [None, None, None], [0, 0, 0]


@dataclass
class BaselineEpoch:
    """One epoch's outcome on a baseline. DD quantities are satellite minus its system's reference."""

    t_gpst: float
    refs: dict[str, str]  # system -> reference satellite
    sats: np.ndarray  # (S,) satellites used this epoch (references included)
    elevation_a_deg: np.ndarray
    elevation_b_deg: np.ndarray
    fixed: np.ndarray  # (S,) bool: DD integers on both frequencies known; references are True
    dd_n: np.ndarray  # (S, 2) DD integers (NaN where not fixed; 0 for references)
    dd_iono_m: np.ndarray  # (S,) DD slant ionosphere on f1 [m] where fixed; 0 for references
    dd_trop_m: np.ndarray  # (S,) DD non-dispersive residual beyond the troposphere model [m]
    freq_hz: np.ndarray  # (S, 2)
    slips: list[str] = field(default_factory=list)
    zwd_m: tuple[float, float] = (0.0, 0.0)
    ratio: float = 0.0
    eligible: np.ndarray | None = None  # (S,) bool: high enough to be fixed (fix_min_elevation_deg)
    # (S,) the filter's DD ionosphere on f1 [m] against the reference and its variance [m^2], fixed or not
    iono_float_m: np.ndarray | None = None
    iono_float_var_m2: np.ndarray | None = None

    def is_reference(self) -> np.ndarray:
        return np.isin(self.sats, list(self.refs.values()))

    @property
    def fixed_fraction(self) -> float:
        """Fixed share of the DD ambiguities that may be fixed (satellites above the fixing mask)."""
        count = ~self.is_reference()
        if self.eligible is not None:
            count &= self.eligible
        return float(self.fixed[count].mean()) if count.any() else 0.0


class BaselineSolver:
    """Integer ambiguities and DD residuals between stations a and b, epoch after epoch."""

    def __init__(self, name_a: str, xyz_a_m, name_b: str, xyz_b_m, config: BaselineConfig | None = None):
        self.name_a = name_a
        self.name_b = name_b
        self.xyz_a = np.asarray(xyz_a_m, float)
        self.xyz_b = np.asarray(xyz_b_m, float)
        self.length_m = float(np.linalg.norm(self.xyz_b - self.xyz_a))
        self.cfg = config or BaselineConfig()
        cfg = self.cfg
        self.tracks: dict[str, _Track] = {}
        self.refs: dict[str, str] = {}
        # sat -> DD integer against refs[sys]: N1, N2, and the wide lane N1 - N2 (held on its own while the
        # narrow lane is still open)
        self.fixed: list[dict[str, int]] = [{}, {}, {}]
        self.clock = {"a": 0.0, "b": 0.0}
        self.t_last = -math.inf
        # Kalman filter: x = [zwd_a, zwd_b, (I, N1, N2, code M1, M2, phase M1, M2) per satellite at self.index[sat]]
        self._mpc = 3 if cfg.code_multipath_share > 0 else None
        self._mpp = (3 + 2 * (self._mpc is not None)) if cfg.phase_multipath_share > 0 else None
        self._block = 3 + 2 * (self._mpc is not None) + 2 * (self._mpp is not None)
        self.x = np.zeros(2)
        # zwd_a = c - r/2, zwd_b = c + r/2 with c the common and r the relative residual wet delay
        vc = max(cfg.zwd_prior_sigma_m**2 - cfg.zwd_relative_prior_sigma_m**2 / 4.0, 0.0)
        vr = cfg.zwd_relative_prior_sigma_m**2
        self.P = np.array([[vc + vr / 4.0, vc - vr / 4.0], [vc - vr / 4.0, vc + vr / 4.0]])
        self.index: dict[str, int] = {}
        self._smooth: dict[str, tuple] = {}  # sat -> (ref, integers, t, iono, trop)
        self._iono_ms: float | None = None  # mean square of fixed satellites' DD ionosphere [ppm^2, vertical]
        self._iono_day_own: float | None = None  # the day's prior from this baseline's fixed satellites [ppm]
        self.iono_day_network: float | None = None  # ... from the whole network's (set by NetworkSolver) [ppm]
        self.iono_day_q = np.zeros(0)  # this epoch's fixed satellites' DD ionosphere [ppm, vertical]
        # mean squared SD geometry-free increments and their spans: one epoch, and the lag [ppm^2, s, ppm^2, s]
        self._activity: np.ndarray | None = None
        self._activity_samples = 0
        self.iono_rate_network: float | None = None  # the network's mean rate (set by NetworkSolver)
        self._dry_level: float | None = None  # prior in force while decisions ran without committing [ppm]
        self._iono_p0: dict[str, float] = {}  # sat -> prior variance its SD ionosphere state started with [m^2]

    @property
    def name(self) -> str:
        return f"{self.name_a}-{self.name_b}"

    # --- state bookkeeping ---------------------------------------------------------------------

    def _iono_mapping(self, el_rad: np.ndarray) -> np.ndarray:
        """Slant over vertical ionosphere (single layer), or ones without a shell height."""
        if self.cfg.iono_shell_height_km is None:
            return np.ones_like(el_rad)
        return thin_shell_mapping(el_rad, 1e3 * self.cfg.iono_shell_height_km)

    def _add_states(self, sat: str, iono_m: float, n1: float, n2: float, mp_code_var_m2: float,
                    mp_phase_var_m2: float, iono_var_scale: float = 1.0) -> None:
        n = len(self.x)
        B = self._block
        self.x = np.concatenate([self.x, [iono_m, n1, n2], np.zeros(B - 3)])
        P = np.zeros((n + B, n + B))
        P[:n, :n] = self.P
        P[n, n] = max((self.cfg.iono_state_prior_ppm * 1e-6 * self.length_m) ** 2 * iono_var_scale,
                      self.cfg.iono_prior_min_m**2)
        self._iono_p0[sat] = P[n, n]
        P[n + 1, n + 1] = P[n + 2, n + 2] = self.cfg.amb_prior_sigma_cyc**2
        if self._mpc is not None:
            P[n + self._mpc, n + self._mpc] = P[n + self._mpc + 1, n + self._mpc + 1] = mp_code_var_m2
        if self._mpp is not None:
            P[n + self._mpp, n + self._mpp] = P[n + self._mpp + 1, n + self._mpp + 1] = mp_phase_var_m2
        self.P = P
        self.index[sat] = n

    def _remove_states(self, sats) -> None:
        drop = [self.index.pop(s) for s in sats if s in self.index]
        if not drop:
            return
        gone = np.concatenate([np.arange(p, p + self._block) for p in drop])
        keep = np.setdiff1d(np.arange(len(self.x)), gone)
        self.x = self.x[keep]
        self.P = self.P[np.ix_(keep, keep)]
        order = sorted(self.index.items(), key=lambda kv: kv[1])
        self.index = {s: 2 + self._block * k for k, (s, _) in enumerate(order)}

    def _restart_ambiguities(self, sat: str, n1: float, n2: float) -> None:
        """A slip: the satellite's ambiguities start afresh (its ionosphere state carries on)."""
        p = self.index[sat]
        for q, val in ((p + 1, n1), (p + 2, n2)):
            self.P[q, :] = 0.0
            self.P[:, q] = 0.0
            self.P[q, q] = self.cfg.amb_prior_sigma_cyc**2
            self.x[q] = val
        for table in self.fixed:
            table.pop(sat, None)
        tr = self.tracks[sat]
        tr.reset_decisions()

    def _set_reference(self, system: str, new_ref: str) -> None:
        """Switch a system's reference satellite, carrying fixed DD integers over where possible."""
        old = self.refs.get(system)
        self.refs[system] = new_ref
        if old is None or old == new_ref:
            return
        for table in self.fixed:
            offset = table.get(new_ref)  # N(new_ref, old)
            sats = [s for s in table if s[0] == system]
            if offset is None:
                for s in sats:
                    del table[s]
                continue
            for s in sats:
                table[s] = table[s] - offset  # N(s, new) = N(s, old) - N(new, old)
            table.pop(new_ref, None)
            table[old] = -offset
        for s, tr in self.tracks.items():
            if s[0] == system:
                tr.reset_decisions()

    # --- one epoch -----------------------------------------------------------------------------

    def update(self, ep_a: StationEpoch, ep_b: StationEpoch, nav: NavigationData,
               geom_a: SatelliteGeometry | None = None, geom_b: SatelliteGeometry | None = None,
               excluded: set[str] | frozenset[str] = frozenset(),
               iono_hints: dict[str, tuple[str, float, float]] | None = None,
               iono_model: dict[str, tuple[str, float, float]] | None = None) -> BaselineEpoch | None:
        """One epoch. `geom_a`/`geom_b`: the stations' geometry for all their satellites (the network
        computes it once per station); `excluded`: satellites the integrity monitor has taken out;
        `iono_hints`: sat -> (reference satellite, DD ionosphere on f1 [m], its variance [m^2]) predicted from
        the other baselines' fixed satellites, used in the integer decision only (never in the filter state:
        the same prediction epoch after epoch is not new information); `iono_model`: the same, from the network's
        ionosphere model fitted over every baseline's fixed satellites, a prior (replacing the day's) rather than
        independent data."""
        cfg = self.cfg
        t = ep_a.t_gpst
        if abs(ep_b.t_gpst - t) > 1e-3:
            raise ValueError(f"{self.name}: epochs not aligned ({ep_a.t_gpst} vs {ep_b.t_gpst})")
        a, b, ia, ib = _common_dual_frequency(ep_a, ep_b, excluded)
        if a is None:
            return None
        if geom_a is None:
            geom_a = satellite_geometry(ep_a.sats, t, self.xyz_a, nav, ep_a.code_m[:, 0], self.clock["a"])
        if geom_b is None:
            geom_b = satellite_geometry(ep_b.sats, t, self.xyz_b, nav, ep_b.code_m[:, 0], self.clock["b"])
        ga, gb = geom_a.subset(ia), geom_b.subset(ib)
        self.clock["a"], self.clock["b"] = ga.clock_s, gb.clock_s
        mask = math.radians(cfg.elevation_mask_deg)
        use = ga.valid & gb.valid & (ga.elevation_rad >= mask) & (gb.elevation_rad >= mask)
        if use.sum() < 2:
            return None
        a, b, ga, gb = a.subset(use), b.subset(use), ga.subset(use), gb.subset(use)
        sats = a.sats
        f = a.freq_hz  # (S, 2)
        lam = C / f
        gamma = (f[:, 0] / f[:, 1]) ** 2
        # undifferenced observables minus the known geometry and the troposphere model [m]
        phase_a = a.phase_cyc * lam - (ga.g_m + ga.trop_model_m)[:, None]
        phase_b = b.phase_cyc * lam - (gb.g_m + gb.trop_model_m)[:, None]
        code_a = a.code_m - (ga.g_m + ga.trop_model_m)[:, None]
        code_b = b.code_m - (gb.g_m + gb.trop_model_m)[:, None]
        sd_phase = phase_b - phase_a
        sd_code = code_b - code_a

        slipped, new_arc = self._detect_slips(t, a, b, f)
        self._choose_references(sats, ga, gb, slipped, new_arc)
        # initial SD ambiguities from phase minus code (the ionosphere state starts at its zero-mean prior)
        n0 = (sd_phase - sd_code) / lam
        shape = 2.0 + 1.0 / np.sin(ga.elevation_rad) ** 2 + 1.0 / np.sin(gb.elevation_rad) ** 2
        mp_var = cfg.code_multipath_share * (cfg.code_sigma_m * cfg.code_correlation_inflation) ** 2 * shape
        mpp_var = cfg.phase_multipath_share * cfg.phase_sigma_m**2 * shape
        iono_scale = self._iono_mapping(np.minimum(ga.elevation_rad, gb.elevation_rad))
        self._measure_activity(t, sats, slipped | new_arc, iono_scale, gamma)
        for k, s in enumerate(sats):
            s = str(s)
            if s in new_arc or s not in self.index:
                self._remove_states([s])
                self.tracks[s] = _Track()
                for table in self.fixed:
                    table.pop(s, None)
                self._add_states(s, 0.0, n0[k, 0], n0[k, 1], mp_var[k], mpp_var[k], iono_scale[k] ** 2)
            elif s in slipped:
                self._restart_ambiguities(s, n0[k, 0], n0[k, 1])
        gone = [s for s in self.index if s not in set(sats.tolist())]
        self._remove_states(gone)
        for s in gone:
            for table in self.fixed:
                table.pop(s, None)
        for k, s in enumerate(sats):
            tr = self.tracks[str(s)]
            tr.t_last = t
            tr.epochs += 1

        # prediction
        dt = t - self.t_last if np.isfinite(self.t_last) else 0.0
        self.t_last = t
        self.P[0, 0] += cfg.zwd_random_walk_m2_s * dt
        self.P[1, 1] += cfg.zwd_random_walk_m2_s * dt
        slots = np.array([self.index[str(s)] for s in sats])
        self.P[slots, slots] += self.iono_q * iono_scale**2 * dt
        if dt > 0 and (self._mpc is not None or self._mpp is not None):
            # AR(1) multipath: x <- phi x, P <- F P F^T + (1 - phi^2) var(el)
            decay = np.ones(len(self.x))  # not `f`: that name holds the frequencies
            innovation = []
            for off, tau, var in ((self._mpc, cfg.code_multipath_tau_s, mp_var),
                                  (self._mpp, cfg.phase_multipath_tau_s, mpp_var)):
                if off is None:
                    continue
                phi = math.exp(-dt / tau)
                mp = np.concatenate([slots + off, slots + off + 1])
                self.x[mp] *= phi
                decay[mp] = phi
                innovation.append((mp, (1.0 - phi**2) * np.concatenate([var, var])))
            self.P *= decay[:, None] * decay[None, :]
            for mp, q in innovation:
                self.P[mp, mp] += q

        # measurement update with all DD code and phase
        ref_of = np.array([self.refs[s[0]] for s in sats])
        pos = {s: k for k, s in enumerate(sats)}
        ref_k = np.array([pos[r] for r in ref_of])
        rows = np.array([k for k in range(len(sats)) if sats[k] != ref_of[k]], dtype=int)
        if rows.size == 0:
            return None
        self._kalman_update(*self._dd_model(sats, rows, ref_k, ga, gb, lam, gamma, sd_phase, sd_code))
        self._hold(sats, rows, ref_k)
        self._release(sats, rows, ref_k, ga, gb, lam, gamma, sd_phase, sd_code)
        el_min = np.degrees(np.minimum(ga.elevation_rad, gb.elevation_rad))
        # Nothing is fixed before the ionosphere's rate is known; the decisions run meanwhile, so their
        # confirmation counts are ready when it is, and are dropped if the rate raises the prior they used.
        rate_known = cfg.iono_activity_ppm_per_rate <= 0 or self.iono_rate is not None
        level = self.iono_level_ppm
        if rate_known and self._dry_level is not None and level > 1.05 * self._dry_level:
            for tr in self.tracks.values():
                tr.reset_decisions()
        self._dry_level = None if rate_known else level
        ratio = self._fix(sats, rows[el_min[rows] >= cfg.fix_min_elevation_deg], ref_k,
                          self._prior_hints(sats, rows, ref_k, iono_scale, iono_hints, iono_model), commit=rate_known)

        # DD residuals where the integers are known
        n = len(sats)
        dd_n = np.full((n, 2), np.nan)
        for k, s in enumerate(sats):
            if s == ref_of[k]:
                dd_n[k] = 0.0
            elif s in self.fixed[0] and s in self.fixed[1]:
                dd_n[k] = (self.fixed[0][s], self.fixed[1][s])
        fixed = np.isfinite(dd_n).all(axis=1)
        ps = slots + _IONO
        pr = slots[ref_k] + _IONO
        dd = sd_phase - sd_phase[ref_k]
        r = dd - lam * dd_n
        dd_iono = (r[:, 0] - r[:, 1]) / (gamma - 1.0)
        dd_trop = (gamma * r[:, 0] - r[:, 1]) / (gamma - 1.0)
        self._learn_ionosphere(dt, fixed & (sats != ref_of), ref_k, iono_scale, dd_iono)
        dd_iono, dd_trop = self._smoothed(t, sats, ref_of, dd_n, fixed, dd_iono, dd_trop)
        return BaselineEpoch(
            t_gpst=t, refs=dict(self.refs), sats=sats.copy(),
            elevation_a_deg=np.degrees(ga.elevation_rad), elevation_b_deg=np.degrees(gb.elevation_rad),
            fixed=fixed, dd_n=dd_n, dd_iono_m=np.where(fixed, dd_iono, np.nan),
            dd_trop_m=np.where(fixed, dd_trop, np.nan), freq_hz=f.copy(), slips=sorted(slipped),
            zwd_m=(float(self.x[0]), float(self.x[1])), ratio=ratio,
            eligible=el_min >= cfg.fix_min_elevation_deg, iono_float_m=self.x[ps] - self.x[pr],
            iono_float_var_m2=self.P[ps, ps] + self.P[pr, pr] - 2.0 * self.P[ps, pr])

    # --- pieces of an epoch --------------------------------------------------------------------

    def _learn_ionosphere(self, dt, fixed, ref_k, mapping, dd_iono) -> None:
        """This epoch's fixed satellites' DD ionosphere in the prior's units (vertical ppm; `iono_day_q`, which the
        network pools), their running mean square, and from it this baseline's own day level."""
        cfg = self.cfg
        self.iono_day_q = np.zeros(0)
        if cfg.iono_prior_adapt <= 0 or not fixed.any():
            return
        q = dd_iono[fixed] / (1e-6 * self.length_m * np.hypot(mapping[fixed], mapping[ref_k[fixed]]))
        q = q[np.isfinite(q)]
        if not q.size:
            return
        self.iono_day_q = q
        ms = float(np.mean(q**2))
        if self._iono_ms is None:
            self._iono_ms = ms
        else:
            self._iono_ms += min(1.0, dt / cfg.iono_prior_adapt_tau_s) * (ms - self._iono_ms)
        level = day_ionosphere_ppm(math.sqrt(self._iono_ms), q.size, cfg)
        if level is not None:
            self._iono_day_own = level

    @property
    def iono_day_ppm(self) -> float | None:
        """The day's ionosphere prior [ppm, vertical]: the network's (pooled over every baseline's fixed
        satellites) where there is one, else this baseline's own; None until either is known. (Taking the larger
        of the two let a baseline's own estimate from its first four satellites, whose 95 % bound is 2.4 times
        their RMS, hold it back for minutes.)"""
        return self.iono_day_network if self.iono_day_network is not None else self._iono_day_own

    @property
    def iono_level_ppm(self) -> float:
        """The ionosphere prior in force [ppm, vertical]: the day's level once known; before, the default
        raised (never lowered) by the measured activity and by what the few fixed satellites show."""
        cfg = self.cfg
        ppm = self.iono_day_ppm
        if ppm is not None:
            return ppm
        ppm = cfg.iono_prior_ppm
        rate = self.iono_rate
        if rate is not None and cfg.iono_activity_ppm_per_rate > 0:
            ppm = max(ppm, cfg.iono_activity_ppm_per_rate * rate)
        if self._iono_ms is not None and cfg.iono_prior_adapt > 0:
            ppm = max(ppm, cfg.iono_prior_adapt * math.sqrt(self._iono_ms))
        return ppm

    def iono_state_prior_dd(self, sat: str, ref: str) -> float:
        """The prior variance the DD ionosphere (sat - ref) had in the filter state [m^2] (NaN if unknown)."""
        return self._iono_p0.get(sat, math.nan) + self._iono_p0.get(ref, math.nan)

    @property
    def iono_rate(self) -> float | None:
        """The ionosphere's rate [ppm/sqrt(s)]: the network's mean where there is one, else this baseline's."""
        if self.iono_rate_network is not None:
            return self.iono_rate_network
        return self.iono_rate_ppm_sqrt_s

    @property
    def iono_rate_ppm_sqrt_s(self) -> float | None:
        """This baseline's measured SD ionosphere rate [ppm/sqrt(s), vertical], None until enough increments."""
        if self._activity is None or self._activity_samples < self.cfg.activity_min_samples:
            return None
        ms_short, dt_short, ms_long, dt_long = self._activity
        if not dt_long > dt_short:
            return None
        return math.sqrt(max(ms_long - ms_short, 0.0) / (dt_long - dt_short))

    @property
    def iono_q(self) -> float:
        """Random-walk variance rate of the SD ionosphere states, vertical [m^2/s]: the configured rate, or
        `activity_rate_margin` times the measured one where that is higher."""
        rate = max(self.cfg.iono_rate_ppm_sqrt_s, self.cfg.activity_rate_margin * (self.iono_rate or 0.0))
        return (rate * 1e-6 * self.length_m) ** 2

    def _measure_activity(self, t, sats, restarted, mapping, gamma) -> None:
        """How fast the ionosphere moves between the stations, from the SD geometry-free phase (no ambiguity
        within an arc, no clock, no geometry: its changes are the SD ionosphere's, plus noise). Per satellite,
        the increment since the previous epoch and since one at least `activity_lag_s` (and three epochs) back,
        squared, in vertical ppm of the baseline: E[d^2] = 2 sigma^2 + q dt for white phase noise sigma and a
        random walk of rate q, so the two means give q whatever the observation interval."""
        cfg = self.cfg
        short, long_ = [], []  # (squared increment [ppm^2], its time span [s])
        for k, s in enumerate(sats):
            tr = self.tracks[str(s)]
            if str(s) in restarted:
                tr.sd_gf = []
            gf = tr.gf_b - tr.gf_a
            if not math.isfinite(gf):
                continue
            scale = 1.0 / ((gamma[k] - 1.0) * mapping[k] * 1e-6 * self.length_m)
            hist = tr.sd_gf
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
        a = 1.0 if self._activity is None else 1.0 / cfg.activity_tau_epochs
        self._activity = now if self._activity is None else self._activity + a * (now - self._activity)
        self._activity_samples += len(long_)

    def _prior_hints(self, sats, rows, ref_k, mapping, hints, model=None):
        """The network's hints, plus, where the prior in force is tighter than the one a satellite's ionosphere
        state (and its reference's) started with, a DD ionosphere pseudo-observation whose variance makes up the
        difference (1/new = 1/old + 1/hint): as if the satellite had started with it (combined with the
        network's hint where there is one). The prior in force is the day's level around zero, or the network's
        ionosphere model's prediction (`model`: sat -> (reference, DD ionosphere [m], variance [m^2])) where
        that is tighter."""
        out = dict(hints or {})
        day = (self.iono_level_ppm * 1e-6 * self.length_m) ** 2
        floor = self.cfg.iono_prior_min_m**2
        for k in rows:
            s, r = str(sats[k]), str(sats[ref_k[k]])
            if s in self.fixed[0] and s in self.fixed[1]:
                continue
            old = self.iono_state_prior_dd(s, r)
            mean, new = 0.0, max(day * mapping[k] ** 2, floor) + max(day * mapping[ref_k[k]] ** 2, floor)
            m = (model or {}).get(s)
            if m is not None and m[0] == r and m[2] < self.cfg.iono_model_max_variance_share * new:
                mean, new = m[1], max(m[2], 2.0 * floor)
            if not new < 0.9 * old:
                continue
            v = 1.0 / (1.0 / new - 1.0 / old)
            z = mean * v / new  # the state started at zero: prior mean = z * new / v
            h = out.get(s)
            if h is not None and h[0] == r:  # a network hint as well: two independent pseudo-observations
                out[s] = (r, (z * h[2] + h[1] * v) / (v + h[2]), h[2] * v / (v + h[2]))
            elif h is None:
                out[s] = (r, z, v)
        return out

    def _smoothed(self, t, sats, ref_of, dd_n, fixed, iono, trop):
        """Exponential smoothing of each satellite's DD residuals while its reference and integers stay."""
        tau = self.cfg.residual_smoothing_s
        out_i, out_t = iono.copy(), trop.copy()
        for k, s in enumerate(sats):
            s = str(s)
            if not fixed[k] or s == ref_of[k] or tau <= 0:
                self._smooth.pop(s, None)
                continue
            key = (ref_of[k], float(dd_n[k, 0]), float(dd_n[k, 1]))
            prev = self._smooth.get(s)
            if prev is None or prev[0] != key or t - prev[1] > self.cfg.max_gap_s:
                si, st = iono[k], trop[k]
            else:
                a = min(1.0, (t - prev[1]) / tau)
                si = prev[2] + a * (iono[k] - prev[2])
                st = prev[3] + a * (trop[k] - prev[3])
            self._smooth[s] = (key, t, si, st)
            out_i[k], out_t[k] = si, st
        return out_i, out_t

    def _detect_slips(self, t, a: StationEpoch, b: StationEpoch, f) -> tuple[set[str], set[str]]:
        gf_a = comb.geometry_free_phase_m(a.phase_cyc[:, 0], a.phase_cyc[:, 1], f[:, 0], f[:, 1])
        gf_b = comb.geometry_free_phase_m(b.phase_cyc[:, 0], b.phase_cyc[:, 1], f[:, 0], f[:, 1])
        lli = ((a.lli & 1).any(axis=1)) | ((b.lli & 1).any(axis=1))
        slipped: set[str] = set()
        new_arc: set[str] = set()
        for k, s in enumerate(a.sats):
            s = str(s)
            tr = self.tracks.get(s)
            if tr is None or s not in self.index or t - tr.t_last > self.cfg.max_gap_s:
                new_arc.add(s)
            else:
                dt = t - tr.t_last
                if lli[k] or comb.slip_geometry_free(tr.gf_a, gf_a[k], dt) or \
                        comb.slip_geometry_free(tr.gf_b, gf_b[k], dt):
                    slipped.add(s)
            if tr is not None:
                tr.gf_a, tr.gf_b = gf_a[k], gf_b[k]
            else:
                self.tracks[s] = _Track(gf_a=gf_a[k], gf_b=gf_b[k])
        return slipped, new_arc

    def _choose_references(self, sats, ga: SatelliteGeometry, gb: SatelliteGeometry, slipped, new_arc):
        """Keep each system's reference while it is healthy and high; else move to the best satellite,
        before slipped satellites are reset, so the others keep their integers."""
        systems = np.array([s[0] for s in sats])
        el_min = np.minimum(ga.elevation_rad, gb.elevation_rad)
        for system in np.unique(systems):
            in_sys = np.flatnonzero(systems == system)
            healthy = [k for k in in_sys if sats[k] not in slipped and sats[k] not in new_arc]
            cur = self.refs.get(system)
            cur_k = next((k for k in healthy if sats[k] == cur), None)
            if cur_k is not None and el_min[cur_k] >= math.radians(self.cfg.ref_min_elevation_deg):
                continue
            pool = healthy if healthy else list(in_sys)
            best = max(pool, key=lambda k: (sats[k] in self.fixed[0] and sats[k] in self.fixed[1], el_min[k]))
            self._set_reference(system, str(sats[best]))
        for system in list(self.refs):
            if system not in systems:
                del self.refs[system]

    def _dd_model(self, sats, rows, ref_k, ga, gb, lam, gamma, sd_phase, sd_code):
        """Design matrix, DD observations and their covariance for code and phase on both frequencies."""
        cfg = self.cfg
        m = rows.size
        z = np.zeros(4 * m)
        cols = np.zeros((4 * m, 8), dtype=int)  # the design matrix by rows: 8 (column, value) pairs each
        vals = np.zeros((4 * m, 8))
        sin_a2 = np.sin(ga.elevation_rad) ** 2
        sin_b2 = np.sin(gb.elevation_rad) ** 2
        shape = 2.0 + 1.0 / sin_a2 + 1.0 / sin_b2  # SD variance / s^2
        var_phase_sd = (1.0 - cfg.phase_multipath_share) * cfg.phase_sigma_m**2 * shape
        var_code_sd = (1.0 - cfg.code_multipath_share) * (cfg.code_sigma_m * cfg.code_correlation_inflation) ** 2 * shape
        d_wet_a = ga.wet_mapping[rows] - ga.wet_mapping[ref_k[rows]]
        d_wet_b = gb.wet_mapping[rows] - gb.wet_mapping[ref_k[rows]]
        ps = np.array([self.index[str(sats[k])] for k in rows])
        pr = np.array([self.index[str(sats[ref_k[k]])] for k in rows])
        g = gamma[rows]
        blocks = (  # (observation, ionosphere coefficient, ambiguity slot or None, frequency)
            ("P", 1.0, None, 0), ("P", g, None, 1), ("L", -1.0, 1, 0), ("L", -g, 2, 1))
        R = np.zeros((4 * m, 4 * m))
        for i, (kind, icoef, slot, fq) in enumerate(blocks):
            sl = slice(i * m, (i + 1) * m)
            entries = [(0, -d_wet_a), (1, d_wet_b), (ps + _IONO, icoef), (pr + _IONO, -icoef)]
            if slot is not None:
                entries += [(ps + slot, lam[rows, fq]), (pr + slot, -lam[rows, fq])]
            mp_off = self._mpp if kind == "L" else self._mpc
            if mp_off is not None:
                entries += [(ps + mp_off + fq, 1.0), (pr + mp_off + fq, -1.0)]
            for j, (c, v) in enumerate(entries):
                cols[sl, j] = c
                vals[sl, j] = v
            obs = sd_phase[:, fq] if kind == "L" else sd_code[:, fq]
            z[sl] = obs[rows] - obs[ref_k[rows]]
            var = var_phase_sd if kind == "L" else var_code_sd
            # DD covariance: each DD has its own SD variance plus its reference's, shared with the DDs of
            # the same reference.
            same_ref = ref_k[rows][:, None] == ref_k[rows][None, :]
            R[sl, sl] = np.diag(var[rows]) + np.where(same_ref, var[ref_k[rows]][:, None], 0.0)
        return cols, vals, z, R

    def _kalman_update(self, cols: np.ndarray, vals: np.ndarray, z: np.ndarray, R: np.ndarray) -> None:
        """Measurement update with a sparse design matrix given by rows: H[r, cols[r, j]] += vals[r, j]."""
        P = self.P
        HP = np.zeros((cols.shape[0], P.shape[0]))
        for j in range(cols.shape[1]):
            HP += vals[:, j, None] * P[cols[:, j]]
        S = R.copy()
        for j in range(cols.shape[1]):
            S += HP[:, cols[:, j]] * vals[None, :, j]
        innov = z - (vals * self.x[cols]).sum(axis=1)
        try:  # S = L L^T: K = HP^T S^-1 and P - K HP = P - W^T W with W = L^-1 HP
            Li = np.linalg.inv(np.linalg.cholesky(S))
        except np.linalg.LinAlgError:
            return
        W = Li @ HP
        self.x = self.x + W.T @ (Li @ innov)
        P = P - W.T @ W
        self.P = 0.5 * (P + P.T)

    def _dd_ambiguity_rows(self, sats, ks, ref_k, fq) -> tuple[np.ndarray, np.ndarray]:
        """Rows picking DD ambiguities out of the state, as (columns, values): N1 (fq 0), N2 (fq 1) or the wide
        lane N1 - N2 (fq 2)."""
        ps = np.array([self.index[str(sats[k])] for k in ks], dtype=int)
        pr = np.array([self.index[str(sats[ref_k[k]])] for k in ks], dtype=int)
        one = np.ones(len(ks))
        if fq < FREQS:
            return np.column_stack([ps + _N1 + fq, pr + _N1 + fq, ps, ps]), np.column_stack([one, -one, 0 * one, 0 * one])
        return (np.column_stack([ps + _N1, pr + _N1, ps + _N1 + 1, pr + _N1 + 1]),
                np.column_stack([one, -one, -one, one]))

    def _hold(self, sats, rows, ref_k) -> None:
        """Fixed DD integers as tight pseudo-observations (fix and hold); a wide lane held on its own where the
        satellite's narrow lane is still open."""
        cs, vs, zs = [], [], []
        for fq in range(FREQS + 1):
            held = [k for k in rows if str(sats[k]) in self.fixed[fq]]
            if fq == FREQS:
                held = [k for k in held if not (str(sats[k]) in self.fixed[0] and str(sats[k]) in self.fixed[1])]
            if not held:
                continue
            c, v = self._dd_ambiguity_rows(sats, held, ref_k, fq)
            cs.append(c)
            vs.append(v)
            zs.append(np.array([self.fixed[fq][str(sats[k])] for k in held], float))
        if not cs:
            return
        cols, vals, zh = np.vstack(cs), np.vstack(vs), np.concatenate(zs)
        # Ambiguities have no process noise: a held one stays held after one update; apply the constraint
        # where it is new (or its state was reset), not again every epoch.
        P = self.P
        var = np.zeros(len(zh))
        for i in range(cols.shape[1]):
            for j in range(cols.shape[1]):
                var += vals[:, i] * vals[:, j] * P[cols[:, i], cols[:, j]]
        new = var > 2.0 * self.cfg.hold_sigma_cyc**2
        if new.any():
            self._kalman_update(cols[new], vals[new], zh[new], np.eye(int(new.sum())) * self.cfg.hold_sigma_cyc**2)

    def _release(self, sats, rows, ref_k, ga, gb, lam, gamma, sd_phase, sd_code) -> None:
        """Post-fit DD phase residuals of fixed satellites; a wrong fix shows as a persistent residual. A released
        satellite's ambiguities start afresh (the hold has pinned their states to the integers let go)."""
        cfg = self.cfg
        for k in rows:
            s = str(sats[k])
            if s not in self.fixed[0] and s not in self.fixed[1]:
                continue
            r = ref_k[k]
            p, q = self.index[s], self.index[str(sats[r])]
            trop = (-(ga.wet_mapping[k] - ga.wet_mapping[r]) * self.x[0]
                    + (gb.wet_mapping[k] - gb.wet_mapping[r]) * self.x[1])
            d_iono = self.x[p] - self.x[q]
            worst = 0.0
            for fq, icoef in ((0, 1.0), (1, gamma[k])):
                if s not in self.fixed[fq]:
                    continue
                pred = trop - icoef * d_iono + lam[k, fq] * self.fixed[fq][s]
                worst = max(worst, abs(sd_phase[k, fq] - sd_phase[r, fq] - pred))
            tr = self.tracks[s]
            if worst > cfg.release_residual_m:
                tr.bad_streak += 1
                if tr.bad_streak >= cfg.release_epochs:
                    n0 = (sd_phase[k] - sd_code[k]) / lam[k]
                    self._restart_ambiguities(s, n0[0], n0[1])
                    tr.bad_streak = 0
            else:
                tr.bad_streak = 0

    def _with_hints(self, sats, rows, ref_k, hints, D, a_hat, Q):
        """The float ambiguities (a_hat, Q) conditioned on DD ionosphere pseudo-observations."""
        hs = []
        for k in rows:
            s = str(sats[k])
            h = hints.get(s)
            if h is None or h[0] != str(sats[ref_k[k]]) or (s in self.fixed[0] and s in self.fixed[1]):
                continue
            hs.append((self.index[s] + _IONO, self.index[h[0]] + _IONO, h[1], h[2]))
        if not hs:
            return a_hat, Q
        H = np.zeros((len(hs), len(self.x)))
        H[np.arange(len(hs)), [h[0] for h in hs]] = 1.0
        H[np.arange(len(hs)), [h[1] for h in hs]] = -1.0
        z = np.array([h[2] for h in hs])
        PHt = self.P @ H.T
        S = H @ PHt + np.diag([h[3] for h in hs])
        DPHt = D @ PHt
        try:
            G = np.linalg.solve(S, DPHt.T).T  # D P H^T S^-1
        except np.linalg.LinAlgError:
            return a_hat, Q
        return a_hat + G @ (z - H @ self.x), Q - G @ DPHt.T

    def _fix(self, sats, rows, ref_k, iono_hints=None, commit: bool = True) -> float:
        """LAMBDA with partial fixing over the DD ambiguities not yet fixed (both frequencies), the float
        solution conditioned on the network's ionosphere hints when there are any."""
        cfg = self.cfg
        cands = [(k, fq) for fq in range(FREQS) for k in rows if str(sats[k]) not in self.fixed[fq]]
        # DD ambiguity = state[ia] - state[ib]: rows of D without building it
        ia = np.array([self.index[str(sats[k])] + _N1 + fq for k, fq in cands], dtype=int)
        ib = np.array([self.index[str(sats[ref_k[k]])] + _N1 + fq for k, fq in cands], dtype=int)
        P = self.P
        ready = P[ia, ia] + P[ib, ib] - 2.0 * P[ia, ib] <= cfg.search_max_sigma_cyc**2
        for i in np.flatnonzero(~ready):
            k, fq = cands[i]
            tr = self.tracks[str(sats[k])]
            tr.candidate[fq], tr.streak[fq] = None, 0
        cands = [c for c, r in zip(cands, ready) if r]
        ia, ib = ia[ready], ib[ready]
        held = sum(len(self.fixed[fq]) for fq in range(FREQS))
        min_count = cfg.fix_min_count if held < cfg.fix_min_count else min(cfg.fix_min_count, cfg.fix_min_count_held)
        if len(cands) < min_count:
            return 0.0
        a_hat = self.x[ia] - self.x[ib]
        DP = P[ia] - P[ib]
        Q = DP[:, ia] - DP[:, ib]
        D = None
        if iono_hints:
            D = np.zeros((len(cands), len(self.x)))
            D[np.arange(len(cands)), ia] = 1.0
            D[np.arange(len(cands)), ib] -= 1.0
        if iono_hints:
            a_hat, Q = self._with_hints(sats, rows, ref_k, iono_hints, D, a_hat, Q)
        # Wide-lane pre-transform: per satellite with both frequencies in the search, (N1, N2) -> (N1 - N2, N1),
        # an integer unimodular map. The wide lane is far better determined than N1 and N2, which are
        # ionosphere-limited; starting from it leaves LAMBDA's reduction a fraction of the permutations.
        T = np.eye(len(cands))
        where = {kf: i for i, kf in enumerate(cands)}
        for i, (k, fq) in enumerate(cands):
            j = where.get((k, 1))
            if fq == 0 and j is not None:
                T[j, :] = 0.0
                T[j, i], T[j, j] = 1.0, -1.0  # row of N2 becomes N1 - N2
        b_hat = T @ a_hat
        Qb = T @ Q @ T.T
        try:
            fix = partial_fix(b_hat, Qb, cfg.fix_min_success_rate, cfg.fix_ratio, min_count)
        except AmbiguityError:
            fix = None
        pinned_val: dict[tuple[int, int], int] = {}
        if fix is not None:
            Zs = T.T @ fix.Zs  # the fixed combinations in terms of the original (N1, N2)
            S = Zs.T @ Q @ Zs
            K = np.linalg.solve(S, Zs.T @ Q).T
            a_cond = a_hat - K @ (Zs.T @ a_hat - fix.z_fixed)
            Qc = Q - K @ Zs.T @ Q
            sig = np.sqrt(np.clip(np.diag(Qc), 0.0, None))
            for i, kf in enumerate(cands):
                val = int(round(a_cond[i]))
                if sig[i] <= cfg.pinned_sigma_cyc and abs(a_cond[i] - val) < 3 * cfg.pinned_sigma_cyc:
                    pinned_val[kf] = val
            # wide lanes pinned by the fix where the satellite's N1 and N2 are not (yet) pinned on their own
            for i, (k, fq) in enumerate(cands):
                j = where.get((k, 1))
                if fq != 0 or j is None or str(sats[k]) in self.fixed[FREQS]:
                    continue
                w = a_cond[i] - a_cond[j]
                sw = math.sqrt(max(Qc[i, i] + Qc[j, j] - 2 * Qc[i, j], 0.0))
                val = int(round(w))
                if sw <= cfg.pinned_sigma_cyc and abs(w - val) < 3 * cfg.pinned_sigma_cyc:
                    pinned_val[(k, FREQS)] = val
        wl = [(k, FREQS) for k, fq in cands if fq == 0 and (k, 1) in where and str(sats[k]) not in self.fixed[FREQS]]
        sure = fix is not None and fix.success_rate >= cfg.fix_sure_success_rate
        confirm = cfg.fix_confirm_epochs_sure if sure else cfg.fix_confirm_epochs
        for k, fq in cands + wl:
            tr = self.tracks[str(sats[k])]
            val = pinned_val.get((k, fq))
            if val is None:
                tr.candidate[fq], tr.streak[fq] = None, 0
                continue
            tr.streak[fq] = tr.streak[fq] + 1 if tr.candidate[fq] == val else 1
            tr.candidate[fq] = val
            if tr.streak[fq] >= confirm and commit:
                self.fixed[fq][str(sats[k])] = val
        for k, _ in wl:
            s = str(sats[k])
            if s in self.fixed[0] and s in self.fixed[1]:
                self.fixed[FREQS][s] = self.fixed[0][s] - self.fixed[1][s]
        return fix.ratio if fix is not None else 0.0


def day_ionosphere_ppm(rms_ppm: float, n: int, cfg: BaselineConfig) -> float | None:
    """The day's ionosphere prior from the RMS of n fixed satellites' DD ionosphere [ppm, vertical]: its 95 %
    upper bound times `iono_prior_adapt`, never below the floor; None with too few satellites."""
    if cfg.iono_prior_adapt <= 0 or n < cfg.iono_day_min_sats or not math.isfinite(rms_ppm):
        return None
    return max(cfg.iono_day_floor_ppm, cfg.iono_prior_adapt * rms_ppm * rms_upper_bound_factor(n))


def rms_upper_bound_factor(n: int, z: float = 1.645) -> float:
    """sqrt(n / chi2_{5 %}(n)): the one-sided 95 % upper bound of an RMS from n samples, over the RMS
    (Wilson-Hilferty's approximation of the chi-square quantile)."""
    q = n * (1.0 - 2.0 / (9.0 * n) - z * math.sqrt(2.0 / (9.0 * n))) ** 3
    return math.sqrt(n / q)


def _common_dual_frequency(ep_a: StationEpoch, ep_b: StationEpoch, excluded=frozenset()):
    """The two stations' observations of the satellites both track on both frequencies, same signals;
    with the index of each in its station's epoch."""
    ia = {s: i for i, s in enumerate(ep_a.sats)}
    dual_a = ep_a.dual_frequency()
    dual_b = ep_b.dual_frequency()
    pairs = [(ia[s], j) for j, s in enumerate(ep_b.sats)
             if s in ia and s not in excluded and dual_a[ia[s]] and dual_b[j]
             and np.array_equal(ep_a.freq_hz[ia[s]], ep_b.freq_hz[j])]
    if len(pairs) < 2:
        return None, None, None, None
    ja = np.array([p[0] for p in pairs])
    jb = np.array([p[1] for p in pairs])
    return ep_a.subset(ja), ep_b.subset(jb), ja, jb
