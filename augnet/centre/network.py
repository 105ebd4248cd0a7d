"""The reference-station network: baselines, closure checks, and DD residuals relative to a master.

Baselines join each station to its nearest neighbours (plus a minimum spanning tree, so the network is
connected). Each baseline resolves its own ambiguities (`baseline.py`); the network then

- checks closure around every triangle of baselines (the DD integers of a-b, b-c and a-c must add up, per
  satellite and frequency; a misclosure means one of them is wrong, and the satellite is dropped on the
  triangle's baselines for that epoch);
- chains baseline residuals along the shortest path from the master station to every station, after
  re-referencing them to one reference satellite per system, giving DD residuals (dispersive and
  non-dispersive) of every station against the master: the input of the interpolation;
- pools the ionosphere's rate and the day's level over every baseline (`ionosphere_prior.py`);
- models each station's receiver antenna where its ANTEX calibration is given (`antennas`): the phase-centre
  corrections enter the single differences, so the DD residuals refer to the antenna reference points, and
  `NetworkEpoch.antenna_m` carries them to the VRS (which takes them out of its master's observations);
- hands each baseline, for the next epoch, ionosphere hints for the satellites it has not fixed
  (`ionosphere_hints.py`) and the prediction of the single-layer ionosphere model fitted over every baseline's
  fixed satellites (`ionosphere_model.py`): the prior of their integer decision.
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.baseline import BaselineEpoch, BaselineSolver
from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.ionosphere_hints import IonosphereHints
from augnet.centre.ionosphere_model import IonosphereModel, ionosphere_model, model_predictions
from augnet.centre.ionosphere_prior import share_network_ionosphere
from augnet.centre.integrity import Alarm, IntegrityMonitor
from augnet.centre.observations import StationEpoch
from augnet.centre.satellite_geometry import SatelliteGeometry, satellite_geometry
from augnet.gnss.antex import ReceiverAntenna
from augnet.gnss.ephemeris import NavigationData
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
    # per modelled station: (sats (S,), (S, 2) phase-centre correction e . PCO - PCV [m]) of this epoch
    antenna_m: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    def antenna_correction(self, ep: StationEpoch) -> np.ndarray | None:
        """(S, 2) phase-centre correction of a station epoch's satellites (NaN for any this epoch did not see:
        a VRS leaves them out rather than carry the station's antenna); None when its antenna is not modelled."""
        got = self.antenna_m.get(ep.station)
        if got is None:
            return None
        sats, corr = got
        pos = {str(s): k for k, s in enumerate(sats)}
        idx = np.array([pos.get(str(s), -1) for s in ep.sats], dtype=int)
        if not len(idx) or not len(sats):
            return np.full((len(idx), 2), np.nan)
        return np.where((idx >= 0)[:, None], corr[np.maximum(idx, 0)], np.nan)

    def fixed_fraction(self) -> dict[str, float]:
        return {k: (b.fixed_fraction if b is not None else 0.0) for k, b in self.baselines.items()}


