"""The baseline filter: integer ambiguities and DD residuals between two reference stations with known
coordinates (network-rtk.md, "the network engine").

The station coordinates are surveyed, so the network solves ambiguities and atmosphere, not positions. A Kalman
filter on the double differences (DD) of code and phase on both frequencies, ionosphere weighted; its states
(`baseline_state.py`) are the residual zenith wet delay of each station (with a prior on their difference), and
per satellite the between-station single-difference (SD) slant ionosphere on f1 (a random walk with a storm's
prior, `ionosphere_prior.py`), the SD ambiguities on f1 and f2, and the SD code and phase multipath on f1 and f2
(first-order Gauss-Markov: static-station multipath is correlated over minutes, decision 0101). This is the
uncombined equivalent of Melbourne-Wuebbena wide-lane fixing followed by ionosphere-free narrow-lane fixing, with
the ionosphere prior in addition.

Per epoch (`BaselineSolver.update`): the single differences (`single_differences.py`), cycle slips
(`cycle_slips.py`), the reference satellites (`reference_satellites.py`), the satellites' states started,
restarted or dropped, the prediction, the measurement update with all DD code and phase, hold, release and the
integer decision (`ambiguity_fixing.py`), and the DD residuals where the integers are known (`dd_residuals.py`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.ambiguity_fixing import BaselineAmbiguities
from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.baseline_state import (IONO, N1, ZWD_A, ZWD_B, SatelliteBlock, add_satellite, dd_indices,
                                          new_state, restart_ambiguities)
from augnet.centre.cycle_slips import CycleSlipDetector, Slips
from augnet.centre.dd_residuals import ResidualSmoother, dd_integers, dispersive_split
from augnet.centre.baseline_integers import BaselineIntegers
from augnet.centre.ionosphere_prior import IonospherePrior, slant_mapping
from augnet.centre.observations import StationEpoch
from augnet.centre.reference_satellites import ReferenceSatellites, pair_with_references
from augnet.centre.satellite_geometry import SatelliteGeometry, satellite_geometry
from augnet.centre.single_differences import SingleDifferences, above_mask, common_dual_frequency
from augnet.gnss.antex import ReceiverAntenna
from augnet.gnss.ephemeris import NavigationData

__all__ = ["BaselineConfig", "BaselineEpoch", "BaselineSolver"]  # BaselineConfig: the settings, imported here too

# Epochs of the two stations closer than this are the same epoch [s]
EPOCH_ALIGNMENT_S = 1e-3


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


def _code_sigma_m(cfg: BaselineConfig) -> float:
    """The undifferenced code sigma s, white and multipath together [m]."""
    return cfg.code_sigma_m * cfg.code_correlation_inflation


class BaselineSolver:
    """Integer ambiguities and DD residuals between stations a and b, epoch after epoch."""

    def __init__(self, name_a: str, xyz_a_m, name_b: str, xyz_b_m, config: BaselineConfig | None = None,
                 antenna_a: ReceiverAntenna | None = None, antenna_b: ReceiverAntenna | None = None):
        self.name_a = name_a
        self.antenna = {"a": antenna_a, "b": antenna_b}  # ANTEX calibrations (None: phase centre at the ARP)
        self.name_b = name_b
        self.xyz_a = np.asarray(xyz_a_m, float)
        self.xyz_b = np.asarray(xyz_b_m, float)
        self.length_m = float(np.linalg.norm(self.xyz_b - self.xyz_a))
        self.cfg = cfg = config or BaselineConfig()
        self.block = SatelliteBlock.from_config(cfg)
        self.state = new_state(cfg)
        self.slips = CycleSlipDetector(cfg.max_gap_s)
        self.references = ReferenceSatellites(cfg.ref_min_elevation_deg)
        self.ambiguities = BaselineAmbiguities(cfg)
        self.ionosphere = IonospherePrior(cfg, self.length_m)
        self.smoother = ResidualSmoother(cfg.residual_smoothing_s, cfg.max_gap_s)
        self.clock = {"a": 0.0, "b": 0.0}  # receiver clocks [s], the geometry's starting guess
        self.t_last = -math.inf

    @property
    def name(self) -> str:
        return f"{self.name_a}-{self.name_b}"

    @property
    def refs(self) -> dict[str, str]:
        return self.references.refs

    @property
    def fixed(self) -> BaselineIntegers:
        return self.ambiguities.fixed

    # --- one epoch -----------------------------------------------------------------------------------

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
        t = ep_a.t_gpst
        if abs(ep_b.t_gpst - t) > EPOCH_ALIGNMENT_S:
            raise ValueError(f"{self.name}: epochs not aligned ({ep_a.t_gpst} vs {ep_b.t_gpst})")
        sd = self._single_differences(ep_a, ep_b, nav, geom_a, geom_b, excluded)
        if sd is None:
            return None
        slips = self.slips.detect(t, sd.a, sd.b, sd.freq_hz, self.state)
        self._choose_references(sd, slips)
        mapping = slant_mapping(sd.el_min_rad, self.cfg.iono_shell_height_km)
        self.ionosphere.activity.observe(t, sd.sats, slips.sd_geometry_free_m, slips.restarted, mapping, sd.gamma)
        mp_code_var, mp_phase_var = self._multipath_variances(sd)
        self._start_states(t, sd, slips, mapping, mp_code_var, mp_phase_var)
        dt = self._predict(t, sd, mapping, mp_code_var, mp_phase_var)
        ref_of, ref_k, rows = pair_with_references(sd.sats, self.refs)
        if rows.size == 0:
            return None
        self._kalman_update(*self._dd_measurements(sd, rows, ref_k))
        self._hold(sd, rows, ref_k)
        self._release(sd, rows, ref_k)
        ratio = self._decide(sd, rows, ref_k, mapping, iono_hints, iono_model)
        return self._outcome(t, dt, sd, slips, ref_of, ref_k, mapping, ratio)

    # --- the steps of an epoch -------------------------------------------------------------------------

    def _single_differences(self, ep_a, ep_b, nav, geom_a, geom_b, excluded) -> SingleDifferences | None:
        """The common dual-frequency satellites above the mask, with the stations' geometry (computed here when
        not given); the receiver clocks are kept as the next epoch's starting guess."""
        a, b, ia, ib = common_dual_frequency(ep_a, ep_b, excluded)
        if a is None:
            return None
        t = ep_a.t_gpst
        if geom_a is None:
            geom_a = satellite_geometry(ep_a.sats, t, self.xyz_a, nav, ep_a.code_m[:, 0], self.clock["a"],
                                        self.antenna["a"], ep_a.codes)
        if geom_b is None:
            geom_b = satellite_geometry(ep_b.sats, t, self.xyz_b, nav, ep_b.code_m[:, 0], self.clock["b"],
                                        self.antenna["b"], ep_b.codes)
        ga, gb = geom_a.subset(ia), geom_b.subset(ib)
        self.clock["a"], self.clock["b"] = ga.clock_s, gb.clock_s
        return above_mask(a, b, ga, gb, self.cfg.elevation_mask_deg)

    def _choose_references(self, sd: SingleDifferences, slips: Slips) -> None:
        for system, old, new in self.references.update(sd.sats, sd.el_min_rad, slips.restarted, self.fixed):
            self.ambiguities.rereference(system, old, new)

    def _multipath_variances(self, sd: SingleDifferences) -> tuple[np.ndarray, np.ndarray]:
        """The SD code and phase multipath variances [m^2] (their share of sigma^2(el) at both stations)."""
        cfg = self.cfg
        shape = sd.noise_shape()
        code = cfg.code_multipath_share * _code_sigma_m(cfg) ** 2 * shape
        return code, cfg.phase_multipath_share * cfg.phase_sigma_m**2 * shape

    def _start_states(self, t, sd: SingleDifferences, slips: Slips, mapping, mp_code_var, mp_phase_var) -> None:
        """A new arc starts the satellite afresh (the ambiguities from phase minus code, the ionosphere at its
        zero-mean prior); a slip restarts its ambiguities; satellites no longer seen are dropped."""
        n0 = sd.ambiguities_from_code()
        amb_var = self.cfg.amb_prior_sigma_cyc**2
        for k, s in enumerate(sd.sats):
            s = str(s)
            if s in slips.new_arc:
                self.state.remove([s])
                self.ambiguities.forget(s)
                self.ionosphere.activity.forget(s)
                add_satellite(self.state, self.block, s, self.ionosphere.state_prior_m2(s, mapping[k]), n0[k, 0],
                              n0[k, 1], amb_var, mp_code_var[k], mp_phase_var[k],
                              mp_code_var[k] * self.cfg.code_sigma_second_factor**2)
            elif s in slips.slipped:
                self._restart(s, n0[k, 0], n0[k, 1])
        seen = set(sd.sats.tolist())
        gone = [s for s in self.state if s not in seen]
        self.state.remove(gone)
        for s in gone:
            self.fixed.forget(s)
        self.slips.seen(sd.sats, t)

    def _restart(self, sat: str, n1: float, n2: float) -> None:
        """The satellite's ambiguities start afresh (its ionosphere state carries on)."""
        restart_ambiguities(self.state, sat, n1, n2, self.cfg.amb_prior_sigma_cyc**2)
        self.ambiguities.restart(sat)

    def _predict(self, t, sd: SingleDifferences, mapping, mp_code_var, mp_phase_var) -> float:
        """The time update: random walks of the wet delays and the SD ionosphere, AR(1) multipath
        (x <- phi x, P <- F P F^T + (1 - phi^2) var(el)). Returns the time step [s]."""
        cfg = self.cfg
        dt = t - self.t_last if np.isfinite(self.t_last) else 0.0
        self.t_last = t
        P = self.state.P
        P[ZWD_A, ZWD_A] += cfg.zwd_random_walk_m2_s * dt
        P[ZWD_B, ZWD_B] += cfg.zwd_random_walk_m2_s * dt
        slots = self.state.indices(sd.sats)
        P[slots + IONO, slots + IONO] += self.ionosphere.random_walk_m2_s * mapping**2 * dt
        if not (dt > 0 and self.block.has_multipath):
            return dt
        x = self.state.x
        decay = np.ones(len(x))
        innovation = []
        f2 = cfg.code_sigma_second_factor**2
        for off, tau, var, var2 in (
                (self.block.code_multipath, cfg.code_multipath_tau_s, mp_code_var, mp_code_var * f2),
                (self.block.phase_multipath, cfg.phase_multipath_tau_s, mp_phase_var, mp_phase_var)):
            if off is None:
                continue
            phi = math.exp(-dt / tau)
            mp = np.concatenate([slots + off, slots + off + 1])
            x[mp] *= phi
            decay[mp] = phi
            innovation.append((mp, (1.0 - phi**2) * np.concatenate([var, var2])))
        P *= decay[:, None] * decay[None, :]
        for mp, q in innovation:
            P[mp, mp] += q
        return dt

    def _dd_measurements(self, sd: SingleDifferences, rows, ref_k):
        """Design matrix (sparse, by rows: 8 (column, value) pairs each), DD observations and their covariance
        for code and phase on both frequencies."""
        cfg = self.cfg
        m = rows.size
        z = np.zeros(4 * m)
        cols = np.zeros((4 * m, 8), dtype=int)
        vals = np.zeros((4 * m, 8))
        shape = sd.noise_shape()  # SD variance / s^2
        var_phase_sd = (1.0 - cfg.phase_multipath_share) * cfg.phase_sigma_m**2 * shape
        var_code_sd = (1.0 - cfg.code_multipath_share) * _code_sigma_m(cfg) ** 2 * shape
        d_wet_a = sd.ga.wet_mapping[rows] - sd.ga.wet_mapping[ref_k[rows]]
        d_wet_b = sd.gb.wet_mapping[rows] - sd.gb.wet_mapping[ref_k[rows]]
        ps, pr = dd_indices(self.state, sd.sats, rows, ref_k, 0)
        g = sd.gamma[rows]
        lam = sd.wavelength_m
        blocks = (  # (observation, ionosphere coefficient, ambiguity offset or None, frequency)
            ("P", 1.0, None, 0), ("P", g, None, 1), ("L", -1.0, N1, 0), ("L", -g, N1 + 1, 1))
        # DD covariance: each DD has its own SD variance plus its reference's, shared with the DDs of the same
        # reference
        same_ref = ref_k[rows][:, None] == ref_k[rows][None, :]
        R = np.zeros((4 * m, 4 * m))
        for i, (kind, icoef, slot, fq) in enumerate(blocks):
            sl = slice(i * m, (i + 1) * m)
            entries = [(ZWD_A, -d_wet_a), (ZWD_B, d_wet_b), (ps + IONO, icoef), (pr + IONO, -icoef)]
            if slot is not None:
                entries += [(ps + slot, lam[rows, fq]), (pr + slot, -lam[rows, fq])]
            mp_off = self.block.phase_multipath if kind == "L" else self.block.code_multipath
            if mp_off is not None:
                entries += [(ps + mp_off + fq, 1.0), (pr + mp_off + fq, -1.0)]
            for j, (c, v) in enumerate(entries):
                cols[sl, j] = c
                vals[sl, j] = v
            obs = sd.phase_m[:, fq] if kind == "L" else sd.code_m[:, fq]
            z[sl] = obs[rows] - obs[ref_k[rows]]
            var = var_phase_sd if kind == "L" else var_code_sd * (cfg.code_sigma_second_factor**2 if fq else 1.0)
            R[sl, sl] = np.diag(var[rows]) + np.where(same_ref, var[ref_k[rows]][:, None], 0.0)
        return cols, vals, z, R

    def _kalman_update(self, cols: np.ndarray, vals: np.ndarray, z: np.ndarray, R: np.ndarray) -> None:
        """Measurement update with a sparse design matrix given by rows: H[r, cols[r, j]] += vals[r, j]."""
        x, P = self.state.x, self.state.P
        HP = np.zeros((cols.shape[0], P.shape[0]))
        for j in range(cols.shape[1]):
            HP += vals[:, j, None] * P[cols[:, j]]
        S = R.copy()
        for j in range(cols.shape[1]):
            S += HP[:, cols[:, j]] * vals[None, :, j]
        innov = z - (vals * x[cols]).sum(axis=1)
        try:  # S = L L^T: K = HP^T S^-1 and P - K HP = P - W^T W with W = L^-1 HP
            Li = np.linalg.inv(np.linalg.cholesky(S))
        except np.linalg.LinAlgError:
            return
        W = Li @ HP
        self.state.x = x + W.T @ (Li @ innov)
        P = P - W.T @ W
        self.state.P = 0.5 * (P + P.T)

    def _hold(self, sd: SingleDifferences, rows, ref_k) -> None:
        """Fixed DD integers as tight pseudo-observations (fix and hold)."""
        held = self.ambiguities.hold_rows(self.state, sd.sats, rows, ref_k)
        if held is not None:
            cols, vals, z = held
            self._kalman_update(cols, vals, z, np.eye(len(z)) * self.cfg.hold_sigma_cyc**2)

    def _release(self, sd: SingleDifferences, rows, ref_k) -> None:
        """Fixed satellites whose phase residuals stop supporting their integers start their ambiguities afresh."""
        released = self.ambiguities.releases(self.state, sd, rows, ref_k)
        if released:
            n0 = sd.ambiguities_from_code()
            pos = {str(s): k for k, s in enumerate(sd.sats)}
            for s in released:
                self._restart(s, n0[pos[s], 0], n0[pos[s], 1])

    def _decide(self, sd: SingleDifferences, rows, ref_k, mapping, iono_hints, iono_model) -> float:
        """The integer decision over the satellites above the fixing mask, conditioned on the ionosphere prior in
        force and the network's hints. Nothing is committed before the ionosphere's rate is known; the decisions
        run meanwhile, so their confirmation counts are ready when it is, and are dropped if the rate raises the
        prior they used."""
        if self.ionosphere.dry_run_outdated():
            self.ambiguities.confirmation.forget_all()
        el_min_deg = np.degrees(sd.el_min_rad)
        pseudo_obs = self.ionosphere.pseudo_observations(sd.sats, rows, ref_k, mapping, self.fixed, iono_hints,
                                                         iono_model)
        return self.ambiguities.decide(self.state, sd.sats, rows[el_min_deg[rows] >= self.cfg.fix_min_elevation_deg],
                                       ref_k, pseudo_obs, commit=self.ionosphere.may_commit())

    def _outcome(self, t, dt, sd: SingleDifferences, slips: Slips, ref_of, ref_k, mapping, ratio) -> BaselineEpoch:
        """The DD residuals where the integers are known (the ionosphere prior learns from them), smoothed, and
        the filter's DD ionosphere for every satellite."""
        sats = sd.sats
        dd_n = dd_integers(sats, ref_of, self.fixed)
        fixed = np.isfinite(dd_n).all(axis=1)
        dd_iono, dd_trop = dispersive_split(sd.phase_m, ref_k, sd.wavelength_m, dd_n, sd.gamma)
        self.ionosphere.learn(dt, fixed & (sats != ref_of), ref_k, mapping, dd_iono)
        dd_iono, dd_trop = self.smoother.smooth(t, sats, ref_of, dd_n, fixed, dd_iono, dd_trop)
        x, P = self.state.x, self.state.P
        ps = self.state.indices(sats) + IONO
        pr = ps[ref_k]
        return BaselineEpoch(
            t_gpst=t, refs=dict(self.refs), sats=sats.copy(),
            elevation_a_deg=np.degrees(sd.ga.elevation_rad), elevation_b_deg=np.degrees(sd.gb.elevation_rad),
            fixed=fixed, dd_n=dd_n, dd_iono_m=np.where(fixed, dd_iono, np.nan),
            dd_trop_m=np.where(fixed, dd_trop, np.nan), freq_hz=sd.freq_hz.copy(), slips=sorted(slips.slipped),
            zwd_m=(float(x[ZWD_A]), float(x[ZWD_B])), ratio=ratio,
            eligible=np.degrees(sd.el_min_rad) >= self.cfg.fix_min_elevation_deg, iono_float_m=x[ps] - x[pr],
            iono_float_var_m2=P[ps, ps] + P[pr, pr] - 2.0 * P[ps, pr])
