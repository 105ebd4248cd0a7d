"""Observation statistics of reference stations, the same code for real RINEX and for a simulated recording.

Per station, by elevation bin: code noise and multipath (TEQC's MP1/MP2: code minus a phase combination that
removes geometry, clocks and the ionosphere, arc-demeaned), phase noise (the geometry-free phase second
difference), slips (loss-of-lock flags, and the unflagged ones the centre's detector `augnet.centre.cycle_slips`
finds) and gaps. Per pair of stations: the double-differenced L1 ionosphere from geometry-free phase (its
change over 30 s and 5 min within continuous arcs, and its level after levelling each arc to the geometry-free
code), per km of baseline, and on a short baseline the double-differenced phase second difference (noise).

The simulator's presets are set beside the real network's figures with it (docs/simulator-calibration.md);
`augnet sim stats` prints the tables.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.cycle_slips import CycleSlipDetector
from augnet.centre.observations import StationEpoch
from augnet.gnss.ephemeris import NavigationData, transit
from augnet.gnss.geometry import azimuth_elevation
from augnet.gnss.rinex.obs import ObsData, read_obs, to_rinex3_types
from augnet.gnss.signals import by_rinex

# Elevation bins [deg], as asked in issue 14 (the 10 degree mask of the catnet files and the simulator).
ELEVATION_BINS_DEG = ((10.0, 20.0), (20.0, 30.0), (30.0, 50.0), (50.0, 90.0))
# Signals per system, first frequency then second, RINEX 3 codes in order of preference: GPS C1 (C/A) and P2,
# what the Trimble NetRS of catnet track and what the simulator writes.
SIGNALS = {"G": (("1C",), ("2W", "2L", "2X")), "E": (("1C", "1X"), ("5Q", "5X")), "C": (("2I",), ("6I",))}
ELEVATION_STEP_S = 30.0  # satellite geometry computed on this grid and interpolated (an arc moves < 0.25 deg)
ARC_MAX_GAP_S = 120.0  # a longer gap ends an arc (the centre's detector restarts there too)
MP_MIN_ARC_S = 600.0  # arcs shorter than this give no multipath figure (their mean is not the bias)
MP_MIN_ARC_EPOCHS = 10
PASS_GAP_MAX_S = 900.0  # a gap longer than this inside a satellite's data is a new pass, not a gap
DD_MIN_ELEVATION_DEG = 15.0  # the DD ionosphere of satellites above this (the reference: the highest one)
DD_LAGS_S = (30.0, 300.0)  # the time changes reported
LEVEL_MIN_EPOCHS = 10  # geometry-free code levelling needs at least this many epochs of an arc
ROBUST_SIGMA = 1.4826  # median absolute value to a normal sigma
PER_KM_MIN_KM = 1.0  # figures per km of baseline only for baselines at least this long
DD_D2_MAX_KM = 25.0  # the DD phase second difference is noise at 1 Hz up to here (geometry: < 0.5 mm)
RESET_CODE_MINUS_PHASE_M = 20.0  # an unflagged slip moving code minus phase by more is a phase reset (0150)


@dataclass
class StationSeries:
    """One station's dual-frequency observations on a regular epoch grid (missing epochs are NaN)."""

    name: str
    times: np.ndarray  # (E,) GPST [s], regular at `interval_s`
    sats: np.ndarray  # (S,)
    code_m: np.ndarray  # (E, S, 2)
    phase_cyc: np.ndarray  # (E, S, 2)
    lli: np.ndarray  # (E, S) bool: loss of lock on either frequency
    freq_hz: np.ndarray  # (S, 2)
    elevation_deg: np.ndarray  # (E, S)
    position_m: np.ndarray  # (3,)
    interval_s: float

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.code_m).all(-1) & np.isfinite(self.phase_cyc).all(-1)

    def decimated(self, interval_s: float) -> StationSeries:
        """Every epoch on a multiple of `interval_s` (a 1 Hz recording seen as a 30 s one)."""
        if interval_s <= self.interval_s + 1e-9:
            return self
        keep = np.abs(np.mod(self.times + 1e-6, interval_s)) < 1e-3
        # a flag anywhere in the dropped epochs belongs to the next kept one
        lli_c = np.cumsum(self.lli, axis=0)
        idx = np.flatnonzero(keep)
        prev = np.concatenate([[-1], idx[:-1]])
        lli = (lli_c[idx] - np.where(prev[:, None] >= 0, lli_c[np.maximum(prev, 0)], 0)) > 0
        return StationSeries(self.name, self.times[idx], self.sats, self.code_m[idx], self.phase_cyc[idx],
                             lli, self.freq_hz, self.elevation_deg[idx], self.position_m, float(interval_s))


