"""Single point positioning: iterated weighted least squares on pseudoranges, multi-GNSS.

Used for the GGA the rover sends to the caster, as the fallback when there are no usable
corrections, and as the RTK filter's starting point.  Unknowns: ECEF position and one receiver
clock per satellite system (GPS, Galileo, BeiDou and QZSS time scales differ by tens of ns, and
receivers add their own inter-system biases).  Corrections: broadcast satellite clock with the
relativistic term and the signal's group delay, Saastamoinen troposphere, optionally Klobuchar.
Integrity: a chi-square test of the weighted residuals, and when it fails the single satellite
whose exclusion passes best is left out (RAIM fault detection and exclusion).

Bad input never raises: `solve_spp` returns a result with `ok=False` and a message.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np

from augnet.gnss.constants import OMEGA_E_GPS_RAD_S, SPEED_OF_LIGHT_M_S, WGS84_A_M, WGS84_E2
from augnet.gnss.ephemeris import NavigationData, group_delay_s, satellite_state
from augnet.gnss.signals import FREQ_L1_HZ
from augnet.gnss.statistics import chi2_quantile
from augnet.onboard.atmosphere import klobuchar_l1_m, saastamoinen_m
from augnet.onboard.observations import BAND_FREQ_HZ, EpochObs

SPP_MAX_ITERATIONS = 10
SPP_CONVERGED_M = 1e-4
# Before the position is known (first iterations from the Earth's centre) no elevation exists;
# the mask and the atmosphere apply once the estimate is this close to the surface.
NEAR_SURFACE_RADIUS_M = 6.0e6
# Code noise model sigma^2 = a^2 + b^2 / sin^2(el): 0.3 m each (RTKLIB's 0.003 m phase x 100).
CODE_SIGMA_A_M = 0.3
CODE_SIGMA_B_M = 0.3
# Klobuchar corrects about half the ionospheric delay (IS-GPS-200 20.3.3.5.2.5): its error sigma
# is taken as half the correction; without it the whole delay (~5 m at zenith) is error.
KLOBUCHAR_ERROR_FRACTION = 0.5
UNMODELLED_IONO_SIGMA_M = 5.0
TROPO_MODEL_SIGMA_M = 0.3  # Saastamoinen with a standard atmosphere, at zenith (scaled by 1/sin el)
# RAIM: false-alarm probability of the chi-square residual test.
RAIM_FALSE_ALARM = 1e-3
# A position this far from the Earth's surface is not a receiver on the ground or in a train.
MAX_PLAUSIBLE_HEIGHT_M = 1.0e5
MIN_PLAUSIBLE_HEIGHT_M = -1.0e3
# Residuals beyond this [m] after convergence mean a blunder (wrong ephemeris, corrupt code).
GROSS_RESIDUAL_M = 1.0e3


class SatPositions(NamedTuple):
    position_m: np.ndarray  # (N, 3) ECEF at transmission (frame of transmission time)
    velocity_m_s: np.ndarray  # (N, 3)
    clock_s: np.ndarray  # (N,) satellite clock bias incl. relativity, no group delay
    clock_drift_s_s: np.ndarray
    ephemeris_index: np.ndarray  # (N,) row in nav.table, -1 where none
    valid: np.ndarray  # (N,) bool
    accuracy_m: np.ndarray  # (N,) broadcast URA/SISA


def satellite_positions(nav: NavigationData, sats: Sequence[str], t_obs: float, pseudorange_m,
                        t_select: float | None = None) -> SatPositions:
    """Satellite states at signal transmission, from the receiver time tag and the pseudorange.

    t_tx = t_obs - P/c - dt_sat: the receiver clock error is inside P, so it need not be known
    (the same approach as every RINEX post-processor).  Ephemerides are selected at `t_select`
    (default t_obs); RTK passes the rover's time for the base too, so both ends use the same issue
    of data even when a new set's toe falls between their time tags.
    """
    sats = list(sats)
    n = len(sats)
    pr = np.asarray(pseudorange_m, dtype=float)
    if n == 0 or len(nav) == 0:
        z = np.zeros((n, 3))
        return SatPositions(z, z, np.zeros(n), np.zeros(n), np.full(n, -1), np.zeros(n, bool), np.zeros(n))
    idx = _select_cached(nav, sats, float(t_obs if t_select is None else t_select))
    valid = (idx >= 0) & np.isfinite(pr)
    rows = nav.table.take(np.where(valid, idx, 0))
    t = np.full(n, float(t_obs))
    tau = np.where(np.isfinite(pr), pr, 0.0) / SPEED_OF_LIGHT_M_S
    st = satellite_state(rows, t, -tau)
    # the satellite's clock bias (under a millisecond) moves the transmission time once more: carry the
    # state by its velocity and drift rather than evaluating the orbit again (the acceleration term
    # over 1 ms is a micrometre)
    d = -st.clock_bias_s
    position = st.position_m + st.velocity_m_s * d[:, None]
    clock = st.clock_bias_s + st.clock_drift_s_s * d
    pos = np.where(valid[:, None], position, np.nan)
    vel = np.where(valid[:, None], st.velocity_m_s, np.nan)
    acc = np.where(valid, rows.accuracy_m, np.nan)
    return SatPositions(pos, vel, np.where(valid, clock, np.nan),
                        np.where(valid, st.clock_drift_s_s, np.nan), np.where(valid, idx, -1), valid, acc)


# Ephemeris selection changes only when a new set is uploaded (GPS every 2 h, Galileo every 10 min):
# reusing a selection for this long [s] picks a set that is still valid and may be a few seconds
# older than the newest, and saves ~2 ms per call (several calls per epoch).  Base and rover of one
# epoch share the key, so they still use the same issue of data.
SELECTION_CACHE_S = 10.0
_SELECTION_CACHE_SIZE = 16
# one small cache per NavigationData object, gone with it (never confused with another one)
_selection_cache: "weakref.WeakKeyDictionary[NavigationData, dict]" = weakref.WeakKeyDictionary()


def _select_cached(nav: NavigationData, sats: Sequence[str], t: float) -> np.ndarray:
    cache = _selection_cache.setdefault(nav, {})
    key = (tuple(str(x) for x in sats), math.floor(t / SELECTION_CACHE_S))
    hit = cache.get(key)
    if hit is not None:
        return hit
    idx = nav.select(list(key[0]), t)
    if len(cache) >= _SELECTION_CACHE_SIZE:
        cache.pop(next(iter(cache)))
    cache[key] = idx
    return idx


def first_code(obs: EpochObs) -> np.ndarray:
    """The first available pseudorange per satellite, slot 0 first (what SPP uses, and RTK for the
    transmission time, where a metre of difference between signals moves the satellite by 13 um)."""
    out = obs.code_m[:, 0].copy()
    for f in range(1, obs.code_m.shape[1]):
        out = np.where(np.isnan(out), obs.code_m[:, f], out)
    return out


def receiver_frame(rx_m) -> tuple[np.ndarray, np.ndarray]:
    """(geodetic lat, lon, h; ENU rotation, rows E, N, U) of one receiver position, kept for the
    positions seen last (the base's never changes; the rover's serves several computations per epoch).

    The same relation as `augnet.gnss.geometry.ecef_to_geodetic` (its two fixed-point refinement
    steps), started from Bowring's closed form instead of PROJ and done in scalar arithmetic: equal to
    an ulp in the angles and a nanometre in height, and ten times faster for one point."""
    p = np.asarray(rx_m, dtype=float)
    key = p.tobytes()
    hit = _frame_cache.get(key)
    if hit is None:
        x, y, z = float(p[0]), float(p[1]), float(p[2])
        a, e2 = WGS84_A_M, WGS84_E2
        rho = math.hypot(x, y)
        b = a * math.sqrt(1.0 - e2)
        th = math.atan2(z * a, rho * b)
        lat = math.atan2(z + e2 / (1.0 - e2) * b * math.sin(th) ** 3, rho - e2 * a * math.cos(th) ** 3)
        for _ in range(2):
            sl, cl = math.sin(lat), math.cos(lat)
            n = a / math.sqrt(1.0 - e2 * sl * sl)
            h = rho * cl + z * sl - a * math.sqrt(1.0 - e2 * sl * sl)
            lat = math.atan2(z, rho * (1.0 - e2 * n / (n + h)))
        lon = math.atan2(y, x)
        sl, cl = math.sin(lat), math.cos(lat)
        so, co = math.sin(lon), math.cos(lon)
        h = rho * cl + z * sl - a * math.sqrt(1.0 - e2 * sl * sl)
        rot = np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])
        hit = (np.array([lat, lon, h]), rot)
        if len(_frame_cache) >= _FRAME_CACHE_SIZE:
            _frame_cache.pop(next(iter(_frame_cache)))
        _frame_cache[key] = hit
    return hit


_FRAME_CACHE_SIZE = 8
_frame_cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def azimuth_elevation_from(rx_m, rot: np.ndarray, sat_m) -> tuple[np.ndarray, np.ndarray]:
    """`augnet.gnss.geometry.azimuth_elevation` with the receiver's ENU rotation already known."""
    d = np.asarray(sat_m, dtype=float) - np.asarray(rx_m, dtype=float)
    enu = np.einsum("...ij,...j->...i", rot, d)
    e, n, u = enu[..., 0], enu[..., 1], enu[..., 2]
    return np.mod(np.arctan2(e, n), 2.0 * np.pi), np.arctan2(u, np.hypot(e, n))


