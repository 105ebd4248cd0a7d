"""Track identification through switches: a hidden-Markov filter over the candidate edges of a topology.

State: the edges the train may be on, each with a log posterior and the chainage the last fix
projected to.  Per epoch:

1. **Transition along the topology only**: every edge keeps its mass and hands it to the edges
   reachable from its last chainage within `MAX_SPEED_M_S * elapsed + ALONG_MARGIN_M`, both ways
   (`Topology.reachable`, which keeps toe <-> leg through a switch).  An edge not connected to one the
   train may be on never receives mass, whatever the fix says.
2. **History floor**: the propagated prior is mixed with a uniform share `HISTORY_FLOOR` over the
   candidates, so the past can add at most ~1/HISTORY_FLOOR to the odds (consecutive GNSS errors are
   correlated; an HMM that multiplied every epoch's likelihood as independent would overstate them).
3. **Likelihood** from the horizontal offset of the fix to each edge, normalised by the fix's sigma in
   the offset's direction; the sigma is widened to PL / K (decision 0250's cross-track protection level
   with its fault terms), so an undetected fault bias the PL covers widens the likelihood too.
4. **Decision with an integrity statement**: the posterior is summed per track; the best track is
   decided only when the posterior of every other track together is at most the allocated per-decision
   integrity risk (`DECISION_RISK`, decision 0250: 1e-9 /h x 0.5 / 3600 = 1.39e-13), else "unknown".
   A fix farther than its protection level from every candidate edge is inconsistent with the map and
   the topology: "unknown", and the fix is not used.

The identifier never reads the simulator's truth; `augnet.track.campaign` compares it with truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.onboard.integrity_allocation import DEFAULT_ALLOCATION, IntegrityAllocation
from augnet.track.topology import Step, Topology

# Highest line speed [m/s] a train may move between two fixes: 360 km/h (CTCS-3 lines run 350 km/h).
MAX_SPEED_M_S = 100.0
# Along-track slack [m] added to the reach, for the fix's along-track error at both epochs.
ALONG_MARGIN_M = 5.0
# Uniform share mixed into the prior each epoch: bounds the history's contribution to the odds at
# ~1e3 (design choice, decision 0290; no measured error correlation time of the moving antenna yet).
HISTORY_FLOOR = 1e-3
# A candidate whose posterior falls below this is dropped; far below DECISION_RISK, so pruning cannot
# move a decision across its threshold.
PRUNE_POSTERIOR = 1e-20
# Edges within this radius [m] of the first fix are the candidates of a cold start (trackmap.py's
# candidate radius: parallel tracks are 4.5-5 m apart).
COLD_START_RADIUS_M = 25.0
# A map's verified accuracy (Topology.accuracy, augnet.track.survey_map.verify) is the 95 % of a one-sided
# perpendicular distance: sigma = figure / 1.96 (Gaussian), added to every fix's variance across the edge.
MAP_ACCURACY_95_SIGMAS = 1.96
# Sigma floor [m]: no fix is better than the map's own centimetre (GEOMETRY_GAP_TOLERANCE is 0.5 m;
# a survey-grade centre line ~1 cm).
MIN_SIGMA_M = 0.01

Transitions = Callable[[Topology, str, float, float], set[str]]


def topology_transitions(topology: Topology, edge: str, km: float, distance_m: float) -> set[str]:
    """Edges a train at `km` on `edge` may be on after moving at most `distance_m` either way."""
    out = {edge}
    for direction in ("up", "down"):
        out.update(s.edge for s in topology.reachable(Step(edge, direction), distance_m, from_km=km))
    return out


@dataclass(frozen=True)
class TrackFix:
    """The identifier's measurement: an ECEF position and its horizontal covariance (east, north)
    with sigma already widened to the protection level's reach."""

    time_s: float
    position_ecef_m: np.ndarray
    cov_en_m2: np.ndarray  # (2, 2) east/north
    rotation: np.ndarray = field(repr=False)  # (3, 3) ECEF -> ENU at the position