def _pick(obs: ObsData, sat_cols: np.ndarray, system: str, kind: str, k: int):
    for code in SIGNALS[system][k]:
        arr = obs.obs.get(kind + code)
        if arr is not None and np.isfinite(arr[:, sat_cols]).any():
            return code, arr[:, sat_cols], obs.lli.get(kind + code)
    return None, None, None


def series_from_obs(obs: ObsData, nav: NavigationData | None, name: str | None = None,
                    systems: tuple[str, ...] = ("G",), position_m=None) -> StationSeries:
    """The station's series from RINEX (2 or 3), elevations from the broadcast ephemerides `nav`."""
    obs = to_rinex3_types(obs)
    name = name or obs.header.marker_name[:4] or "?"
    letters = np.array([s[0] for s in obs.sats.tolist()])
    cols = np.flatnonzero(np.isin(letters, systems))
    sats = obs.sats[cols]
    t_raw = obs.times
    interval = obs.header.interval_s or float(np.median(np.diff(t_raw)))
    grid = t_raw[0] + np.arange(int(round((t_raw[-1] - t_raw[0]) / interval)) + 1) * interval
    row = np.round((t_raw - t_raw[0]) / interval).astype(int)
    E, S = len(grid), len(sats)
    code = np.full((E, S, 2), np.nan)
    phase = np.full((E, S, 2), np.nan)
    lli = np.zeros((E, S), bool)
    freq = np.full((S, 2), np.nan)
    for system in systems:
        sc = np.flatnonzero(letters[cols] == system)
        if not sc.size:
            continue
        for k in range(2):
            c_code, c_arr, _ = _pick(obs, cols[sc], system, "C", k)
            l_code, l_arr, l_lli = _pick(obs, cols[sc], system, "L", k)
            if c_arr is None or l_arr is None:
                continue
            freq[sc, k] = by_rinex(system, l_code).freq_hz
            code[row[:, None], sc[None, :], k] = c_arr
            phase[row[:, None], sc[None, :], k] = l_arr
            if l_lli is not None:
                lli[row[:, None], sc[None, :]] |= (l_lli[:, cols[sc]] & 1) > 0
    pos = np.asarray(position_m if position_m is not None else obs.header.approx_position_m, float)
    el = elevations_deg(nav, sats, pos, grid) if nav is not None else np.full((E, S), np.nan)
    return StationSeries(name, grid, sats, code, phase, lli, freq, el, pos, float(interval))


def elevations_deg(nav: NavigationData, sats, pos, times) -> np.ndarray:
    """Satellite elevations (E, S) [deg], computed every ELEVATION_STEP_S and interpolated."""
    coarse = np.arange(times[0], times[-1] + ELEVATION_STEP_S, ELEVATION_STEP_S)
    tr = transit(nav, list(sats), pos, coarse)
    _, el = azimuth_elevation(pos, pos + tr.line_of_sight)
    el = np.degrees(el)
    out = np.empty((len(times), len(sats)))
    for j in range(len(sats)):
        ok = np.isfinite(el[:, j])
        out[:, j] = np.interp(times, coarse[ok], el[ok, j]) if ok.sum() >= 2 else np.nan
    return out