def geometric_range(sat_pos_m, rx_m):
    """(range [m] incl. Sagnac, unit line-of-sight receiver->satellite (N, 3))."""
    d = sat_pos_m - rx_m
    r = np.linalg.norm(d, axis=-1)
    r = np.where(r > 0.0, r, np.nan)  # a satellite at the receiver is bad data, not a division by zero
    sagnac = OMEGA_E_GPS_RAD_S * (sat_pos_m[..., 0] * rx_m[1] - sat_pos_m[..., 1] * rx_m[0]) / SPEED_OF_LIGHT_M_S
    return r + sagnac, d / r[..., None]


@dataclass
class SppOptions:
    elevation_mask_rad: float = math.radians(10.0)
    ionosphere: str = "klobuchar"  # 'klobuchar' or 'off'
    klobuchar_alpha: Sequence[float] | None = None
    klobuchar_beta: Sequence[float] | None = None
    troposphere: bool = True
    raim: bool = True
    systems: Sequence[str] = ("G", "E", "C", "J")


@dataclass
class SppResult:
    ok: bool
    time: float
    position_m: np.ndarray  # (3,) ECEF, NaN when not ok
    clocks_m: dict[str, float] = field(default_factory=dict)  # receiver clock per system [m]
    covariance_m2: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))
    used: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # mask over the epoch's sats
    residuals_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    excluded: list[str] = field(default_factory=list)  # satellites RAIM left out
    gdop: float = math.nan
    chi2: float = math.nan
    message: str = ""
    converged: bool = True  # False when a limited number of `steps` stopped it short of convergence

    @property
    def n_used(self) -> int:
        return int(np.count_nonzero(self.used))


