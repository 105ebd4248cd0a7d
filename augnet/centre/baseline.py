"""Ambiguity resolution on one baseline between two reference stations with known coordinates.

The station coordinates are surveyed, so the network solves ambiguities and atmosphere, not positions.
Per epoch (network-rtk.md, "the network engine"):

1. Geometry at each station: satellite positions at transmission (Sagnac included), satellite clocks and
   the receiver clock from the code, so g = rho - c*dts is right to the millimetre.
2. Cycle slips per station and satellite: loss-of-lock flags, geometry-free phase jumps, gaps. A slip
   restarts that satellite's ambiguities (its ionosphere state carries on).
3. A Kalman filter on the double differences (DD) of code and phase on both frequencies, ionosphere
   weighted: states are the residual zenith wet delay of each station, and per satellite the
   between-station single-difference (SD) slant ionosphere on f1 (a random walk with a prior scaled by the
   baseline length: DD ionosphere is ~1-4 ppm of the baseline on a quiet day, network-rtk.md) and the SD
   ambiguities on f1 and f2. This is the uncombined equivalent of Melbourne-Wuebbena wide-lane fixing
   followed by ionosphere-free narrow-lane fixing, and it uses the ionosphere prior in addition, which is
   what rejects the near-equivalent integer pairs (e.g. N1 + 7, Nw - 2 on GPS L1/L2) that the
   ionosphere-free phase alone cannot tell apart.
4. LAMBDA with partial fixing on the DD ambiguities (both frequencies), ratio test and bootstrapped
   success rate; a DD ambiguity is fixed when the conditioned solution pins it to an integer and the same
   integer has come out on several consecutive epochs; fixed ones are held as tight constraints (fix and
   hold) and released when the phase residuals stop supporting them.
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

C = SPEED_OF_LIGHT_M_S
FREQS = 2  # dual-frequency network processing


@dataclass(frozen=True)
class BaselineConfig:
    elevation_mask_deg: float = 10.0
    # Reference satellite: the highest one, kept while it stays above this elevation.
    ref_min_elevation_deg: float = 20.0
    # Undifferenced noise sigma^2(el) = s^2 + s^2 / sin^2(el) (RTKLIB's a = b form) for phase and code.
    phase_sigma_m: float = 0.003
    # Code: the filter takes the noise as white, but station multipath is correlated over minutes; the
    # code weight is lowered by this factor so the filter does not believe averaged code too soon.
    code_sigma_m: float = 0.3
    code_correlation_inflation: float = 1.5
    # Residual zenith wet delay: prior and random walk (a few mm to a cm per sqrt(hour)).
    zwd_prior_sigma_m: float = 0.10
    zwd_random_walk_m2_s: float = 2.0e-8
    # SD slant ionosphere: prior and random walk, both in parts per million of the baseline length.
    iono_prior_ppm: float = 5.0
    iono_prior_min_m: float = 0.03
    iono_rate_ppm_sqrt_s: float = 0.05
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
    fix_confirm_epochs: int = 5
    # DD ambiguities still this uncertain [cycles] stay out of the integer search (they cannot be fixed
    # yet and only make the decorrelation slower).
    search_max_sigma_cyc: float = 5.0
    pinned_sigma_cyc: float = 0.05  # conditioned DD ambiguity sigma at which it counts as pinned
    hold_sigma_cyc: float = 0.005
    # A fixed DD whose post-fit phase residual stays above this for `release_epochs` is released.
    release_residual_m: float = 0.04
    release_epochs: int = 3
    # An arc restarts after a gap longer than this [s].
    max_gap_s: float = 30.0
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
    candidate: list = field(default_factory=lambda: [None, None])  # per frequency
    streak: list = field(default_factory=lambda: [0, 0])
    bad_streak: int = 0


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
        self.iono_prior_var = max(cfg.iono_prior_min_m, cfg.iono_prior_ppm * 1e-6 * self.length_m) ** 2
        self.iono_q = (cfg.iono_rate_ppm_sqrt_s * 1e-6 * self.length_m) ** 2
        self.tracks: dict[str, _Track] = {}
        self.refs: dict[str, str] = {}
        self.fixed: list[dict[str, int]] = [{}, {}]  # per frequency: sat -> DD integer against refs[sys]
        self.clock = {"a": 0.0, "b": 0.0}
        self.t_last = -math.inf
        # Kalman filter: x = [zwd_a, zwd_b, (I, N1, N2) per satellite at self.index[sat]]
        self.x = np.zeros(2)
        self.P = np.eye(2) * cfg.zwd_prior_sigma_m**2
        self.index: dict[str, int] = {}
        self._smooth: dict[str, tuple] = {}  # sat -> (ref, integers, t, iono, trop)

    @property
    def name(self) -> str:
        return f"{self.name_a}-{self.name_b}"

    # --- state bookkeeping ---------------------------------------------------------------------

    def _add_states(self, sat: str, iono_m: float, n1: float, n2: float) -> None:
        n = len(self.x)
        self.x = np.concatenate([self.x, [iono_m, n1, n2]])
        P = np.zeros((n + 3, n + 3))
        P[:n, :n] = self.P
        P[n, n] = self.iono_prior_var
        P[n + 1, n + 1] = P[n + 2, n + 2] = self.cfg.amb_prior_sigma_cyc**2
        self.P = P
        self.index[sat] = n

    def _remove_states(self, sats) -> None:
        drop = [self.index.pop(s) for s in sats if s in self.index]
        if not drop:
            return
        gone = np.concatenate([np.arange(p, p + 3) for p in drop])
        keep = np.setdiff1d(np.arange(len(self.x)), gone)
        self.x = self.x[keep]
        self.P = self.P[np.ix_(keep, keep)]
        order = sorted(self.index.items(), key=lambda kv: kv[1])
        self.index = {s: 2 + 3 * k for k, (s, _) in enumerate(order)}

    def _restart_ambiguities(self, sat: str, n1: float, n2: float) -> None:
        """A slip: the satellite's ambiguities start afresh (its ionosphere state carries on)."""
        p = self.index[sat]
        for q, val in ((p + 1, n1), (p + 2, n2)):
            self.P[q, :] = 0.0
            self.P[:, q] = 0.0
            self.P[q, q] = self.cfg.amb_prior_sigma_cyc**2
            self.x[q] = val
        for f in range(FREQS):
            self.fixed[f].pop(sat, None)
        tr = self.tracks[sat]
        tr.candidate, tr.streak = [None, None], [0, 0]

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
                tr.candidate, tr.streak = [None, None], [0, 0]

    # --- one epoch -----------------------------------------------------------------------------

    def update(self, ep_a: StationEpoch, ep_b: StationEpoch, nav: NavigationData,
               geom_a: SatelliteGeometry | None = None, geom_b: SatelliteGeometry | None = None,
               excluded: set[str] | frozenset[str] = frozenset()) -> BaselineEpoch | None:
        """One epoch. `geom_a`/`geom_b`: the stations' geometry for all their satellites (the network
        computes it once per station); `excluded`: satellites the integrity monitor has taken out."""
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
        for k, s in enumerate(sats):
            s = str(s)
            if s in new_arc or s not in self.index:
                self._remove_states([s])
                self.tracks[s] = _Track()
                for fq in range(FREQS):
                    self.fixed[fq].pop(s, None)
                self._add_states(s, 0.0, n0[k, 0], n0[k, 1])
            elif s in slipped:
                self._restart_ambiguities(s, n0[k, 0], n0[k, 1])
        gone = [s for s in self.index if s not in set(sats.tolist())]
        self._remove_states(gone)
        for s in gone:
            for fq in range(FREQS):
                self.fixed[fq].pop(s, None)
        for k, s in enumerate(sats):
            tr = self.tracks[str(s)]
            tr.t_last = t
            tr.epochs += 1

        # prediction
        dt = t - self.t_last if np.isfinite(self.t_last) else 0.0
        self.t_last = t
        self.P[0, 0] += cfg.zwd_random_walk_m2_s * dt
        self.P[1, 1] += cfg.zwd_random_walk_m2_s * dt
        for p in self.index.values():
            self.P[p, p] += self.iono_q * dt

        # measurement update with all DD code and phase
        ref_of = np.array([self.refs[s[0]] for s in sats])
        pos = {s: k for k, s in enumerate(sats)}
        ref_k = np.array([pos[r] for r in ref_of])
        rows = np.array([k for k in range(len(sats)) if sats[k] != ref_of[k]], dtype=int)
        if rows.size == 0:
            return None
        H, z, R = self._dd_model(sats, rows, ref_k, ga, gb, lam, gamma, sd_phase, sd_code)
        self._kalman_update(H, z - H @ self.x, R)
        self._hold(sats, rows, ref_k)
        self._release(sats, rows, ref_k, ga, gb, lam, gamma, sd_phase)
        el_min = np.degrees(np.minimum(ga.elevation_rad, gb.elevation_rad))
        ratio = self._fix(sats, rows[el_min[rows] >= cfg.fix_min_elevation_deg], ref_k)

        # DD residuals where the integers are known
        n = len(sats)
        dd_n = np.full((n, 2), np.nan)
        for k, s in enumerate(sats):
            if s == ref_of[k]:
                dd_n[k] = 0.0
            elif s in self.fixed[0] and s in self.fixed[1]:
                dd_n[k] = (self.fixed[0][s], self.fixed[1][s])
        fixed = np.isfinite(dd_n).all(axis=1)
        dd = sd_phase - sd_phase[ref_k]
        r = dd - lam * dd_n
        dd_iono = (r[:, 0] - r[:, 1]) / (gamma - 1.0)
        dd_trop = (gamma * r[:, 0] - r[:, 1]) / (gamma - 1.0)
        dd_iono, dd_trop = self._smoothed(t, sats, ref_of, dd_n, fixed, dd_iono, dd_trop)
        return BaselineEpoch(
            t_gpst=t, refs=dict(self.refs), sats=sats.copy(),
            elevation_a_deg=np.degrees(ga.elevation_rad), elevation_b_deg=np.degrees(gb.elevation_rad),
            fixed=fixed, dd_n=dd_n, dd_iono_m=np.where(fixed, dd_iono, np.nan),
            dd_trop_m=np.where(fixed, dd_trop, np.nan), freq_hz=f.copy(), slips=sorted(slipped),
            zwd_m=(float(self.x[0]), float(self.x[1])), ratio=ratio,
            eligible=el_min >= cfg.fix_min_elevation_deg)

    # --- pieces of an epoch --------------------------------------------------------------------

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
        nx = len(self.x)
        H = np.zeros((4 * m, nx))
        z = np.zeros(4 * m)
        sin_a2 = np.sin(ga.elevation_rad) ** 2
        sin_b2 = np.sin(gb.elevation_rad) ** 2
        shape = 2.0 + 1.0 / sin_a2 + 1.0 / sin_b2  # SD variance / s^2
        var_phase_sd = cfg.phase_sigma_m**2 * shape
        var_code_sd = (cfg.code_sigma_m * cfg.code_correlation_inflation) ** 2 * shape
        d_wet_a = ga.wet_mapping[rows] - ga.wet_mapping[ref_k[rows]]
        d_wet_b = gb.wet_mapping[rows] - gb.wet_mapping[ref_k[rows]]
        ps = np.array([self.index[str(sats[k])] for k in rows])
        pr = np.array([self.index[str(sats[ref_k[k]])] for k in rows])
        g = gamma[rows]
        blocks = (  # (observation, ionosphere coefficient, ambiguity slot or None, frequency)
            ("P", 1.0, None, 0), ("P", g, None, 1), ("L", -1.0, 1, 0), ("L", -g, 2, 1))
        Rs = []
        for i, (kind, icoef, slot, fq) in enumerate(blocks):
            sl = slice(i * m, (i + 1) * m)
            rr = np.arange(i * m, (i + 1) * m)
            H[rr, 0] = -d_wet_a
            H[rr, 1] = d_wet_b
            H[rr, ps] += icoef
            H[rr, pr] -= icoef
            if slot is not None:
                H[rr, ps + slot] += lam[rows, fq]
                H[rr, pr + slot] -= lam[rows, fq]
            obs = sd_phase[:, fq] if kind == "L" else sd_code[:, fq]
            z[sl] = obs[rows] - obs[ref_k[rows]]
            var = var_phase_sd if kind == "L" else var_code_sd
            # DD covariance: each DD has its own SD variance plus its reference's, shared with the DDs of
            # the same reference.
            Rb = np.diag(var[rows])
            same_ref = ref_k[rows][:, None] == ref_k[rows][None, :]
            Rb = Rb + np.where(same_ref, var[ref_k[rows]][:, None], 0.0)
            Rs.append(Rb)
        R = np.zeros((4 * m, 4 * m))
        for i, Rb in enumerate(Rs):
            R[i * m:(i + 1) * m, i * m:(i + 1) * m] = Rb
        return H, z, R

    def _kalman_update(self, H: np.ndarray, innov: np.ndarray, R: np.ndarray) -> None:
        PHt = self.P @ H.T
        S = H @ PHt + R
        try:
            K = np.linalg.solve(S, PHt.T).T
        except np.linalg.LinAlgError:
            return
        self.x = self.x + K @ innov
        self.P = self.P - K @ PHt.T
        self.P = 0.5 * (self.P + self.P.T)

    def _dd_ambiguity_rows(self, sats, ks, ref_k, fq) -> np.ndarray:
        D = np.zeros((len(ks), len(self.x)))
        for i, k in enumerate(ks):
            D[i, self.index[str(sats[k])] + 1 + fq] = 1.0
            D[i, self.index[str(sats[ref_k[k]])] + 1 + fq] = -1.0
        return D

    def _hold(self, sats, rows, ref_k) -> None:
        for fq in range(FREQS):
            held = [k for k in rows if str(sats[k]) in self.fixed[fq]]
            if not held:
                continue
            D = self._dd_ambiguity_rows(sats, held, ref_k, fq)
            zh = np.array([self.fixed[fq][str(sats[k])] for k in held], float)
            self._kalman_update(D, zh - D @ self.x, np.eye(len(held)) * self.cfg.hold_sigma_cyc**2)

    def _release(self, sats, rows, ref_k, ga, gb, lam, gamma, sd_phase) -> None:
        """Post-fit DD phase residuals of fixed satellites; a wrong fix shows as a persistent residual."""
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
                    for fq in range(FREQS):
                        self.fixed[fq].pop(s, None)
                    tr.candidate, tr.streak, tr.bad_streak = [None, None], [0, 0], 0
            else:
                tr.bad_streak = 0

    def _fix(self, sats, rows, ref_k) -> float:
        """LAMBDA with partial fixing over the DD ambiguities not yet fixed (both frequencies)."""
        cfg = self.cfg
        cands = [(k, fq) for fq in range(FREQS) for k in rows if str(sats[k]) not in self.fixed[fq]]
        D = np.zeros((len(cands), len(self.x)))
        for i, (k, fq) in enumerate(cands):
            D[i, self.index[str(sats[k])] + 1 + fq] = 1.0
            D[i, self.index[str(sats[ref_k[k]])] + 1 + fq] = -1.0
        ready = np.einsum("ij,jk,ik->i", D, self.P, D) <= cfg.search_max_sigma_cyc**2
        for i in np.flatnonzero(~ready):
            k, fq = cands[i]
            tr = self.tracks[str(sats[k])]
            tr.candidate[fq], tr.streak[fq] = None, 0
        cands = [c for c, r in zip(cands, ready) if r]
        D = D[ready]
        if len(cands) < cfg.fix_min_count:
            return 0.0
        a_hat = D @ self.x
        Q = D @ self.P @ D.T
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
            fix = partial_fix(b_hat, Qb, cfg.fix_min_success_rate, cfg.fix_ratio, cfg.fix_min_count)
        except AmbiguityError:
            fix = None
        pinned_val: dict[tuple[int, int], int] = {}
        if fix is not None:
            Zs = T.T @ fix.Zs  # the fixed combinations in terms of the original (N1, N2)
            S = Zs.T @ Q @ Zs
            K = np.linalg.solve(S, Zs.T @ Q).T
            a_cond = a_hat - K @ (Zs.T @ a_hat - fix.z_fixed)
            sig = np.sqrt(np.clip(np.diag(Q - K @ Zs.T @ Q), 0.0, None))
            for i, kf in enumerate(cands):
                val = int(round(a_cond[i]))
                if sig[i] <= cfg.pinned_sigma_cyc and abs(a_cond[i] - val) < 3 * cfg.pinned_sigma_cyc:
                    pinned_val[kf] = val
        for k, fq in cands:
            tr = self.tracks[str(sats[k])]
            val = pinned_val.get((k, fq))
            if val is None:
                tr.candidate[fq], tr.streak[fq] = None, 0
                continue
            tr.streak[fq] = tr.streak[fq] + 1 if tr.candidate[fq] == val else 1
            tr.candidate[fq] = val
            if tr.streak[fq] >= cfg.fix_confirm_epochs:
                self.fixed[fq][str(sats[k])] = val
        return fix.ratio if fix is not None else 0.0


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