def load_station(path, nav: NavigationData | None, name: str | None = None, systems=("G",)) -> StationSeries:
    return series_from_obs(read_obs(path), nav, name, systems)


# -- combinations ---------------------------------------------------------------------------------------------

def _lam(s: StationSeries):
    return 299_792_458.0 / s.freq_hz  # (S, 2)


def _alpha(s: StationSeries):
    return (s.freq_hz[:, 0] / s.freq_hz[:, 1]) ** 2 - 1.0  # TEQC's alpha: gamma - 1


def multipath_m(s: StationSeries):
    """(MP1, MP2) [m] before arc demeaning (Estey & Meertens 1999, TEQC): code minus the phase combination."""
    lam = _lam(s)
    L1 = s.phase_cyc[..., 0] * lam[:, 0]
    L2 = s.phase_cyc[..., 1] * lam[:, 1]
    a = _alpha(s)
    mp1 = s.code_m[..., 0] - (1 + 2 / a) * L1 + (2 / a) * L2
    mp2 = s.code_m[..., 1] - (2 * (a + 1) / a) * L1 + (2 * (a + 1) / a - 1) * L2
    return mp1, mp2


def geometry_free_phase_m(s: StationSeries):
    lam = _lam(s)
    return s.phase_cyc[..., 0] * lam[:, 0] - s.phase_cyc[..., 1] * lam[:, 1]


def geometry_free_code_m(s: StationSeries):
    return s.code_m[..., 1] - s.code_m[..., 0]


# -- slips and arcs -------------------------------------------------------------------------------------------

@dataclass
class Slips:
    flagged: np.ndarray  # (E, S) bool: loss of lock flagged inside an arc
    unflagged: np.ndarray  # (E, S) bool: the centre's detector fired without a flag
    segment: np.ndarray  # (E, S) int: continuous-phase segment id (-1 where no data)


def detect_slips(s: StationSeries) -> Slips:
    """Flags and the centre's detector, epoch by epoch (it is sequential); segments between slips and gaps."""
    valid = s.valid
    E, S = valid.shape
    det = CycleSlipDetector(max_gap_s=ARC_MAX_GAP_S)
    flagged = np.zeros((E, S), bool)
    unflagged = np.zeros((E, S), bool)
    new_arc = np.zeros((E, S), bool)
    codes = np.full((S, 2), "", dtype="<U2")
    lli2 = np.zeros((E, S, 2), np.int8)
    lli2[..., 0] = s.lli
    nan2 = np.full((S, 2), np.nan)
    for e in np.flatnonzero(valid.any(1)):
        cols = np.flatnonzero(valid[e])
        ep = StationEpoch(s.name, float(s.times[e]), s.sats[cols], s.code_m[e, cols], s.phase_cyc[e, cols],
                          lli2[e, cols], nan2[cols], s.freq_hz[cols], codes[cols])
        res = det.detect(ep.t_gpst, ep, ep, ep.freq_hz, set(s.sats[cols].tolist()))
        det.seen(ep.sats, ep.t_gpst)
        for j, c in enumerate(cols):
            sat = str(s.sats[c])
            if sat in res.new_arc:
                new_arc[e, c] = True
            elif sat in res.slipped:
                if s.lli[e, c]:
                    flagged[e, c] = True
                else:
                    unflagged[e, c] = True
    brk = new_arc | flagged | unflagged
    seg = np.cumsum(brk, axis=0) + np.arange(S)[None, :] * (E + 1)
    return Slips(flagged, unflagged, np.where(valid, seg, -1))


# -- per-station statistics -----------------------------------------------------------------------------------