def _fail(t, n, msg) -> SppResult:
    return SppResult(False, t, np.full(3, np.nan), used=np.zeros(n, bool), residuals_m=np.full(n, np.nan), message=msg)


def solve_spp(obs: EpochObs, nav: NavigationData, options: SppOptions | None = None,
              initial_m=None, sat_positions: SatPositions | None = None, steps: int | None = None) -> SppResult:
    """Position and per-system clocks from slot-0 pseudoranges of one epoch.  Never raises on data.

    `sat_positions`: the epoch's satellite states if the caller has them already, computed by
    `satellite_positions(nav, obs.sats, obs.time, first_code(obs))` (what this function would do).
    `steps`: stop after this many Gauss-Newton steps from `initial_m` instead of iterating to
    convergence (one step from a point within 100 m is exact to a millimetre: enough to check given
    coordinates against the data).
    """
    opt = options or SppOptions()
    n = len(obs.sats)
    try:
        return _solve(obs, nav, opt, initial_m, sat_positions, steps)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:  # defensive: bad numbers
        return _fail(obs.time, n, f"SPP failed: {exc}")


def _solve(obs: EpochObs, nav: NavigationData, opt: SppOptions, initial_m, sp_given=None, steps=None) -> SppResult:
    n = len(obs.sats)
    if n == 0:
        return _fail(obs.time, n, "no observations")
    sys_ = np.array([s[0] for s in obs.sats])
    obs = obs.sanitised()
    # slot 0 (L1/E1/B1I) code, or the next slot's where slot 0 is missing (its own group delay and
    # ionospheric scaling follow from the signal)
    slot = np.zeros(n, dtype=int)
    for f in range(1, obs.code_m.shape[1]):
        slot = np.where(np.isnan(obs.code_m[np.arange(n), slot]) & np.isfinite(obs.code_m[:, f]), f, slot)
    rows_n = np.arange(n)
    pr = obs.code_m[rows_n, slot].copy()
    signal = obs.signal[rows_n, slot]
    usable = np.isfinite(pr) & np.isin(sys_, list(opt.systems)) & (pr > 1.0e7) & (pr < 6.0e7)
    # (satellites not usable are masked below whatever their computed state)
    sp = sp_given if sp_given is not None else satellite_positions(nav, obs.sats, obs.time, np.where(usable, pr, np.nan))
    usable &= sp.valid
    # group delay of the slot-0 signal (TGD, BGD); unknown signals get none
    tgd = np.zeros(n)
    if np.any(sp.valid):
        rows = nav.table.take(np.where(sp.valid, sp.ephemeris_index, 0))
        for sig in np.unique(signal):
            if sig:
                m = signal == sig
                gd = group_delay_s(rows, sig)
                tgd = np.where(m & np.isfinite(gd), gd, tgd)
    freq0 = np.array([BAND_FREQ_HZ.get((s[0], sig[:1]), FREQ_L1_HZ) if sig else FREQ_L1_HZ
                      for s, sig in zip(obs.sats, signal)])
    iono_scale = (FREQ_L1_HZ / freq0) ** 2
    alpha = opt.klobuchar_alpha
    beta = opt.klobuchar_beta

    x = np.zeros(3)
    if initial_m is not None and np.all(np.isfinite(initial_m)) and 6.0e6 < np.linalg.norm(initial_m) < 6.5e6:
        x = np.array(initial_m, dtype=float)  # a plausible starting point near the surface
    excluded: list[str] = []
    exclude_mask = np.zeros(n, bool)
    for _raim_round in range(3):
        res = _iterate(obs, sp, pr, tgd, iono_scale, usable & ~exclude_mask, sys_, x, opt, alpha, beta, steps)
        if not res.ok or not opt.raim:
            break
        dof = res.n_used - 3 - len(res.clocks_m)
        if dof <= 0 or res.chi2 <= chi2_quantile(dof, RAIM_FALSE_ALARM):
            break
        # exclusion: try each used satellite, keep the best passing solution
        best = None
        for j in np.flatnonzero(res.used):
            m = exclude_mask.copy()
            m[j] = True
            r = _iterate(obs, sp, pr, tgd, iono_scale, usable & ~m, sys_, res.position_m, opt, alpha, beta, steps)
            if r.ok:
                d = r.n_used - 3 - len(r.clocks_m)
                if d > 0 and (best is None or r.chi2 / chi2_quantile(d, RAIM_FALSE_ALARM) < best[1]):
                    best = (j, r.chi2 / chi2_quantile(d, RAIM_FALSE_ALARM), r)
        if best is None:
            res.message = "RAIM: residual test failed, no exclusion possible"
            break
        exclude_mask[best[0]] = True
        excluded.append(str(obs.sats[best[0]]))
        res = best[2]
        if best[1] <= 1.0:
            break
    res.excluded = excluded
    if res.ok and excluded and not res.message:
        res.message = f"RAIM excluded {','.join(excluded)}"
    return res


