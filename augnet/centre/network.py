"""The reference-station network: baselines, closure checks, and DD residuals relative to a master.

Baselines join each station to its nearest neighbours (plus a minimum spanning tree, so the network is
connected). Each baseline resolves its own ambiguities (`baseline.py`); the network then

- checks closure around every triangle of baselines (the DD integers of a-b, b-c and a-c must add up, per
  satellite and frequency; a misclosure means one of them is wrong, and the satellite is dropped on the
  triangle's baselines for that epoch);
- chains baseline residuals along the shortest path from the master station to every station, after
  re-referencing them to one reference satellite per system, giving DD residuals (dispersive and
  non-dispersive) of every station against the master: the input of the interpolation;
- hands each baseline, for the next epoch, ionosphere hints for the satellites it has not fixed: the DD
  ionosphere predicted from the other baselines where they are fixed (a linear model per satellite pair over
  the network), which separates the wide-lane candidates (0.57-0.8 m of DD ionosphere apart) at once;
- fits a single-layer ionosphere model over every baseline's fixed satellites (`ionosphere_model`) and hands
  each baseline its prediction for the satellites not fixed there: the prior of their integer decision.
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.baseline import (BaselineConfig, BaselineEpoch, BaselineSolver, day_ionosphere_ppm,
                                   rms_upper_bound_factor)
from augnet.centre.integrity import Alarm, IntegrityMonitor
from augnet.centre.observations import StationEpoch
from augnet.centre.satellite_geometry import SatelliteGeometry, satellite_geometry
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.ionosphere import IONO_K_M3_S2, SHELL_HEIGHT_M, thin_shell_mapping
from augnet.gnss.geometry import ecef_to_enu

NEIGHBOURS_PER_STATION = 2


def choose_baselines(names: list[str], xyz: np.ndarray, k: int = NEIGHBOURS_PER_STATION) -> list[tuple[int, int]]:
    """Edges (i, j), i < j: every station to its k nearest, plus a minimum spanning tree."""
    n = len(names)
    d = np.linalg.norm(xyz[:, None, :] - xyz[None, :, :], axis=2)
    edges = set()
    for i in range(n):
        for j in np.argsort(d[i])[1:k + 1]:
            edges.add((min(i, int(j)), max(i, int(j))))
    # Prim's minimum spanning tree guarantees connectivity
    seen = {0}
    heap = [(d[0, j], 0, j) for j in range(1, n)]
    heapq.heapify(heap)
    while heap and len(seen) < n:
        _, i, j = heapq.heappop(heap)
        if j in seen:
            continue
        seen.add(j)
        edges.add((min(i, j), max(i, j)))
        for m in range(n):
            if m not in seen:
                heapq.heappush(heap, (d[j, m], j, m))
    return sorted(edges)


def triangles(edges: list[tuple[int, int]]) -> list[tuple[int, int, int]]:
    es = set(edges)
    nodes = sorted({i for e in edges for i in e})
    return [t for t in itertools.combinations(nodes, 3)
            if (t[0], t[1]) in es and (t[1], t[2]) in es and (t[0], t[2]) in es]


@dataclass
class NetworkEpoch:
    t_gpst: float
    master: str
    stations: list[str]  # row order of the residual matrices; the master first
    station_en_m: np.ndarray  # (n, 2) east/north of each station from the master [m]
    station_xyz_m: np.ndarray  # (n, 3)
    refs: dict[str, str]  # network reference satellite per system
    sats: np.ndarray  # (S,) columns of the residual matrices
    dd_iono_m: np.ndarray  # (n, S) DD ionosphere on f1 of station minus master, sat minus ref; NaN unknown
    dd_trop_m: np.ndarray  # (n, S) DD non-dispersive residual beyond the model
    baselines: dict[str, BaselineEpoch | None]
    misclosures: int = 0
    present: list[str] = field(default_factory=list)  # stations with data this epoch
    clocks: dict[str, float] = field(default_factory=dict)  # receiver clock estimates [s] per station
    excluded: set[str] = field(default_factory=set)  # satellites the integrity monitor took out
    alarms: list[Alarm] = field(default_factory=list)  # alarms raised this epoch

    def fixed_fraction(self) -> dict[str, float]:
        return {k: (b.fixed_fraction if b is not None else 0.0) for k, b in self.baselines.items()}


class NetworkSolver:
    def __init__(self, stations: dict[str, np.ndarray], master: str | None = None,
                 config: BaselineConfig | None = None, edges: list[tuple[str, str]] | None = None):
        self.names = list(stations)
        self.xyz = np.array([np.asarray(stations[n], float) for n in self.names])
        self.master = master if master is not None else self._central_station()
        if edges is None:
            idx_edges = choose_baselines(self.names, self.xyz)
        else:
            pos = {n: i for i, n in enumerate(self.names)}
            idx_edges = sorted((min(pos[a], pos[b]), max(pos[a], pos[b])) for a, b in edges)
        self.edges = idx_edges
        self.triangles = triangles(idx_edges)
        self.cfg = config or BaselineConfig()
        self.solvers = {(i, j): BaselineSolver(self.names[i], self.xyz[i], self.names[j], self.xyz[j], self.cfg)
                        for i, j in idx_edges}
        m = self.names.index(self.master)
        self.order = [m] + [i for i in range(len(self.names)) if i != m]
        self.en = ecef_to_enu(self.xyz - self.xyz[m], self.xyz[m])[:, :2]
        # baseline vectors (b minus a, east/north) and, per baseline, the others near enough to lend it their
        # ionosphere
        self._dx = {e: self.en[e[1]] - self.en[e[0]] for e in idx_edges}
        self._len = {e: float(np.linalg.norm(v)) for e, v in self._dx.items()}
        mid = {e: 0.5 * (self.en[e[0]] + self.en[e[1]]) for e in idx_edges}
        far = self.cfg.iono_hint_max_distance_km * 1e3
        self._near = {t: [(e, float(np.linalg.norm(mid[e] - mid[t]))) for e in idx_edges
                          if e != t and np.linalg.norm(mid[e] - mid[t]) <= far] for t in idx_edges}
        self._hints: dict[tuple[int, int], dict] = {}
        self._model_hints: dict[tuple[int, int], dict] = {}
        self.iono_model: IonosphereModel | None = None
        self.clocks = {n: 0.0 for n in self.names}
        self.integrity = IntegrityMonitor(self.names)

    def _central_station(self) -> str:
        c = self.xyz.mean(axis=0)
        return self.names[int(np.argmin(np.linalg.norm(self.xyz - c, axis=1)))]

    def update(self, epochs: dict[str, StationEpoch], nav: NavigationData) -> NetworkEpoch:
        present = {n for n, e in epochs.items() if e is not None and len(e.sats) and n in self.clocks}
        results: dict[tuple[int, int], BaselineEpoch | None] = {}
        t = next(iter(epochs[n].t_gpst for n in present)) if present else float("nan")
        geom: dict[str, SatelliteGeometry] = {}
        pos = {n: i for i, n in enumerate(self.names)}
        for n in present:
            ep = epochs[n]
            geom[n] = satellite_geometry(ep.sats, ep.t_gpst, self.xyz[pos[n]], nav, ep.code_m[:, 0], self.clocks[n])
            self.clocks[n] = geom[n].clock_s
        excluded = self.integrity.observe(t, {n: epochs[n] for n in present}, geom) if present else set()
        for (i, j), solver in self.solvers.items():
            a, b = self.names[i], self.names[j]
            if a in present and b in present:
                results[(i, j)] = solver.update(epochs[a], epochs[b], nav, geom[a], geom[b], excluded,
                                                self._hints.get((i, j)), self._model_hints.get((i, j)))
            else:
                results[(i, j)] = None
        misclosures = self._check_closures(results)
        self._share_day_ionosphere()
        self._hints = self._iono_hints(results)
        self.iono_model = ionosphere_model(results, self._len, self.cfg)
        self._model_hints = self._model_predictions(results)
        refs = self._network_refs(results)
        sats = np.array(sorted({str(s) for r in results.values() if r is not None for s in r.sats}))
        n = len(self.names)
        iono = np.full((n, len(sats)), np.nan)
        trop = np.full((n, len(sats)), np.nan)
        col = {s: k for k, s in enumerate(sats)}
        per_edge = {e: self._rereferenced(r, refs, col, len(sats)) for e, r in results.items()}
        m = self.order[0]
        iono[m] = 0.0
        trop[m] = 0.0
        # Residuals of every station against the master, chained over baselines: per satellite, along the
        # shortest path (in metres) on which that satellite is fixed on every baseline. Edges are relaxed in
        # order of length, so a short path wins over a long one; a satellite missing on one baseline
        # reaches the station over another.
        edges = sorted((self.solvers[e].length_m, e) for e, v in per_edge.items() if v is not None)
        dist = np.full((n, len(sats)), np.inf)
        dist[m] = 0.0
        for _ in range(n):
            changed = False
            for length, (a, b) in edges:
                vi, vt = per_edge[(a, b)]
                ok = np.isfinite(vi) & np.isfinite(vt)
                for src, dst, sign in ((a, b, 1.0), (b, a, -1.0)):  # residuals are b minus a
                    better = ok & np.isfinite(dist[src]) & (dist[src] + length < dist[dst])
                    if better.any():
                        iono[dst, better] = iono[src, better] + sign * vi[better]
                        trop[dst, better] = trop[src, better] + sign * vt[better]
                        dist[dst, better] = dist[src, better] + length
                        changed = True
            if not changed:
                break
        rows = self.order
        return NetworkEpoch(
            t_gpst=t, master=self.master, stations=[self.names[i] for i in rows], station_en_m=self.en[rows],
            station_xyz_m=self.xyz[rows], refs=refs, sats=sats, dd_iono_m=iono[rows], dd_trop_m=trop[rows],
            baselines={self.solvers[e].name: r for e, r in results.items()}, misclosures=misclosures,
            present=sorted(present), clocks=dict(self.clocks), excluded=set(excluded),
            alarms=self.integrity.drain())

    def _share_day_ionosphere(self) -> None:
        """The ionosphere's measured rate (mean over the baselines) and the day's level from every baseline's fixed
        satellites at once (in ppm of each baseline's length), handed to every baseline: a network of four
        baselines with three satellites fixed on each knows the day's level after the first fixes, where one
        baseline alone would wait for more."""
        rates = [s.iono_rate_ppm_sqrt_s for s in self.solvers.values() if s.iono_rate_ppm_sqrt_s is not None]
        for s in self.solvers.values():
            s.iono_rate_network = float(np.mean(rates)) if rates else None
        q = np.concatenate([s.iono_day_q for s in self.solvers.values()])
        level = day_ionosphere_ppm(float(np.sqrt(np.mean(q**2))) if q.size else math.nan, q.size, self.cfg)
        if level is None:
            return
        for s in self.solvers.values():
            # the network's level is kept until a lower one is well established (an epoch with few fixes does
            # not reset it), and follows a higher one at once
            prev = s.iono_day_network
            s.iono_day_network = level if prev is None or level > prev or q.size >= 2 * self.cfg.iono_day_min_sats \
                else prev

    def _iono_hints(self, results) -> dict[tuple[int, int], dict[str, tuple[str, float, float]]]:
        """For each baseline and satellite not fixed there: the DD ionosphere (against the baseline's reference)
        predicted from the other baselines where both are fixed, with a linear model per satellite pair (DD
        ionosphere = gradient . baseline vector; the gradient fitted by weighted least squares, each source
        weighted by the model error at its distance). A satellite fixed on one baseline thus helps the parallel
        ones at once, and two non-parallel ones help every baseline around them. Used for the next epoch."""
        cfg = self.cfg
        if not cfg.iono_hints:
            return {}
        shell = cfg.iono_shell_height_km or 350.0
        rr = 6371.0 / (6371.0 + shell)
        info = {e: (r, {str(s): k for k, s in enumerate(r.sats)}) for e, r in results.items() if r is not None}
        hints: dict[tuple[int, int], dict[str, tuple[str, float, float]]] = {}
        for t, (rt, post) in info.items():
            need = ~rt.fixed & (rt.eligible if rt.eligible is not None else True)
            if not need.any():
                continue
            dxt = self._dx[t]
            lt = self._len[t]
            # the hint's error model is the quiet day's: scaled up with the day's level where it is higher
            activity = max(1.0, self.solvers[t].iono_level_ppm / cfg.iono_prior_ppm)
            el = np.radians(np.minimum(rt.elevation_a_deg, rt.elevation_b_deg))
            mapping = 1.0 / np.sqrt(1.0 - (rr * np.cos(el)) ** 2)
            out = {}
            for k in np.flatnonzero(need):
                s = str(rt.sats[k])
                ref = rt.refs.get(s[0])
                kr = post.get(ref)
                if kr is None or s == ref:
                    continue
                meff = math.hypot(mapping[k], mapping[kr])
                lam = np.eye(2) / (10.0 * cfg.iono_prior_ppm * 1e-6 * meff) ** 2  # weak prior on the gradient
                vec = np.zeros(2)
                used = 0
                for e, dist in self._near[t]:
                    src = info.get(e)
                    if src is None:
                        continue
                    re, pe = src
                    ks, kq = pe.get(s), pe.get(ref)
                    if ks is None or kq is None:
                        continue
                    dxe = self._dx[e]
                    var = (cfg.iono_hint_ppm_per_100km * activity * 1e-6 * max(dist, 0.5 * lt) / 1e5 * self._len[e]
                           * meff) ** 2
                    if re.fixed[ks] and re.fixed[kq]:
                        y = re.dd_iono_m[ks] - re.dd_iono_m[kq]
                    elif (cfg.iono_hints_float and re.iono_float_m is not None and re.refs.get(s[0]) == ref
                          and not set(e) & set(t)):
                        # not fixed there either: the float estimate of a baseline with no station in common
                        # (independent multipath and noise), less its prior (which this baseline has too): in
                        # information form, data = posterior - prior
                        vp = self.solvers[e].iono_state_prior_dd(s, ref)
                        v = float(re.iono_float_var_m2[ks])
                        if not v < 0.8 * vp:
                            continue
                        y = float(re.iono_float_m[ks]) * vp / (vp - v)
                        var += v * vp / (vp - v)
                    else:
                        continue
                    if not np.isfinite(y):
                        continue
                    lam += np.outer(dxe, dxe) / var
                    vec += dxe * y / var
                    used += 1
                if not used:
                    continue
                cov = np.linalg.inv(lam)
                var = float(dxt @ cov @ dxt)
                # only where it says more than the baseline's own prior
                prior_dd = self.solvers[t].iono_level_ppm * 1e-6 * lt * meff
                if var < prior_dd**2:
                    out[s] = (ref, float(dxt @ cov @ vec), var)
            if out:
                hints[t] = out
        return hints

    def _model_predictions(self, results) -> dict[tuple[int, int], dict[str, tuple[str, float, float]]]:
        """Per baseline, the ionosphere model's DD ionosphere [m] and its variance [m^2] for the satellites high
        enough to be fixed and not fixed yet (against the baseline's reference). Used for the next epoch."""
        model = self.iono_model
        if model is None:
            return {}
        out = {}
        for e, r in results.items():
            if r is None:
                continue
            need = ~r.fixed & (r.eligible if r.eligible is not None else True)
            if not need.any():
                continue
            mean, var = model.predict(r, self._len[e])
            pos = {str(s): k for k, s in enumerate(r.sats)}
            hints = {}
            for k in np.flatnonzero(need & np.isfinite(mean)):
                s = str(r.sats[k])
                ref = r.refs.get(s[0])
                if ref in pos and ref != s:
                    hints[s] = (ref, float(mean[k]), float(var[k]))
            out[e] = hints
        return out

    def _network_refs(self, results) -> dict[str, str]:
        """Per system, the satellite fixed on the most baselines (ties: the first baseline's reference)."""
        votes: dict[str, dict[str, int]] = {}
        for r in results.values():
            if r is None:
                continue
            for k, s in enumerate(r.sats):
                if r.fixed[k]:
                    votes.setdefault(s[0], {}).setdefault(str(s), 0)
                    votes[s[0]][str(s)] += 1
        return {sys_: max(v.items(), key=lambda kv: (kv[1], kv[0]))[0] for sys_, v in votes.items()}

    @staticmethod
    def _rereferenced(r: BaselineEpoch | None, refs: dict[str, str], col: dict[str, int], n: int):
        """A baseline's DD residuals against the network's references, as (iono, trop) rows."""
        if r is None:
            return None
        iono = np.full(n, np.nan)
        trop = np.full(n, np.nan)
        pos = {str(s): k for k, s in enumerate(r.sats)}
        for system, ref in refs.items():
            kr = pos.get(ref)
            if kr is None or not r.fixed[kr]:
                continue
            for k, s in enumerate(r.sats):
                if s[0] != system or not r.fixed[k]:
                    continue
                iono[col[str(s)]] = r.dd_iono_m[k] - r.dd_iono_m[kr]
                trop[col[str(s)]] = r.dd_trop_m[k] - r.dd_trop_m[kr]
        return iono, trop

    def _check_closures(self, results) -> int:
        """Integer closure around each triangle; on a misclosure, the satellite's residuals are voided on the
        triangle's baselines for this epoch. Returns the number of misclosures."""
        bad = 0
        for i, j, k in self.triangles:
            rij, rjk, rik = results.get((i, j)), results.get((j, k)), results.get((i, k))
            if rij is None or rjk is None or rik is None:
                continue
            common = set(map(str, rij.sats)) & set(map(str, rjk.sats)) & set(map(str, rik.sats))
            for system in {s[0] for s in common}:
                ref_sets = {rij.refs.get(system), rjk.refs.get(system), rik.refs.get(system)}
                if len(ref_sets) != 1:
                    continue  # different references: checked once they agree
                for s in (x for x in common if x[0] == system):
                    vals = []
                    for r in (rij, rjk, rik):
                        q = int(np.flatnonzero(r.sats == s)[0])
                        vals.append((r.fixed[q], r.dd_n[q], r, q))
                    if not all(v[0] for v in vals):
                        continue
                    mis = vals[0][1] + vals[1][1] - vals[2][1]
                    if np.any(mis != 0):
                        bad += 1
                        for _, _, r, q in vals:
                            r.fixed[q] = False
                            r.dd_iono_m[q] = np.nan
                            r.dd_trop_m[q] = np.nan
        return bad



@dataclass(frozen=True)
class IonosphereModel:
    """The network's single-layer ionosphere model of the DD ionosphere: a vertical TEC `vtec_tecu` on a shell at
    `iono_shell_height_km`, which a satellite's DD ionosphere holds through the difference of the two stations'
    mapping functions (b minus a, satellite minus reference; a 50 km baseline across the satellite's azimuth
    changes its elevation by ~0.45 degree, at 15 degrees the mapping function by ~1 %: 0.5 TECU, 8 cm on L1, of
    17 TECU), plus a residual (the TEC's gradients between the pierce points) of `level_ppm` [ppm of the
    baseline length, vertical, mapped with hypot(M_s, M_ref) like the day's level]: the 95 % upper bound of the
    fit's residual RMS times `iono_prior_adapt`, never below `iono_model_floor_ppm`."""

    vtec_tecu: float
    vtec_var_tecu2: float
    level_ppm: float
    n: int  # fixed DD ionospheres it was fitted on
    shell_km: float

    def predict(self, r: BaselineEpoch, length_m: float) -> tuple[np.ndarray, np.ndarray]:
        """A baseline's DD ionosphere on f1 [m] and its variance [m^2] for each of its satellites against its
        reference (NaN where the system has no reference)."""
        d, m, mr = _mapping_terms(r, self.shell_km)
        tecu_m = IONO_K_M3_S2 / r.freq_hz[:, 0] ** 2  # metres of f1 delay per TECU
        mean = d * self.vtec_tecu * tecu_m
        spread = self.level_ppm * 1e-6 * length_m * np.hypot(m, mr)
        return mean, spread**2 + (d * tecu_m) ** 2 * self.vtec_var_tecu2


def _mapping_terms(r: BaselineEpoch, shell_km: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per satellite of a baseline epoch: the DD of the stations' mapping functions (b - a, satellite - its
    reference; NaN without a reference), and the mapping function at the lower station of the satellite and of
    its reference (the scale of the day's level)."""
    ma = thin_shell_mapping(np.radians(r.elevation_a_deg), 1e3 * shell_km)
    mb = thin_shell_mapping(np.radians(r.elevation_b_deg), 1e3 * shell_km)
    low = np.maximum(ma, mb)
    pos = {str(s): k for k, s in enumerate(r.sats)}
    kr = np.array([pos.get(r.refs.get(str(s)[0]), -1) for s in r.sats])
    has = kr >= 0
    kr = np.where(has, kr, 0)
    sd = mb - ma
    return np.where(has, sd - sd[kr], np.nan), low, np.where(has, low[kr], np.nan)


def ionosphere_model(results: dict, lengths: dict, cfg: BaselineConfig) -> IonosphereModel | None:
    """Fit the vertical TEC of the single-layer model over every baseline's fixed satellites by weighted least
    squares (each DD ionosphere weighted by the day level's scale, L * hypot(M_s, M_ref)); the residual's level
    in ppm. None without `iono_model_min_dd` fixed DD ionospheres, or when the model is off."""
    if cfg.iono_model_floor_ppm <= 0:
        return None
    shell = cfg.iono_shell_height_km or SHELL_HEIGHT_M / 1e3  # the filter's default where the config has none
    ys, ds, ss = [], [], []
    for e, r in results.items():
        if r is None:
            continue
        fixed = r.fixed & ~r.is_reference() & np.isfinite(r.dd_iono_m)
        if not fixed.any():
            continue
        d, m, mr = _mapping_terms(r, shell)
        tecu_m = IONO_K_M3_S2 / r.freq_hz[:, 0] ** 2
        scale = 1e-6 * lengths[e] * np.hypot(m, mr) / tecu_m  # TECU per ppm
        ok = fixed & np.isfinite(d)
        ys.append(r.dd_iono_m[ok] / tecu_m[ok])
        ds.append(d[ok])
        ss.append(scale[ok])
    if not ys:
        return None
    y, d, s = np.concatenate(ys), np.concatenate(ds), np.concatenate(ss)
    n = y.size
    if n < max(cfg.iono_model_min_dd, 2):
        return None
    a = d / s
    info = float(a @ a)
    if not info > 0:
        return None
    v = float(a @ (y / s)) / info
    rms = math.sqrt(float(np.sum((y / s - a * v) ** 2)) / (n - 1))
    level = max(cfg.iono_model_floor_ppm, cfg.iono_prior_adapt * rms * rms_upper_bound_factor(n - 1))
    return IonosphereModel(vtec_tecu=v, vtec_var_tecu2=level**2 / info, level_ppm=level, n=n, shell_km=shell)
