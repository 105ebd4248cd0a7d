"""Track identification in the full chain: `augnet.track.identification` fed the onboard RTK solutions of a
layout scenario (the real simulated GNSS chain of `augnet.scenario.runner`), scored per switch passage
against the simulator's truth (edge and route distance per epoch).

The identifier sees only the solutions (position, covariance) and the map it is given (the as-built truth
map exported from the simulator, or a map built from a survey run: `augnet.track.survey_map`); the truth
(route, edges, frogs) is read here, to judge, and nowhere else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.track.identification import TrackIdentifier, fix_from_position
from augnet.track.topology import Topology
from stations.layout import Layout


@dataclass
class SwitchPassage:
    train: str
    switch: str
    facing: bool  # from the toe: a choice of leg
    leg_track: str  # the track of the leg taken (facing) / of the toe (trailing)
    s_node_m: float  # route distance of the switch node
    s_frog_m: float  # route distance of the frog on the leg taken (facing) or left (trailing)
    decided_after_frog_m: float = math.nan  # route distance past the frog of the first right decision
    wrong: int = 0  # wrong-track decisions between this switch and the next


@dataclass
class ChainIdentification:
    epochs: int = 0
    with_fix: int = 0
    decided: int = 0
    wrong: int = 0
    unknown: int = 0
    inconsistent: int = 0
    no_fix: int = 0
    passages: list[SwitchPassage] = field(default_factory=list)
    wrong_details: list[str] = field(default_factory=list)
    unknown_at: list[tuple[str, float, int]] = field(default_factory=list)  # (train, t [s], solution status)

    def totals(self) -> dict:
        facing = [p for p in self.passages if p.facing]
        d = np.array([p.decided_after_frog_m for p in facing if math.isfinite(p.decided_after_frog_m)])
        return {
            "epochs": self.epochs, "with_fix": self.with_fix, "decided": self.decided, "wrong": self.wrong,
            "unknown": self.unknown, "inconsistent": self.inconsistent, "no_fix": self.no_fix,
            "unknown_pct_of_fixes": 100.0 * self.unknown / max(self.with_fix, 1),
            "unknown_on_fixed_solutions": sum(1 for x in self.unknown_at if x[2] == 1),
            "unknown_last_t_s": max((x[1] for x in self.unknown_at), default=math.nan),
            "correct_pct_of_decided": 100.0 * (self.decided - self.wrong) / max(self.decided, 1),
            "facing_switches": len(facing), "facing_decided": int(len(d)),
            "trailing_switches": len(self.passages) - len(facing),
            "after_frog_m": sorted(round(float(x), 1) for x in d),
            "after_frog_median_m": float(np.median(d)) if len(d) else math.nan,
            "after_frog_p95_m": float(np.percentile(d, 95)) if len(d) else math.nan,
            "after_frog_max_m": float(np.max(d)) if len(d) else math.nan,
        }

    def text(self) -> str:
        t = self.totals()
        lines = [f"epochs {t['epochs']} (with a fix {t['with_fix']}), decided {t['decided']}, wrong {t['wrong']} "
                 f"(correct {t['correct_pct_of_decided']:.2f} % of decided), unknown {t['unknown']} "
                 f"({t['unknown_pct_of_fixes']:.1f} % of fixes), inconsistent {t['inconsistent']}, "
                 f"no fix {t['no_fix']}"]
        for p in self.passages:
            lines.append(f"  {p.train} {p.switch} {'facing' if p.facing else 'trailing'} -> {p.leg_track}: "
                         f"decided {p.decided_after_frog_m:.1f} m after the frog, wrong {p.wrong}")
        lines.append(f"facing switches {t['facing_switches']}, decided {t['facing_decided']}; after the frog: "
                     f"median {t['after_frog_median_m']:.1f} m, p95 {t['after_frog_p95_m']:.1f} m, "
                     f"max {t['after_frog_max_m']:.1f} m")
        lines.extend(f"  WRONG {w}" for w in self.wrong_details[:20])
        return "\n".join(lines)


def switch_passages(layout: Layout, train_id: str, route_edges, direction: int, start_km: float) -> list[SwitchPassage]:
    """The switches a route passes, with the truth route distance of each node and frog."""
    route = layout.route(list(route_edges), direction, start_km)
    out = []
    for j in range(1, len(route.edges)):
        a, b = route.edges[j - 1], route.edges[j]
        ea = layout.edges[a]
        node = ea.end if route.directions[j - 1] == "up" else ea.begin
        if layout.node_kind[node] != "switch":
            continue
        t = layout.turnouts[node]
        s_node = float(route.u_m[np.flatnonzero(route.edge_index == j - 1)[-1]])
        frog = layout.frog_m(node)
        facing = a == t["toe"]
        out.append(SwitchPassage(train_id, node, facing, layout.edges[b].track, s_node,
                                 s_node + frog if facing else s_node - frog))
    return out


def identify(log, topology: Topology, layout: Layout | None = None) -> ChainIdentification:
    """Run the identifier on every train's onboard solutions (cold start at its first fix) over `topology`
    and score it against the truth of the run `log` (an `augnet.scenario.runner.RunLog` of a layout scenario)."""
    sc = log.scenario
    if sc.layout is None:
        raise ValueError(f"scenario {sc.name} has no layout: no switches to identify the track through")
    layout = layout or Layout.load(sc.layout.file)
    res = ChainIdentification()
    for cfg in sc.trains:
        tl = log.trains[cfg.id]
        passages = switch_passages(layout, cfg.id, cfg.route, cfg.direction, cfg.start_km)
        ident = TrackIdentifier(topology)
        decisions = []  # (route distance, decided track or None, truth track)
        for k, t in enumerate(tl.t_s):
            p = np.asarray(tl.position[k], float)
            c = np.asarray(tl.covariance[k], float)
            truth_track = topology.edges[tl.truth_edge[k]].track
            res.epochs += 1
            if p.shape == (3,) and np.all(np.isfinite(p)) and c.shape == (3, 3) and np.all(np.isfinite(c)):
                res.with_fix += 1
                d = ident.update(fix_from_position(float(t), p, c))
            else:
                d = ident.update(None, float(t))
            if d.status == "decided":
                res.decided += 1
                if d.track != truth_track:
                    res.wrong += 1
                    res.wrong_details.append(f"{cfg.id} t={t:.0f} s, s={tl.truth_route_m[k]:.1f} m: decided "
                                             f"{d.track}, truth {truth_track} ({tl.truth_edge[k]})")
            elif d.status == "unknown":
                res.unknown += 1
                res.unknown_at.append((cfg.id, float(t), int(tl.status[k]) if k < len(getattr(tl, "status", [])) else -1))
            elif d.status == "inconsistent":
                res.inconsistent += 1
            else:
                res.no_fix += 1
            decisions.append((tl.truth_route_m[k], d.track if d.status == "decided" else None, truth_track))
        facing_nodes = [p.s_node_m for p in passages if p.facing]
        all_nodes = [p.s_node_m for p in passages]
        for sw in passages:
            later = facing_nodes if sw.facing else all_nodes
            s_next = next((x for x in later if x > sw.s_node_m), math.inf)
            first = True
            for s, track, truth in decisions:
                if s <= sw.s_node_m or track is None:
                    continue
                if s >= s_next:
                    break
                if track != truth:
                    sw.wrong += 1
                elif first:
                    sw.decided_after_frog_m = s - sw.s_frog_m
                    first = False
        res.passages.extend(passages)
    return res


# Campaign variation (`vary`): each train's start moved back by up to this much [km] and its line speed drawn
# in this range [km/h], so the 1 Hz epochs fall at other places relative to the switches.
VARY_START_KM = 0.030
VARY_SPEED_KMH = (80.0, 120.0)


def varied(sc, seed: int):
    """`sc` with `seed`, each train's start moved back 0-30 m and its speed drawn (seeded by `seed`)."""
    rng = np.random.default_rng([seed, 291])
    trains = []
    for t in sc.trains:
        shift = rng.uniform(0.0, VARY_START_KM) * (-t.direction)
        v = float(rng.uniform(*VARY_SPEED_KMH))
        trains.append(t.model_copy(update={"start_km": round(t.start_km + shift, 4), "speed_kmh": v,
                                           "start_speed_kmh": v}))
    return sc.model_copy(update={"seed": int(seed), "trains": trains})


def campaign(sc, seeds, maps: dict[str, Topology], *, vary: bool = False, warm_up_s: float = 60.0,
             progress=None) -> dict[str, list[ChainIdentification]]:
    """Each seed's full chain run once, identified on every map: {map name: [result per seed]}."""
    from augnet.scenario.runner import simulate

    layout = Layout.load(sc.layout.file)
    out: dict[str, list[ChainIdentification]] = {k: [] for k in maps}
    for seed in seeds:
        run_sc = varied(sc, seed) if vary else sc.model_copy(update={"seed": int(seed)})
        log = simulate(run_sc, warm_up_s=warm_up_s)
        for name, topo in maps.items():
            out[name].append(identify(log, topo, layout))
            if progress is not None:
                progress(seed, name, out[name][-1])
    return out


def merged(results: list[ChainIdentification]) -> ChainIdentification:
    m = ChainIdentification()
    for r in results:
        for k in ("epochs", "with_fix", "decided", "wrong", "unknown", "inconsistent", "no_fix"):
            setattr(m, k, getattr(m, k) + getattr(r, k))
        m.passages.extend(r.passages)
        m.wrong_details.extend(r.wrong_details)
        m.unknown_at.extend(r.unknown_at)
    return m