def _iterate(obs, sp, pr, tgd, iono_scale, usable, sys_, x0, opt, alpha, beta, steps=None) -> SppResult:
    n = len(obs.sats)
    x = np.array(x0, dtype=float)
    clocks: dict[str, float] = {}
    converged = True
    for it in range(SPP_MAX_ITERATIONS if steps is None else steps):
        near = np.linalg.norm(x) > NEAR_SURFACE_RADIUS_M
        rng, los = geometric_range(np.where(usable[:, None], sp.position_m, 0.0), x)
        use = usable.copy()
        var = np.full(n, np.inf)
        corr = np.zeros(n)
        if near:
            llh, rot = receiver_frame(x)
            az, el = azimuth_elevation_from(x, rot, np.where(usable[:, None], sp.position_m, x + 1.0))
            use &= el >= opt.elevation_mask_rad
            sin_el = np.maximum(np.sin(el), 0.05)
            var = CODE_SIGMA_A_M**2 + CODE_SIGMA_B_M**2 / sin_el**2
            if opt.troposphere:
                corr += saastamoinen_m(llh[0], llh[2], el)
                var = var + (TROPO_MODEL_SIGMA_M / (sin_el + 0.1)) ** 2
            if opt.ionosphere == "klobuchar":
                from augnet.onboard.atmosphere import KLOBUCHAR_DEFAULT_ALPHA, KLOBUCHAR_DEFAULT_BETA
                iono = klobuchar_l1_m(obs.time, llh[0], llh[1], az, el,
                                      alpha or KLOBUCHAR_DEFAULT_ALPHA, beta or KLOBUCHAR_DEFAULT_BETA) * iono_scale
                corr += iono
                var = var + (KLOBUCHAR_ERROR_FRACTION * iono) ** 2
            else:
                var = var + (UNMODELLED_IONO_SIGMA_M * iono_scale / sin_el) ** 2
            var = var + np.nan_to_num(sp.accuracy_m, nan=10.0) ** 2
        else:
            var = np.full(n, 100.0)
        systems = [s for s in ("G", "E", "C", "J") if np.any(use & (sys_ == s))]
        n_unk = 3 + len(systems)
        if np.count_nonzero(use) < n_unk:
            return _fail(obs.time, n, f"too few satellites ({int(np.count_nonzero(use))}) for {n_unk} unknowns")
        idx = np.flatnonzero(use)
        H = np.zeros((len(idx), n_unk))
        H[:, :3] = -los[idx]
        for k, s in enumerate(systems):
            H[:, 3 + k] = (sys_[idx] == s)
        clk = np.array([clocks.get(s, 0.0) for s in systems])
        pred = rng[idx] + H[:, 3:] @ clk - SPEED_OF_LIGHT_M_S * (sp.clock_s[idx] - tgd[idx]) + corr[idx]
        v = pr[idx] - pred
        w = 1.0 / var[idx]
        A = H.T @ (H * w[:, None])
        try:
            Q = np.linalg.inv(A)
        except np.linalg.LinAlgError:
            return _fail(obs.time, n, "singular geometry")
        dx = Q @ (H.T @ (w * v))
        x = x + dx[:3]
        clk = clk + dx[3:]
        clocks = {s: float(c) for s, c in zip(systems, clk)}
        if np.linalg.norm(dx[:3]) < SPP_CONVERGED_M and near:
            break
    else:
        if steps is None:
            return _fail(obs.time, n, "SPP did not converge")
        converged = False
    # residuals after the last update
    rng, _ = geometric_range(np.where(usable[:, None], sp.position_m, 0.0), x)
    pred = rng[idx] + H[:, 3:] @ clk - SPEED_OF_LIGHT_M_S * (sp.clock_s[idx] - tgd[idx]) + corr[idx]
    v = pr[idx] - pred
    resid = np.full(n, np.nan)
    resid[idx] = v
    llh, _ = receiver_frame(x)
    if not (MIN_PLAUSIBLE_HEIGHT_M < llh[2] < MAX_PLAUSIBLE_HEIGHT_M):
        return SppResult(False, obs.time, np.full(3, np.nan), used=use, residuals_m=resid,
                         message=f"implausible height {llh[2]:.0f} m")
    chi2 = float(np.sum(v**2 * w))
    gdop = float(np.sqrt(np.trace(np.linalg.inv(H.T @ H))))
    res = SppResult(True, obs.time, x, clocks, Q[:3, :3], use, resid, [], gdop, chi2, "", converged)
    if np.any(np.abs(v) > GROSS_RESIDUAL_M):
        res.chi2 = math.inf  # forces RAIM exclusion of the blunder
    return res


