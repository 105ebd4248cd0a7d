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
from augnet.centre.satellite_geometry import GeometryRequest, SatelliteGeometry, station_geometries
from augnet.gnss.antex import ReceiverAntenna
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import ecef_to_enu

NEIGHBOURS_PER_STATION = 2
# A station this close to another is the same place twice (a typo or a duplicate entry): a baseline of a few
# metres has no ionosphere or troposphere to resolve and both stations would be one to the interpolation.
MIN_STATION_SEPARATION_M = 1.0
# ECEF radius of a place a reference station may stand: from the Dead Sea shore (WGS84 polar radius 6,356.8 km
# less 1 km) to far above the highest summit (equatorial radius 6,378.1 km plus 10 km).
MIN_STATION_RADIUS_M = 6_355_000.0
MAX_STATION_RADIUS_M = 6_389_000.0
MEMBERSHIP_KIND = "station-left"  # alarm kind: a station left the network (raised) / joined it again (cleared)


@dataclass(frozen=True)
class MembershipChange:
    """What one add / remove / move did to the network (for the log, the alarm and the tests)."""

    station: str
    action: str  # "add" | "remove" | "move"
    added: tuple[str, ...]  # baselines created (their ambiguities start afresh)
    dropped: tuple[str, ...]  # baselines removed with their state
    master_before: str | None
    master_after: str | None