@dataclass
class StationStats:
    name: str
    interval_s: float
    sat_hours: float
    mp1_m: dict  # bin label -> RMS
    mp2_m: dict
    gf_d2_mm: dict  # RMS of the geometry-free phase second difference at the series' interval
    n_mp: dict
    flagged_per_sat_h: float
    unflagged_per_sat_h: float
    n_flagged: int
    n_unflagged: int
    gaps_per_sat_h: float
    missing_epochs: float  # share of the grid's epochs without any data
    extra: dict = field(default_factory=dict)

    @property
    def phase_sigma_mm(self) -> dict:
        """Phase noise per frequency implied by the GF second difference (white, equal on L1 and L2)."""
        return {k: v / math.sqrt(12.0) for k, v in self.gf_d2_mm.items()}


def bin_label(lo: float, hi: float) -> str:
    return f"{lo:.0f}-{hi:.0f}"


def _binned_rms(values, el, mask):
    out, n = {}, {}
    for lo, hi in ELEVATION_BINS_DEG:
        m = mask & (el >= lo) & (el < hi) & np.isfinite(values)
        n[bin_label(lo, hi)] = int(m.sum())
        out[bin_label(lo, hi)] = float(np.sqrt(np.mean(values[m] ** 2))) if m.sum() else math.nan
    return out, n


def _demean_by_segment(values, seg, times, interval):
    """values minus their segment mean; NaN for segments shorter than MP_MIN_ARC_S or MP_MIN_ARC_EPOCHS."""
    ok = (seg >= 0) & np.isfinite(values)
    keys, inv = np.unique(seg[ok], return_inverse=True)
    cnt = np.bincount(inv)
    mean = np.bincount(inv, values[ok]) / cnt
    t = np.broadcast_to(times[:, None], seg.shape)[ok]
    span = np.full(len(keys), -np.inf)
    np.maximum.at(span, inv, t)
    first = np.full(len(keys), np.inf)
    np.minimum.at(first, inv, t)
    long = (cnt >= MP_MIN_ARC_EPOCHS) & (span - first + interval >= MP_MIN_ARC_S)
    out = np.full(values.shape, np.nan)
    out[ok] = np.where(long[inv], values[ok] - mean[inv], np.nan)
    return out


def station_statistics(s: StationSeries, slips: Slips | None = None) -> StationStats:
    slips = slips or detect_slips(s)
    valid = s.valid
    el = s.elevation_deg
    mp1, mp2 = multipath_m(s)
    mp1 = _demean_by_segment(mp1, slips.segment, s.times, s.interval_s)
    mp2 = _demean_by_segment(mp2, slips.segment, s.times, s.interval_s)
    mp1_b, n_mp = _binned_rms(mp1, el, valid)
    mp2_b, _ = _binned_rms(mp2, el, valid)
    gf = geometry_free_phase_m(s)
    seg = slips.segment
    same = (seg[2:] == seg[1:-1]) & (seg[1:-1] == seg[:-2]) & (seg[1:-1] >= 0)
    d2 = np.where(same, gf[2:] - 2 * gf[1:-1] + gf[:-2], np.nan) * 1e3
    gf_b, _ = _binned_rms(d2, el[1:-1], same)
    sat_h = valid.sum() * s.interval_s / 3600.0
    gaps = 0
    for j in range(len(s.sats)):
        t = s.times[valid[:, j]]
        dt = np.diff(t)
        gaps += int(((dt > 1.5 * s.interval_s) & (dt <= PASS_GAP_MAX_S)).sum())
    missing = float(1.0 - valid.any(1).mean())
    nf, nu = int(slips.flagged.sum()), int(slips.unflagged.sum())
    resets = int(count_phase_resets(s, slips.unflagged))
    return StationStats(s.name, s.interval_s, sat_h, mp1_b, mp2_b, gf_b, n_mp, nf / max(sat_h, 1e-9),
                        nu / max(sat_h, 1e-9), nf, nu, gaps / max(sat_h, 1e-9), missing,
                        extra=dict(resets=resets, resets_per_sat_h=resets / max(sat_h, 1e-9)))