# Doppler velocity: residuals beyond this [m/s] are left out (a wrong Doppler, a cycle-slip spike).
DOPPLER_MAX_RESIDUAL_M_S = 5.0
DOPPLER_SIGMA_M_S = 0.05  # range-rate noise of a geodetic / good automotive receiver, per satellite


def doppler_velocity(obs: EpochObs, nav: NavigationData, position_m, mask_rad: float = math.radians(10.0),
                     sat_positions: SatPositions | None = None):
    """(velocity ECEF [m/s] (3,), its covariance (3, 3)) from slot-0 Dopplers by least squares with a
    receiver clock drift; NaNs when fewer than five Dopplers are usable.  Range rate = -lambda * D."""
    nan = (np.full(3, np.nan), np.full((3, 3), np.nan))
    p = np.asarray(position_m, dtype=float)
    if not np.all(np.isfinite(p)):
        return nan
    o = obs.sanitised()
    dop = o.doppler_hz[:, 0]
    lam = o.wavelength_m[:, 0]
    if sat_positions is None:
        sp = satellite_positions(nav, o.sats, o.time, o.code_m[:, 0])
        ok = sp.valid & np.isfinite(dop) & np.isfinite(lam)
    else:  # computed from `first_code`: the same states wherever slot 0 has a code
        sp = sat_positions
        ok = sp.valid & np.isfinite(o.code_m[:, 0]) & np.isfinite(dop) & np.isfinite(lam)
    if np.count_nonzero(ok) < 5:
        return nan
    _, los = geometric_range(np.where(ok[:, None], sp.position_m, p + 1.0), p)
    _, rot = receiver_frame(p)
    _, el = azimuth_elevation_from(p, rot, np.where(ok[:, None], sp.position_m, p + np.array([0.0, 0.0, 1.0])))
    ok &= el >= mask_rad
    if np.count_nonzero(ok) < 5:
        return nan
    idx = np.flatnonzero(ok)
    e = los[idx]
    rr = -lam[idx] * dop[idx]
    # satellite motion and clock drift, and the Earth-rotation (Sagnac) rate for a receiver at rest
    vs = sp.velocity_m_s[idx]
    sag = OMEGA_E_GPS_RAD_S / SPEED_OF_LIGHT_M_S * (vs[:, 0] * p[1] - vs[:, 1] * p[0])
    y = rr - np.einsum("ij,ij->i", e, vs) + SPEED_OF_LIGHT_M_S * sp.clock_drift_s_s[idx] - sag
    H = np.column_stack((-e, np.ones(len(idx))))
    use = np.ones(len(idx), bool)
    for _ in range(2):
        if np.count_nonzero(use) < 5:
            return nan
        sol, *_ = np.linalg.lstsq(H[use], y[use], rcond=None)
        res = y - H @ sol
        new = np.abs(res - np.median(res[use])) < DOPPLER_MAX_RESIDUAL_M_S
        if np.array_equal(new, use):
            break
        use = new
    try:
        cov = np.linalg.inv(H[use].T @ H[use]) * DOPPLER_SIGMA_M_S**2
    except np.linalg.LinAlgError:
        return nan
    return sol[:3], cov[:3, :3]