def fix_from_position(time_s: float, position_ecef_m, covariance_ecef_m2,
                      allocation: IntegrityAllocation = DEFAULT_ALLOCATION) -> TrackFix:
    """A fix from an ECEF position and its 3x3 ECEF covariance; sigma widened so K sigma = cross PL."""
    p = np.asarray(position_ecef_m, dtype=float).reshape(-1)
    c = np.asarray(covariance_ecef_m2, dtype=float)
    if p.shape != (3,) or c.shape != (3, 3) or not (np.all(np.isfinite(p)) and np.all(np.isfinite(c))):
        raise ValueError("a track fix needs a finite (3,) ECEF position and a finite (3, 3) covariance")
    if not math.isfinite(time_s):
        raise ValueError("a track fix needs a finite time")
    llh = ecef_to_geodetic(p)
    r = enu_rotation(llh[0], llh[1])
    cen = (r @ c @ r.T)[:2, :2]
    cen = 0.5 * (cen + cen.T)
    sigma = max(math.sqrt(max(float(np.linalg.eigvalsh(cen)[-1]), 0.0)), MIN_SIGMA_M)
    # widen by PL / (K sigma): the fault terms of decision 0250 enter the likelihood's width
    scale = allocation.protection_level(sigma, "cross") / (allocation.k_fault_free * sigma)
    cen = cen * max(scale, 1.0) ** 2 + np.eye(2) * MIN_SIGMA_M ** 2
    return TrackFix(float(time_s), p, cen, r)


def fix_from_solution(solution, allocation: IntegrityAllocation = DEFAULT_ALLOCATION) -> TrackFix | None:
    """The identifier's measurement from an onboard solution (`RtkSolution` or anything with `time`,
    `position_m`, `covariance_m2`); None when the solution has no finite position."""
    p = np.asarray(solution.position_m, dtype=float)
    c = np.asarray(solution.covariance_m2, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)) or c.shape != (3, 3) or not np.all(np.isfinite(c)):
        return None
    return fix_from_position(float(solution.time), p, c, allocation)


@dataclass(frozen=True)
class TrackDecision:
    time_s: float
    status: str  # "decided", "unknown" (ambiguous), "inconsistent" (fix beyond PL of every candidate), "no fix"
    track: str | None  # the decided track, None unless decided
    edge: str | None  # the most probable edge of the decided track
    best_track: str | None  # the most probable track, decided or not
    other_mass: float  # posterior of every track but the best one (the decision's risk)
    tracks: dict[str, float]  # posterior per candidate track


@dataclass
class _Candidate:
    log_p: float
    km: float