def count_phase_resets(s: StationSeries, at: np.ndarray) -> int:
    """Epochs in `at` where code minus L1 phase jumped by more than RESET_CODE_MINUS_PHASE_M since the
    satellite's previous epoch with data: the phase re-aligned to the code (Trimble NetRS, decision 0150)."""
    cmp = s.code_m[..., 0] - s.phase_cyc[..., 0] * _lam(s)[:, 0]
    n = 0
    for j in np.flatnonzero(at.any(0)):
        rows = np.flatnonzero(s.valid[:, j])
        jump = np.abs(np.diff(cmp[rows, j]))
        n += int((at[rows[1:], j] & (jump > RESET_CODE_MINUS_PHASE_M)).sum())
    return n


# -- pair statistics ------------------------------------------------------------------------------------------

@dataclass
class PairStats:
    a: str
    b: str
    baseline_km: float
    interval_s: float
    dd_level_rms_mm: float  # DD L1 ionosphere after code levelling
    dd_level_p95_mm: float
    dd_change_rms_mm: dict  # lag [s] -> RMS of the DD L1 ionosphere's change over it
    n_level: int
    n_change: dict
    dd_phase_d2_mm: float = math.nan  # DD L1 phase second difference, robust sigma (noise, short baselines)
    dd_level_floor_mm: float = math.nan  # RMS of the levelling error in dd_level_rms_mm (code multipath)

    @property
    def dd_level_mm(self) -> float:
        """The DD ionosphere's RMS level with the levelling error taken out (in quadrature)."""
        return math.sqrt(max(self.dd_level_rms_mm**2 - self.dd_level_floor_mm**2, 0.0))

    def per_km(self, mm: float) -> float:
        return mm / self.baseline_km if self.baseline_km >= PER_KM_MIN_KM else math.nan

    @property
    def dd_phase_sigma_mm(self) -> float:
        """Undifferenced phase noise implied by the DD second difference: four white terms, sqrt(6) each."""
        return self.dd_phase_d2_mm / math.sqrt(24.0)


def _common(a: StationSeries, b: StationSeries):
    """Both series on their common epochs and satellites (b's epochs mapped onto a's grid)."""
    interval = max(a.interval_s, b.interval_s)
    a = a.decimated(interval)
    b = b.decimated(interval)
    ta = np.round(a.times, 3)
    tb = np.round(b.times, 3)
    t, ia, ib = np.intersect1d(ta, tb, return_indices=True)
    sats, ja, jb = np.intersect1d(a.sats, b.sats, return_indices=True)
    return a, b, ia[:, None], ja[None, :], ib[:, None], jb[None, :], t, sats, interval


