"""Track identification campaign: seeded train runs through the switches of a topology, with a
simulated onboard solution error model, scored against the runs' truth.

Not the full GNSS chain (that runs minutes per scenario): the onboard solution is simulated as a
fixed/float/none Markov mixture with time-correlated errors whose covariance the solution reports
honestly (the error's stationary covariance equals the reported one).  Rates and sigmas below are
stated assumptions in the range of the project's RTK runs (docs/measured.md: fixed H95 ~1-2 cm; float
20-30 cm), not a calibration.

Truth stays here: the identifier (`augnet.track.identification`) sees only the simulated fixes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.track.identification import TrackIdentifier, fix_from_position
from augnet.track.topology import Step, Topology, TopologyError

EPOCH_S = 1.0  # onboard PVT rate [s] (1 Hz, integrity_allocation.DEFAULT_EPOCH_INTERVAL_S)
# Solution state chain per epoch (assumed): mean fixed run 100 s, mean float run 20 s (-> ~83 % fixed),
# an outage (no solution) every ~500 s lasting ~5 s, re-acquired as float.
P_FIXED_TO_FLOAT = 0.01
P_FLOAT_TO_FIXED = 0.05
P_TO_NONE = 0.002
P_NONE_TO_FLOAT = 0.2
# Horizontal 1-sigma per axis [m]: fixed 1.5 cm (H95 ~3.5 cm); float drawn per float spell in 0.15-0.5 m.
SIGMA_FIXED_M = 0.015
SIGMA_FLOAT_RANGE_M = (0.15, 0.5)
SIGMA_UP_FACTOR = 2.0  # vertical sigma / horizontal sigma (GNSS geometry, typical VDOP/HDOP)
# Error correlation times [s] (assumed: multipath and residual atmosphere on a moving antenna).
TAU_FIXED_S = 20.0
TAU_FLOAT_S = 30.0
# Stress (off by default): share of fixed spells that are wrong fixes carrying a cross-track bias.
WRONG_FIX_FRACTION = 0.2
# Train speed [m/s] drawn per run (36-108 km/h: station and crossover speeds).
SPEED_RANGE_M_S = (10.0, 30.0)
# A run starts and ends this far [m] from the route's end nodes.
END_CLEARANCE_M = 200.0
# Probability of taking the diverging leg at a facing switch, when a route is drawn at random.
P_DIVERGING = 0.5
# Default campaign seeds (4 route starts on the test line x 4 leg patterns).
DEFAULT_SEEDS = tuple(range(16))


@dataclass(frozen=True)
class RoutePlan:
    steps: tuple[Step, ...]
    lengths_m: tuple[float, ...]

    @property
    def length_m(self) -> float:
        return float(sum(self.lengths_m))


def plan_route(topology: Topology, start: Step, rng: np.random.Generator | None = None,
               pattern: int | None = None, p_diverging: float = P_DIVERGING, max_steps: int = 1000) -> RoutePlan:
    """Walk from `start` (entered at its far end) to a buffer stop or open end; at the j-th facing
    switch take the diverging leg when bit j of `pattern` is set, or (no pattern) at random with
    `p_diverging`.  Every step follows `Topology.next_steps`."""
    if pattern is None and rng is None:
        raise ValueError("plan_route needs a pattern or a random generator")
    steps = [start]
    facing = 0
    for _ in range(max_steps):
        nxt = topology.next_steps(steps[-1])
        if not nxt:
            break
        if len(nxt) > 1:
            t = topology.turnouts[topology.node_ahead(steps[-1])]
            div = [s for s in nxt if s.edge == t.diverging]
            straight = [s for s in nxt if s.edge != t.diverging]
            take = (pattern >> facing) & 1 if pattern is not None else rng.random() < p_diverging
            nxt = div if take else straight
            facing += 1
        steps.append(nxt[0])
    else:
        raise TopologyError("route", f"no end within {max_steps} steps from {start.edge}")
    topology.check_route(steps)
    return RoutePlan(tuple(steps), tuple(topology.length_m(s.edge) for s in steps))


def route_starts(topology: Topology) -> list[Step]:
    """Steps leaving every buffer stop and open end of the line, into the line."""
    out = []
    for n in topology.nodes.values():
        if n.kind in ("buffer_stop", "open_end"):
            (eid, side), = topology.edges_at(n.id)
            out.append(Step(eid, "up" if side == "begin" else "down"))
    return sorted(out, key=lambda s: (s.edge, s.direction))


def _locate(topology: Topology, plan: RoutePlan, s_m: float) -> tuple[int, float]:
    """(step index, arc length on the step's edge from its begin) at route distance `s_m`."""
    cum = np.concatenate([[0.0], np.cumsum(plan.lengths_m)])
    i = int(np.clip(np.searchsorted(cum, s_m, side="right") - 1, 0, len(plan.steps) - 1))
    d = min(s_m - cum[i], plan.lengths_m[i])
    along = d if plan.steps[i].direction == "up" else plan.lengths_m[i] - d
    return i, float(along)


@dataclass(frozen=True)
class FacingSwitch:
    switch: str
    leg: str  # the edge taken
    track: str  # the track of the edge taken
    s_node_m: float  # route distance of the switch node
    s_frog_m: float  # route distance of the frog on the leg taken


def facing_switches(topology: Topology, plan: RoutePlan, facing: bool = True) -> list[FacingSwitch]:
    """Switches the route passes from the toe (facing: a choice of leg), or with `facing` False the
    trailing ones (from a leg to the toe: no choice; `s_frog_m` is then the frog on the leg left)."""
    out, s = [], 0.0
    for a, b, la in zip(plan.steps, plan.steps[1:], plan.lengths_m):
        s += la
        node = topology.node_ahead(a)
        if topology.nodes[node].kind == "switch" and (topology.turnouts[node].toe == a.edge) == facing:
            t = topology.turnouts[node]
            frog = s + t.frog_m if facing else s - t.frog_m
            out.append(FacingSwitch(node, b.edge, topology.edges[b.edge].track, s, frog))
    return out


@dataclass
class RunResult:
    seed: int
    route: list[str]
    speed_m_s: float
    epochs: int = 0
    decided: int = 0
    wrong: int = 0
    unknown: int = 0
    inconsistent: int = 0
    no_fix: int = 0
    fixed: int = 0
    switches: int = 0
    switches_correct: int = 0
    trailing: int = 0
    trailing_correct: int = 0
    after_frog_m: list[float] = field(default_factory=list)  # decision distance after the frog (< 0: before)
    wrong_details: list[str] = field(default_factory=list)


class SolutionErrorModel:
    """Fixed/float/none Markov chain with AR(1) horizontal and vertical errors (module constants)."""

    def __init__(self, rng: np.random.Generator, error_scale: float = 1.0, wrong_fix_bias_m: float = 0.0):
        """`error_scale`: true error / reported sigma (stress: a covariance that understates);
        `wrong_fix_bias_m`: cross-track bias of a wrong fix (WRONG_FIX_FRACTION of fixed spells)."""
        if not (error_scale > 0.0 and math.isfinite(error_scale) and math.isfinite(wrong_fix_bias_m)):
            raise ValueError("error scale must be positive and finite, the wrong-fix bias finite")
        self.rng = rng
        self.error_scale = float(error_scale)
        self.wrong_fix_bias_m = float(wrong_fix_bias_m)
        self.bias_cross_m = 0.0  # the current spell's cross-track bias
        self.state = "float"  # a run starts on a float solution, like a receiver coming up
        self.sigma = rng.uniform(*SIGMA_FLOAT_RANGE_M)
        self.err = rng.normal(0.0, 1.0, 3) * self._sig3()

    def _sig3(self) -> np.ndarray:
        return np.array([self.sigma, self.sigma, SIGMA_UP_FACTOR * self.sigma])

    def step(self) -> tuple[str, np.ndarray | None, np.ndarray]:
        """Advance one epoch: (state, ENU error [m] or None in an outage, reported ENU sigmas [m]);
        the spell's cross-track bias is in `bias_cross_m` (to the left of the direction of travel)."""
        u = self.rng.random()
        prev = self.state
        if self.state == "none":
            if u < P_NONE_TO_FLOAT:
                self.state = "float"
        elif u < P_TO_NONE:
            self.state = "none"
        elif self.state == "fixed" and u < P_TO_NONE + P_FIXED_TO_FLOAT:
            self.state = "float"
        elif self.state == "float" and u < P_TO_NONE + P_FLOAT_TO_FIXED:
            self.state = "fixed"
        if self.state == "none":
            return "none", None, self._sig3()
        new_sigma = SIGMA_FIXED_M if self.state == "fixed" else (
            self.sigma if prev == "float" else self.rng.uniform(*SIGMA_FLOAT_RANGE_M))
        tau = TAU_FIXED_S if self.state == "fixed" else TAU_FLOAT_S
        if self.state != prev:
            # a new solution state: the error restarts from its own stationary distribution
            self.sigma = new_sigma
            self.err = self.rng.normal(0.0, 1.0, 3) * self._sig3()
            self.bias_cross_m = 0.0
            if self.wrong_fix_bias_m and self.state == "fixed" and self.rng.random() < WRONG_FIX_FRACTION:
                self.bias_cross_m = self.wrong_fix_bias_m * (1.0 if self.rng.random() < 0.5 else -1.0)
        else:
            rho = math.exp(-EPOCH_S / tau)
            self.err = rho * self.err + math.sqrt(1.0 - rho * rho) * self.rng.normal(0.0, 1.0, 3) * self._sig3()
        return self.state, self.err * self.error_scale, self._sig3()


def run_one(topology: Topology, seed: int, start: Step | None = None, error_scale: float = 1.0,
            wrong_fix_bias_m: float = 0.0) -> RunResult:
    rng = np.random.default_rng(seed)
    starts = route_starts(topology)
    start = start or starts[seed % len(starts)]
    # every start, then each facing switch's diverging leg in turn: seeds 0..4n-1 cover both legs of
    # every facing switch of a line with n route starts and up to two facing switches per route
    plan = plan_route(topology, start, pattern=seed // len(starts))
    speed = float(rng.uniform(*SPEED_RANGE_M_S))
    res = RunResult(seed, [f"{s.edge}{'+' if s.direction == 'up' else '-'}" for s in plan.steps], speed)
    switches = facing_switches(topology, plan)
    errors = SolutionErrorModel(rng, error_scale, wrong_fix_bias_m)
    ident = TrackIdentifier(topology)
    s_end = plan.length_m - END_CLEARANCE_M
    n = int((s_end - END_CLEARANCE_M) / (speed * EPOCH_S)) + 1
    decisions = []  # (route distance, decided track or None, truth track)
    for k in range(n):
        s = END_CLEARANCE_M + k * speed * EPOCH_S
        i, along = _locate(topology, plan, s)
        truth_edge = plan.steps[i].edge
        truth_track = topology.edges[truth_edge].track
        x = topology.point_at_m(truth_edge, along)
        state, err, sig = errors.step()
        t = k * EPOCH_S
        res.epochs += 1
        if err is None:
            d = ident.update(None, t)
        else:
            llh = ecef_to_geodetic(x)
            r = enu_rotation(llh[0], llh[1])
            cov = r.T @ np.diag(sig ** 2) @ r
            if errors.bias_cross_m:
                ahead = topology.point_at_m(truth_edge, min(along + 1.0, plan.lengths_m[i]))
                behind = topology.point_at_m(truth_edge, max(along - 1.0, 0.0))
                tan = (r @ (ahead - behind))[:2] * (1.0 if plan.steps[i].direction == "up" else -1.0)
                tan /= np.linalg.norm(tan)
                err = err + errors.bias_cross_m * np.array([-tan[1], tan[0], 0.0])
            d = ident.update(fix_from_position(t, x + r.T @ err, cov))
            res.fixed += state == "fixed"
        if d.status == "decided":
            res.decided += 1
            if d.track != truth_track:
                res.wrong += 1
                res.wrong_details.append(f"t={t:.0f} s, s={s:.1f} m: decided {d.track}, truth {truth_track} "
                                         f"({truth_edge}, {state})")
        elif d.status == "unknown":
            res.unknown += 1
        elif d.status == "inconsistent":
            res.inconsistent += 1
        else:
            res.no_fix += 1
        decisions.append((s, d.track if d.status == "decided" else None, truth_track))
    # per switch: the first decision past the switch node, before the next switch, is the truth's track
    trailing = facing_switches(topology, plan, facing=False)
    nodes = sorted(x.s_node_m for x in switches + trailing)  # facing_switches lists in route order
    for sw in switches + trailing:
        if not (END_CLEARANCE_M < sw.s_node_m < s_end):
            continue
        is_facing = sw in switches
        res.switches += is_facing
        res.trailing += not is_facing
        # a facing switch's leg is told until the next choice (deciding track 2 after the crossover's
        # trailing end still says which leg was taken); a trailing one's until the next switch
        later = [x.s_node_m for x in switches] if is_facing else nodes
        s_next = next((x for x in later if x > sw.s_node_m), math.inf)
        for s, track, truth in decisions:
            if s <= sw.s_node_m or track is None:
                continue
            if s >= s_next:
                break
            if track == truth:
                if is_facing:
                    res.switches_correct += 1
                    res.after_frog_m.append(s - sw.s_frog_m)
                else:
                    res.trailing_correct += 1
            break
    return res


@dataclass
class CampaignReport:
    runs: list[RunResult]

    def totals(self) -> dict[str, float]:
        r = self.runs
        epochs = sum(x.epochs for x in r)
        d = np.array([v for x in r for v in x.after_frog_m])
        return {
            "runs": len(r), "epochs": epochs, "decided": sum(x.decided for x in r),
            "wrong": sum(x.wrong for x in r), "unknown": sum(x.unknown for x in r),
            "inconsistent": sum(x.inconsistent for x in r), "no_fix": sum(x.no_fix for x in r),
            "unknown_pct": 100.0 * sum(x.unknown for x in r) / max(epochs, 1),
            "not_decided_pct": 100.0 * (epochs - sum(x.decided for x in r)) / max(epochs, 1),
            "fixed_pct": 100.0 * sum(x.fixed for x in r) / max(epochs, 1),
            "switches": sum(x.switches for x in r), "switches_correct": sum(x.switches_correct for x in r),
            "trailing": sum(x.trailing for x in r), "trailing_correct": sum(x.trailing_correct for x in r),
            "after_frog_median_m": float(np.median(d)) if len(d) else math.nan,
            "after_frog_p95_m": float(np.percentile(d, 95)) if len(d) else math.nan,
            "after_frog_max_m": float(np.max(d)) if len(d) else math.nan,
        }

    def text(self) -> str:
        t = self.totals()
        lines = [f"{'seed':>4} {'speed':>6} {'epochs':>6} {'decided':>7} {'wrong':>5} {'unknown':>7} "
                 f"{'incons':>6} {'nofix':>5} {'switch':>7}  route"]
        for x in self.runs:
            lines.append(f"{x.seed:>4} {x.speed_m_s:>6.1f} {x.epochs:>6} {x.decided:>7} {x.wrong:>5} {x.unknown:>7} "
                         f"{x.inconsistent:>6} {x.no_fix:>5} {x.switches_correct:>3}/{x.switches:<3}  "
                         f"{' '.join(x.route)}")
            lines.extend(f"     WRONG {w}" for w in x.wrong_details)
        lines.append(
            f"runs {t['runs']}, epochs {t['epochs']}, decided {t['decided']}, wrong {t['wrong']}, "
            f"unknown {t['unknown']} ({t['unknown_pct']:.1f} %), inconsistent {t['inconsistent']}, "
            f"no fix {t['no_fix']} (not decided {t['not_decided_pct']:.1f} %), fixed {t['fixed_pct']:.1f} % of epochs")
        lines.append(f"facing switches passed {t['switches']}, decided correctly {t['switches_correct']} "
                     f"(trailing {t['trailing']}, {t['trailing_correct']}); "
                     f"decision after the frog: median {t['after_frog_median_m']:.1f} m, "
                     f"p95 {t['after_frog_p95_m']:.1f} m, max {t['after_frog_max_m']:.1f} m (negative: before it)")
        return "\n".join(lines)


def run_campaign(topology: Topology, seeds=DEFAULT_SEEDS, error_scale: float = 1.0,
                 wrong_fix_bias_m: float = 0.0) -> CampaignReport:
    return CampaignReport([run_one(topology, int(s), error_scale=error_scale, wrong_fix_bias_m=wrong_fix_bias_m)
                           for s in seeds])