def station_position_problem(name: str, xyz, others: dict[str, np.ndarray]) -> str | None:
    """Why `name` cannot stand at `xyz` (ECEF [m]) beside the stations `others` (name -> ECEF), or None."""
    p = np.asarray(xyz, dtype=float).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        return f"station {name}: position must be 3 finite ECEF coordinates [m]"
    r = float(np.linalg.norm(p))
    if not MIN_STATION_RADIUS_M <= r <= MAX_STATION_RADIUS_M:
        return (f"station {name}: position {r / 1000:.1f} km from the Earth's centre is not on the Earth's "
                f"surface ({MIN_STATION_RADIUS_M / 1000:.0f}..{MAX_STATION_RADIUS_M / 1000:.0f} km)")
    if others:
        names = list(others)
        d = np.linalg.norm(np.asarray([others[n] for n in names], float).reshape(-1, 3) - p, axis=1)
        k = int(np.argmin(d))
        if d[k] < MIN_STATION_SEPARATION_M:
            return f"station {name}: {d[k]:.2f} m from station {names[k]} (the same place twice)"
    return None


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
    # stations left out of VRS synthesis (no master, no interpolation node): published coordinates flagged by the
    # coordinate monitor (coordinate_monitor.py); set by the centre engine
    vrs_excluded: set[str] = field(default_factory=set)
    # per modelled station: (sats (S,), (S, 2) phase-centre correction e . PCO - PCV [m]) of this epoch
    antenna_m: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    # (n, S, 2) DD integers [cycles] of station minus master, satellite minus the system's reference in `refs`,
    # chained like the residuals (NaN where not fixed along the path): a VRS changing its master keeps its
    # phase continuous with them (vrs_handover.py); None when not computed
    dd_n: np.ndarray | None = None

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

    # --- membership: stations join and leave a running network --------------------------------------------

    def station_problem(self, name: str, xyz) -> str | None:
        """Why `name` at `xyz` (ECEF [m]) cannot join the network, or None."""
        if not isinstance(name, str) or not name.strip():
            return "a station needs a non-empty name"
        if name in self.clocks:
            return f"station {name} is already in the network"
        return self._position_problem(name, xyz)

    def _position_problem(self, name: str, xyz, ignore: str | None = None) -> str | None:
        others = {n: self.xyz[k] for k, n in enumerate(self.names) if n != ignore}
        return station_position_problem(name, xyz, others)

    def add_station(self, name: str, xyz, antenna: ReceiverAntenna | None = None) -> MembershipChange:
        """`name` joins from the next epoch: baselines to it by the network's rule (`choose_baselines` over every
        station: the new station's edges among them); every existing baseline keeps its solver, so its fixed
        ambiguities. ValueError (saying why) for a duplicate or a position off the Earth."""
        problem = self.station_problem(name, xyz)
        if problem is not None:
            raise ValueError(problem)
        if antenna is not None:
            self.antennas[name] = antenna
        names = self.names + [name]
        xyz_all = np.vstack([self.xyz.reshape(-1, 3), np.asarray(xyz, float).reshape(1, 3)])
        new = len(names) - 1
        edges = [e for e in choose_baselines(names, xyz_all) if new in e] if len(names) > 1 else []
        pairs = self._pairs()
        added = [(names[i], names[j]) for i, j in edges]
        before = self.master
        self._relink(names, xyz_all, pairs, added, self.master if len(self.names) else None)
        self.clocks[name] = 0.0
        self.integrity.add_station(name)
        return MembershipChange(name, "add", tuple(f"{a}-{b}" for a, b in added), (), before, self.master)

    def remove_station(self, name: str) -> MembershipChange:
        """`name` leaves from the next epoch: its baselines and their state are dropped; if that splits the network,
        the shortest baselines of `choose_baselines` over the rest that join the parts are added; a master that
        leaves is replaced by the central station of the rest. ValueError for a station not in the network or
        the last one (a network of none serves nobody: disable its data instead)."""
        if name not in self.clocks:
            raise ValueError(f"station {name} is not in the network")
        if len(self.names) == 1:
            raise ValueError(f"station {name} is the network's last station: it cannot leave")
        k = self.names.index(name)
        names = [n for n in self.names if n != name]
        xyz = np.delete(self.xyz, k, axis=0)
        pairs = {p: s for p, s in self._pairs().items() if name not in p}
        dropped = tuple(s.name for p, s in self._pairs().items() if name in p)
        added = self._reconnect(names, xyz, list(pairs))
        before = self.master
        self._relink(names, xyz, pairs, added, None if self.master == name else self.master)
        self.clocks.pop(name, None)
        self.antennas.pop(name, None)
        self.integrity.remove_station(name)
        return MembershipChange(name, "remove", tuple(f"{a}-{b}" for a, b in added), dropped, before, self.master)

    def move_station(self, name: str, xyz) -> MembershipChange:
        """New coordinates for `name`: leave and join (its baselines restart from the new position: a network
        fixed on wrong coordinates poisons every correction); the other baselines are kept."""
        if name not in self.clocks:
            raise ValueError(f"station {name} is not in the network")
        problem = self._position_problem(name, xyz, ignore=name)
        if problem is not None:
            raise ValueError(problem)
        if len(self.names) == 1:
            self._relink([name], np.asarray(xyz, float).reshape(1, 3), {}, [], name)
            self.integrity.remove_station(name)
            self.integrity.add_station(name)
            return MembershipChange(name, "move", (), (), name, name)
        antenna = self.antennas.get(name)
        left = self.remove_station(name)
        joined = self.add_station(name, xyz, antenna)
        return MembershipChange(name, "move", joined.added, left.dropped, left.master_before, joined.master_after)

    def _pairs(self) -> dict[tuple[str, str], BaselineSolver]:
        return {(self.names[i], self.names[j]): s for (i, j), s in self.solvers.items()}

    @staticmethod
    def _reconnect(names: list[str], xyz: np.ndarray, pairs: list[tuple[str, str]]) -> list[tuple[str, str]]:
        """Baselines of `choose_baselines` over `names`, shortest first, that join the parts `pairs` leave apart."""
        parent = {n: n for n in names}

        def root(n):
            while parent[n] != n:
                parent[n] = parent[parent[n]]
                n = parent[n]
            return n

        for a, b in pairs:
            parent[root(a)] = root(b)
        if len({root(n) for n in names}) <= 1:
            return []
        cand = choose_baselines(names, xyz)
        cand.sort(key=lambda e: float(np.linalg.norm(xyz[e[0]] - xyz[e[1]])))
        out = []
        for i, j in cand:
            ra, rb = root(names[i]), root(names[j])
            if ra != rb:
                parent[ra] = rb
                out.append((names[i], names[j]))
        return out

    def _relink(self, names: list[str], xyz: np.ndarray, pairs: dict[tuple[str, str], BaselineSolver],
                added: list[tuple[str, str]], master: str | None) -> None:
        """Index everything again over `names` (in their order): the kept solvers under their new indices, new
        ones for `added`, the triangles, the master's east/north frame, the hint geometry; last epoch's hints
        follow their baselines."""
        old = {e: (self.names[e[0]], self.names[e[1]]) for e in self.solvers}
        hints = {old[e]: h for e, h in self._hints.items() if e in old}
        model_hints = {old[e]: h for e, h in self._model_hints.items() if e in old}
        self.names = list(names)
        self.xyz = np.asarray(xyz, float).reshape(-1, 3)
        pos = {n: i for i, n in enumerate(self.names)}
        solvers = {}
        for (a, b), s in pairs.items():
            solvers[(pos[a], pos[b])] = s
        for a, b in added:
            i, j = sorted((pos[a], pos[b]))
            solvers[(i, j)] = BaselineSolver(self.names[i], self.xyz[i], self.names[j], self.xyz[j], self.cfg,
                                             self.antennas.get(self.names[i]), self.antennas.get(self.names[j]))
        self.solvers = dict(sorted(solvers.items()))
        self.edges = sorted(self.solvers)
        self.triangles = triangles(self.edges)
        self.master = master if master in pos else self._central_station()
        m = pos[self.master]
        self.order = [m] + [i for i in range(len(self.names)) if i != m]
        self.en = ecef_to_enu(self.xyz - self.xyz[m], self.xyz[m])[:, :2]
        self.ionosphere_hints = IonosphereHints(self.edges, self.en, self.cfg)
        back = {(self.names[i], self.names[j]): (i, j) for i, j in self.edges}
        self._hints = {back[p]: h for p, h in hints.items() if p in back}
        self._model_hints = {back[p]: h for p, h in model_hints.items() if p in back}

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
        iono, trop, dd_n = self._chain_to_master(results, refs, sats)
        rows = self.order
        return NetworkEpoch(
            t_gpst=t, master=self.master, stations=[self.names[i] for i in rows], station_en_m=self.en[rows],
            station_xyz_m=self.xyz[rows], refs=refs, sats=sats, dd_iono_m=iono[rows], dd_trop_m=trop[rows],
            baselines={self.solvers[e].name: r for e, r in results.items()}, misclosures=misclosures,
            present=sorted(present), clocks=dict(self.clocks), excluded=set(excluded),
            alarms=self.integrity.drain(),
            antenna_m={n: (g.sats, g.antenna_m) for n, g in geom.items() if g.antenna_m is not None},
            dd_n=dd_n[rows])

    def _geometry(self, epochs, present, nav) -> dict[str, SatelliteGeometry]:
        """Each present station's satellite geometry, computed once for all its baselines; the receiver clocks are
        kept as the next epoch's starting guess."""
        pos = {n: i for i, n in enumerate(self.names)}
        names = list(present)
        requests = [GeometryRequest(epochs[n].sats, epochs[n].t_gpst, self.xyz[pos[n]], epochs[n].code_m[:, 0],
                                    self.clocks[n], self.antennas.get(n), epochs[n].codes) for n in names]
        geom = dict(zip(names, station_geometries(requests, nav)))  # every station's satellites in one evaluation
        for n in names:
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

    def _chain_to_master(self, results, refs, sats) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(n, S) DD ionosphere and non-dispersive residuals of every station (in `self.names` order) against the
        master, chained over baselines: per satellite, along the shortest path (in metres) on which that satellite
        is fixed on every baseline. Edges are relaxed in order of length, so a short path wins over a long one; a
        satellite missing on one baseline reaches the station over another. Third: the (n, S, 2) DD integers
        chained along the same paths."""
        n = len(self.names)
        iono = np.full((n, len(sats)), np.nan)
        trop = np.full((n, len(sats)), np.nan)
        ints = np.full((n, len(sats), 2), np.nan)
        col = {s: k for k, s in enumerate(sats)}
        per_edge = {e: self._rereferenced(r, refs, col, len(sats)) for e, r in results.items()}
        m = self.order[0]
        iono[m] = 0.0
        trop[m] = 0.0
        ints[m] = 0.0
        edges = sorted((self.solvers[e].length_m, e) for e, v in per_edge.items() if v is not None)
        dist = np.full((n, len(sats)), np.inf)
        dist[m] = 0.0
        for _ in range(n):
            changed = False
            for length, (a, b) in edges:
                vi, vt, vn = per_edge[(a, b)]
                ok = np.isfinite(vi) & np.isfinite(vt)
                for src, dst, sign in ((a, b, 1.0), (b, a, -1.0)):  # residuals are b minus a
                    better = ok & np.isfinite(dist[src]) & (dist[src] + length < dist[dst])
                    if better.any():
                        iono[dst, better] = iono[src, better] + sign * vi[better]
                        trop[dst, better] = trop[src, better] + sign * vt[better]
                        ints[dst, better] = ints[src, better] + sign * vn[better]
                        dist[dst, better] = dist[src, better] + length
                        changed = True
            if not changed:
                break
        return iono, trop, ints

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
        """A baseline's DD residuals against the network's references, as (iono, trop, (n, 2) integers) rows."""
        if r is None:
            return None
        iono = np.full(n, np.nan)
        trop = np.full(n, np.nan)
        ints = np.full((n, 2), np.nan)
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
                ints[col[str(s)]] = r.dd_n[k] - r.dd_n[kr]
        return iono, trop, ints

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