class NetworkSolver:
    """The network engine: every baseline's solver, their closures, the ionosphere they share, and the DD
    residuals of every station against the master."""

    def __init__(self, stations: dict[str, np.ndarray], master: str | None = None,
                 config: BaselineConfig | None = None, edges: list[tuple[str, str]] | None = None,
                 antennas: dict[str, ReceiverAntenna] | None = None):
        """`antennas`: the receiver antenna calibration of each station to model (`augnet.gnss.antex`); stations
        without one keep their phase centre at the ARP (no correction)."""
        self.names = list(stations)
        self.antennas = dict(antennas or {})
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
        self.solvers = {(i, j): BaselineSolver(self.names[i], self.xyz[i], self.names[j], self.xyz[j], self.cfg,
                                               self.antennas.get(self.names[i]), self.antennas.get(self.names[j]))
                        for i, j in idx_edges}
        m = self.names.index(self.master)
        self.order = [m] + [i for i in range(len(self.names)) if i != m]
        self.en = ecef_to_enu(self.xyz - self.xyz[m], self.xyz[m])[:, :2]
        self.ionosphere_hints = IonosphereHints(idx_edges, self.en, self.cfg)
        self._hints: dict[tuple[int, int], dict] = {}
        self._model_hints: dict[tuple[int, int], dict] = {}
        self.iono_model: IonosphereModel | None = None
        self.clocks = {n: 0.0 for n in self.names}
        self.integrity = IntegrityMonitor(self.names)

    def set_antenna(self, name: str, antenna: ReceiverAntenna | None) -> None:
        """Model (or stop modelling, None) a station's antenna from the next epoch on (a live station's RTCM 1033
        descriptor may arrive after its first epochs: its residuals step by the correction, millimetres to
        centimetres, which a fixed satellite's release check may take for a slip)."""
        if antenna is None:
            self.antennas.pop(name, None)
        else:
            self.antennas[name] = antenna
        for solver in self.solvers.values():
            if solver.name_a == name:
                solver.antenna["a"] = antenna
            if solver.name_b == name:
                solver.antenna["b"] = antenna

    def _central_station(self) -> str:
        c = self.xyz.mean(axis=0)
        return self.names[int(np.argmin(np.linalg.norm(self.xyz - c, axis=1)))]

    def update(self, epochs: dict[str, StationEpoch], nav: NavigationData) -> NetworkEpoch:
        """One epoch of every station (None or absent: no data)."""
        present = {n for n, e in epochs.items() if e is not None and len(e.sats) and n in self.clocks}
        t = next(iter(epochs[n].t_gpst for n in present)) if present else float("nan")
        geom = self._geometry(epochs, present, nav)
        excluded = self.integrity.observe(t, {n: epochs[n] for n in present}, geom) if present else set()
        results = self._solve_baselines(epochs, present, nav, geom, excluded)
        misclosures = self._check_closures(results)
        self._share_ionosphere(results)
        refs = self._network_refs(results)
        sats = np.array(sorted({str(s) for r in results.values() if r is not None for s in r.sats}))
        iono, trop = self._chain_to_master(results, refs, sats)
        rows = self.order
        return NetworkEpoch(
            t_gpst=t, master=self.master, stations=[self.names[i] for i in rows], station_en_m=self.en[rows],
            station_xyz_m=self.xyz[rows], refs=refs, sats=sats, dd_iono_m=iono[rows], dd_trop_m=trop[rows],
            baselines={self.solvers[e].name: r for e, r in results.items()}, misclosures=misclosures,
            present=sorted(present), clocks=dict(self.clocks), excluded=set(excluded),
            alarms=self.integrity.drain(),
            antenna_m={n: (g.sats, g.antenna_m) for n, g in geom.items() if g.antenna_m is not None})

    def _geometry(self, epochs, present, nav) -> dict[str, SatelliteGeometry]:
        """Each present station's satellite geometry, computed once for all its baselines; the receiver clocks are
        kept as the next epoch's starting guess."""
        geom: dict[str, SatelliteGeometry] = {}
        pos = {n: i for i, n in enumerate(self.names)}
        for n in present:
            ep = epochs[n]
            geom[n] = satellite_geometry(ep.sats, ep.t_gpst, self.xyz[pos[n]], nav, ep.code_m[:, 0], self.clocks[n],
                                         self.antennas.get(n), ep.codes)
            self.clocks[n] = geom[n].clock_s
        return geom

    def _solve_baselines(self, epochs, present, nav, geom, excluded) -> dict[tuple[int, int], BaselineEpoch | None]:
        """Each baseline whose two stations have data, with the hints and model predictions of the last epoch."""
        results: dict[tuple[int, int], BaselineEpoch | None] = {}
        for (i, j), solver in self.solvers.items():
            a, b = self.names[i], self.names[j]
            if a in present and b in present:
                results[(i, j)] = solver.update(epochs[a], epochs[b], nav, geom[a], geom[b], excluded,
                                                self._hints.get((i, j)), self._model_hints.get((i, j)))
            else:
                results[(i, j)] = None
        return results

    def _share_ionosphere(self, results) -> None:
        """The rate and day's level pooled over the baselines, and, for the next epoch, the hints and the
        single-layer model's predictions."""
        priors = {e: solver.ionosphere for e, solver in self.solvers.items()}
        share_network_ionosphere(list(priors.values()), self.cfg)
        self._hints = self.ionosphere_hints.predict(results, priors)
        self.iono_model = ionosphere_model(results, self.ionosphere_hints.length, self.cfg)
        self._model_hints = model_predictions(self.iono_model, results, self.ionosphere_hints.length)

    def _chain_to_master(self, results, refs, sats) -> tuple[np.ndarray, np.ndarray]:
        """(n, S) DD ionosphere and non-dispersive residuals of every station (in `self.names` order) against the
        master, chained over baselines: per satellite, along the shortest path (in metres) on which that satellite
        is fixed on every baseline. Edges are relaxed in order of length, so a short path wins over a long one; a
        satellite missing on one baseline reaches the station over another."""
        n = len(self.names)
        iono = np.full((n, len(sats)), np.nan)
        trop = np.full((n, len(sats)), np.nan)
        col = {s: k for k, s in enumerate(sats)}
        per_edge = {e: self._rereferenced(r, refs, col, len(sats)) for e, r in results.items()}
        m = self.order[0]
        iono[m] = 0.0
        trop[m] = 0.0
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
        return iono, trop

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