def _level(gf_phase, gf_code, seg):
    """Geometry-free phase levelled to the code, arc by arc (NaN where the arc is too short), and the variance
    of each point's levelling error: (median of the arc's first half - of its second half)^2 / 4, empirical
    (code multipath is correlated over minutes, so the arc's scatter over sqrt(n) would understate it)."""
    diff = gf_phase - gf_code
    ok = (seg >= 0) & np.isfinite(diff)
    keys, inv = np.unique(seg[ok], return_inverse=True)
    cnt = np.bincount(inv)
    vals = diff[ok]
    order = np.lexsort((np.broadcast_to(np.arange(seg.shape[0])[:, None], seg.shape)[ok], inv))
    starts = np.concatenate([[0], np.cumsum(cnt)[:-1]])
    med = np.empty(len(keys))
    half_var = np.empty(len(keys))
    for i, (a, n) in enumerate(zip(starts, cnt)):  # one entry per arc: tens a day
        v = vals[order[a:a + n]]  # in time order
        med[i] = np.median(v)
        half_var[i] = (np.median(v[: n // 2]) - np.median(v[n // 2:])) ** 2 / 4.0 if n >= 2 else np.nan
    out = np.full(gf_phase.shape, np.nan)
    var = np.full(gf_phase.shape, np.nan)
    long = cnt[inv] >= LEVEL_MIN_EPOCHS
    out[ok] = np.where(long, gf_phase[ok] - med[inv], np.nan)
    var[ok] = np.where(long, half_var[inv], np.nan)
    return out, var


def pair_statistics(a: StationSeries, b: StationSeries, slips_a: Slips | None = None,
                    slips_b: Slips | None = None) -> PairStats:
    """DD ionosphere of a baseline, and its DD phase second difference."""
    baseline_km = float(np.linalg.norm(a.position_m - b.position_m) / 1e3)
    a2, b2, ia, ja, ib, jb, t, sats, interval = _common(a, b)
    sa = detect_slips(a2) if slips_a is None or a2 is not a else slips_a
    sb = detect_slips(b2) if slips_b is None or b2 is not b else slips_b
    alpha = _alpha(a2)[ja[0]]
    gfa, gfb = geometry_free_phase_m(a2)[ia, ja], geometry_free_phase_m(b2)[ib, jb]
    lev_a, var_a = _level(gfa, geometry_free_code_m(a2)[ia, ja], sa.segment[ia, ja])
    lev_b, var_b = _level(gfb, geometry_free_code_m(b2)[ib, jb], sb.segment[ib, jb])
    seg_a, seg_b = sa.segment[ia, ja], sb.segment[ib, jb]
    el = a2.elevation_deg[ia, ja]
    ok = np.isfinite(gfa) & np.isfinite(gfb) & (seg_a >= 0) & (seg_b >= 0) & np.isfinite(el)
    el_ok = np.where(ok, el, -np.inf)
    ref = np.argmax(el_ok, axis=1)  # (T,) the highest common satellite
    has_ref = np.isfinite(el_ok[np.arange(len(t)), ref]) & (el_ok.max(1) > -np.inf)
    rows = np.arange(len(t))
    # single differences, L1 ionosphere units [m]
    sd = (gfa - gfb) / alpha
    sd_lev = (lev_a - lev_b) / alpha
    use = ok & (el >= DD_MIN_ELEVATION_DEG) & has_ref[:, None] & (np.arange(len(sats))[None, :] != ref[:, None])
    dd_lev = sd_lev - sd_lev[rows, ref][:, None]
    sd_var = (var_a + var_b) / alpha**2
    dd_var = sd_var + sd_var[rows, ref][:, None]
    lv_ok = use & np.isfinite(dd_lev)
    lv = dd_lev[lv_ok] * 1e3
    floor = float(np.sqrt(np.mean(dd_var[lv_ok]))) * 1e3 if lv.size else math.nan
    changes, n_change = {}, {}
    for lag in DD_LAGS_S:
        k = int(round(lag / interval))
        if k < 1 or k >= len(t):
            changes[lag], n_change[lag] = math.nan, 0
            continue
        r0 = rows[:-k]
        same_t = np.isclose(t[k:] - t[:-k], lag)
        rf = ref[:-k]
        cont = (seg_a[k:] == seg_a[:-k]) & (seg_b[k:] == seg_b[:-k]) & ok[k:] & ok[:-k]
        ref_cont = cont[r0, rf]
        m = use[:-k] & cont & ref_cont[:, None] & same_t[:, None]
        ch = (sd[k:] - sd[r0 + k, rf][:, None]) - (sd[:-k] - sd[r0, rf][:, None])
        vals = ch[m] * 1e3
        changes[lag] = float(np.sqrt(np.mean(vals**2))) if vals.size else math.nan
        n_change[lag] = int(vals.size)
    # DD L1 phase second difference (noise on a short baseline; geometry is smooth over three epochs)
    lam1 = _lam(a2)[ja[0], 0]
    l1 = (a2.phase_cyc[ia, ja, 0] - b2.phase_cyc[ib, jb, 0]) * lam1
    dd1 = l1 - l1[rows, ref][:, None]
    if len(t) >= 3:
        cont3 = ((seg_a[2:] == seg_a[1:-1]) & (seg_a[1:-1] == seg_a[:-2]) & (seg_b[2:] == seg_b[1:-1])
                 & (seg_b[1:-1] == seg_b[:-2]) & ok[2:] & ok[1:-1] & ok[:-2])
        same_ref = (ref[2:] == ref[1:-1]) & (ref[1:-1] == ref[:-2])
        r1 = rows[1:-1]
        ref_c = cont3[r1 - 1, ref[1:-1]]
        m3 = cont3 & same_ref[:, None] & ref_c[:, None] & use[1:-1]
        regular = np.isclose(t[2:] - t[1:-1], interval) & np.isclose(t[1:-1] - t[:-2], interval)
        m3 &= regular[:, None]
        d2 = (dd1[2:] - 2 * dd1[1:-1] + dd1[:-2])[m3] * 1e3
        # robust: receiver clock jumps (ms) move a DD of phase at one epoch through the satellites' range rates
        dd_d2 = float(ROBUST_SIGMA * np.median(np.abs(d2))) if d2.size else math.nan
    else:
        dd_d2 = math.nan
    return PairStats(a.name, b.name, baseline_km, interval,
                     float(np.sqrt(np.mean(lv**2))) if lv.size else math.nan,
                     float(np.percentile(np.abs(lv), 95)) if lv.size else math.nan,
                     changes, int(lv.size), n_change, dd_d2, floor)


# -- tables ---------------------------------------------------------------------------------------------------

def _f(x, fmt="{:.2f}"):
    return "-" if x is None or not np.isfinite(x) else fmt.format(x)


def station_table(rows: list[tuple[str, StationStats]]) -> str:
    bins = [bin_label(lo, hi) for lo, hi in ELEVATION_BINS_DEG]
    head = (["source", "station", "dt s"] + [f"MP1 {b}" for b in bins] + [f"MP2 {b}" for b in bins]
            + [f"GF d2 mm {b}" for b in bins]
            + ["LLI slips /sat-h", "unflagged /sat-h", "of which resets /sat-h", "gaps /sat-h"])
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for src, st in rows:
        cells = [src, st.name, _f(st.interval_s, "{:g}")]
        cells += [_f(st.mp1_m[b]) for b in bins] + [_f(st.mp2_m[b]) for b in bins]
        cells += [_f(st.gf_d2_mm[b], "{:.1f}") for b in bins]
        cells += [_f(st.flagged_per_sat_h, "{:.3f}"), _f(st.unflagged_per_sat_h, "{:.3f}"),
                  _f(st.extra.get("resets_per_sat_h", math.nan), "{:.3f}"), _f(st.gaps_per_sat_h, "{:.3f}")]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def pair_table(rows: list[tuple[str, PairStats]]) -> str:
    head = ["source", "pair", "km", "dt s", "DD iono RMS mm/km (levelled, floor out)", "raw RMS mm/km",
            "levelling floor mm/km", "95 % mm/km", "30 s change RMS mm", "5 min change RMS mm",
            "5 min change mm/km", "DD L1 phase d2 sigma mm"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for src, p in rows:
        c30, c300 = p.dd_change_rms_mm.get(30.0, math.nan), p.dd_change_rms_mm.get(300.0, math.nan)
        out.append("| " + " | ".join([
            src, f"{p.a}-{p.b}", _f(p.baseline_km, "{:.1f}"), _f(p.interval_s, "{:g}"),
            _f(p.per_km(p.dd_level_mm), "{:.3f}"), _f(p.per_km(p.dd_level_rms_mm), "{:.3f}"),
            _f(p.per_km(p.dd_level_floor_mm), "{:.3f}"), _f(p.per_km(p.dd_level_p95_mm), "{:.3f}"),
            _f(c30, "{:.1f}"), _f(c300, "{:.1f}"), _f(p.per_km(c300), "{:.3f}"),
            _f(p.dd_phase_d2_mm if p.interval_s <= 1.0 and p.baseline_km <= DD_D2_MAX_KM else math.nan,
               "{:.1f}")]) + " |")
    return "\n".join(out)