class TrackIdentifier:
    """Hidden-Markov track identification over a topology; feed `update(fix)` once per epoch."""

    def __init__(self, topology: Topology, allocation: IntegrityAllocation = DEFAULT_ALLOCATION,
                 transitions: Transitions = topology_transitions, decision_risk: float | None = None):
        self.topology = topology
        self.allocation = allocation
        self.decision_risk = allocation.per_decision_risk if decision_risk is None else float(decision_risk)
        if not 0.0 < self.decision_risk < 0.5:
            raise ValueError("decision risk must be in (0, 0.5)")
        # gate on the normalised offset: a fix beyond its PL from every candidate is inconsistent
        self.gate_sigma = allocation.k_fault_free
        self.transitions = transitions
        # the map's own error widens every likelihood (a survey-built map carries its figure; else 0)
        acc = (topology.accuracy or {}).get("horizontal_95_m")
        self.map_sigma_m = float(acc) / MAP_ACCURACY_95_SIGMAS if acc is not None and math.isfinite(acc) else 0.0
        self._cands: dict[str, _Candidate] = {}
        self._last_time: float | None = None

    @property
    def candidates(self) -> dict[str, float]:
        """Posterior per candidate edge."""
        return {e: math.exp(c.log_p) for e, c in self._cands.items()}

    def reset(self) -> None:
        """Forget the track (a cold start at the next fix): e.g. after a balise or a dispatcher reset."""
        self._cands.clear()
        self._last_time = None

    def start(self, edge: str, km: float, time_s: float) -> None:
        """Start on a known edge (the train's entry data or a balise), instead of a cold start."""
        self.topology.along_m(edge, km)  # validates edge and km
        self._cands = {edge: _Candidate(0.0, float(km))}
        self._last_time = float(time_s)

    def update(self, fix: TrackFix | None, time_s: float | None = None) -> TrackDecision:
        if fix is None:
            t = math.nan if time_s is None else float(time_s)
            return TrackDecision(t, "no fix", None, None, None, 1.0, {})
        if self._last_time is not None and fix.time_s < self._last_time:
            raise ValueError(f"fix at {fix.time_s} s is older than the last one ({self._last_time} s)")
        if not self._cands:
            near = self.topology.nearest_edges(fix.position_ecef_m, COLD_START_RADIUS_M)
            if not near:
                return TrackDecision(fix.time_s, "inconsistent", None, None, None, 1.0, {})
            prior = {h.edge: -math.log(len(near)) for h in near}
            kms = {h.edge: h.km for h in near}
        else:
            elapsed = fix.time_s - self._last_time
            reach = MAX_SPEED_M_S * elapsed + ALONG_MARGIN_M
            acc: dict[str, list[float]] = {}
            for e, c in self._cands.items():
                for s in self.transitions(self.topology, e, c.km, reach):
                    acc.setdefault(s, []).append(c.log_p)
            n = len(acc)
            prior = {}
            for s, lps in acc.items():
                lp = _logsumexp(np.array(lps))
                prior[s] = float(np.logaddexp(math.log1p(-HISTORY_FLOOR) + lp, math.log(HISTORY_FLOOR / n)))
            kms = {}
        # likelihood of each candidate edge: horizontal offset of the fix, Mahalanobis along the offset
        loglik, d_norm = {}, {}
        for e in prior:
            npnt = self.topology.nearest_point(e, fix.position_ecef_m)
            kms[e] = npnt.km
            o = (fix.rotation @ (fix.position_ecef_m - npnt.point_ecef_m))[:2]
            dist = float(np.hypot(o[0], o[1]))
            if dist > 0.0:
                u = o / dist
                var = float(u @ fix.cov_en_m2 @ u) + self.map_sigma_m ** 2
                d2 = dist * dist / var
            else:
                d2 = 0.0
            d_norm[e] = math.sqrt(d2)
            loglik[e] = -0.5 * d2  # the normalising constant is the same for every edge
        if min(d_norm.values()) > self.gate_sigma:
            # inconsistent with every edge the train may be on: keep the state, decide nothing
            if not self._cands:
                return TrackDecision(fix.time_s, "inconsistent", None, None, None, 1.0, {})
            return TrackDecision(fix.time_s, "inconsistent", None, None, None, 1.0, self._track_posterior())
        edges = list(prior)
        lp = np.array([prior[e] + loglik[e] for e in edges])
        lp -= _logsumexp(lp)
        keep = lp >= math.log(PRUNE_POSTERIOR)
        lp = lp[keep]
        edges = [e for e, k in zip(edges, keep) if k]
        lp -= _logsumexp(lp)
        self._cands = {e: _Candidate(float(v), kms[e]) for e, v in zip(edges, lp)}
        self._last_time = fix.time_s
        return self._decide(fix.time_s)

    # ------------------------------------------------------------------------------------------

    def _track_posterior(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for e, c in self._cands.items():
            t = self.topology.edges[e].track
            out[t] = out.get(t, 0.0) + math.exp(c.log_p)
        return out

    def _decide(self, time_s: float) -> TrackDecision:
        tracks = self._track_posterior()
        best = max(tracks, key=tracks.get)
        # the risk is the other tracks' mass summed directly (1 - p loses it below 1e-16)
        other = sum(p for t, p in tracks.items() if t != best)
        edge = max((e for e in self._cands if self.topology.edges[e].track == best),
                   key=lambda e: self._cands[e].log_p)
        if other <= self.decision_risk:
            return TrackDecision(time_s, "decided", best, edge, best, other, tracks)
        return TrackDecision(time_s, "unknown", None, None, best, other, tracks)


def _logsumexp(a: np.ndarray) -> float:
    m = float(np.max(a))
    if not math.isfinite(m):
        return m
    return m + math.log(float(np.sum(np.exp(a - m))))


__all__ = ["TrackIdentifier", "TrackFix", "TrackDecision", "fix_from_solution", "fix_from_position",
           "topology_transitions"]
