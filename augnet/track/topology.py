"""Track topology: nodes, track segments (edges) with chainage and geometry, turnouts, points of interest.

The model a railway draws its line in (docs/track-topology.md is the file format):

- an **edge** is a piece of track between two nodes, a WGS 84 polyline with the line's chainage per
  vertex (km strictly increasing from its `begin` node to its `end` node);
- a **node** joins edge ends: a `joint` (two ends, a railML track boundary), a `switch` (three ends:
  toe, straight leg, diverging leg), a `buffer_stop` or an `open_end` (one end, where the map stops);
- a **turnout** names the legs of a switch node and the frog's distance from the switch along the
  diverging leg; a crossover is two turnouts joined by a `crossover` edge, a loop track two turnouts
  joined by `loop` (or `platform`) edges;
- **points of interest** (balise groups, signals, platform ends, stations) and **section boundaries**
  sit on an edge at a chainage.

Movement rule the queries keep: through a switch a train goes toe <-> straight or toe <-> diverging,
never straight <-> diverging.  Pure: no file access here (`augnet.track.topology_file` reads and
writes); errors are `TopologyError` naming the element.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable

import numpy as np

from augnet.gnss.geometry import ecef_to_geodetic, geodetic_deg_to_ecef

FORMAT = "augnet-topology/1"
NODE_KINDS = ("joint", "switch", "buffer_stop", "open_end")
# Edge ends a node of each kind joins.
NODE_DEGREE = {"joint": 2, "switch": 3, "buffer_stop": 1, "open_end": 1}
EDGE_KINDS = ("main", "loop", "platform", "crossover", "siding", "connecting")
POI_KINDS = ("balise_group", "signal", "platform_end", "station", "km_post")
COURSES = ("left", "right")
DIRECTIONS = ("up", "down")  # up: increasing chainage
# An edge end farther than this from its node's position is a geometry gap [m]: survey-grade maps
# close to centimetres, 0.5 m catches a wrong coordinate without tripping on rounding.
GEOMETRY_GAP_TOLERANCE_M = 0.5
# Consecutive vertices closer than this [m] are one point given twice (a chord of no direction).
MIN_SEGMENT_M = 0.001
# A point of interest may sit this far outside its edge's chainage range [km] (rounding of mileage).
CHAINAGE_TOLERANCE_KM = 1e-6
# Standard gauge (UIC, 1435 mm): the frog's nose is where the inner rails cross, i.e. where the two
# legs' centre lines are one gauge apart.
STANDARD_GAUGE_M = 1.435
# Step along the diverging leg when locating the frog [m].
FROG_SEARCH_STEP_M = 0.1


class TopologyError(ValueError):
    """A topology that cannot be used; `element` names the offending element ("edge T1.0")."""

    def __init__(self, element: str, reason: str):
        super().__init__(f"{element}: {reason}")
        self.element = element
        self.reason = reason


@dataclass(frozen=True)
class Node:
    id: str
    kind: str
    position_llh: tuple[float, float, float]  # lat deg, lon deg, ellipsoidal h m


@dataclass(frozen=True)
class Edge:
    id: str
    track: str  # the track (railML track id, or the main track's number) this segment belongs to
    kind: str
    begin: str  # node id at the first vertex
    end: str  # node id at the last vertex
    points_llh: np.ndarray = field(compare=False)  # (n, 3) lat deg, lon deg, h m
    km: np.ndarray = field(compare=False)  # (n,) line chainage of each vertex [km], increasing
    station: str = ""  # station (railML ocp) the edge lies in, "" on open line
    name: str = ""

    @property
    def km_begin(self) -> float:
        return float(self.km[0])

    @property
    def km_end(self) -> float:
        return float(self.km[-1])


@dataclass(frozen=True)
class Turnout:
    id: str  # = the switch node's id
    toe: str  # edge ids
    straight: str
    diverging: str
    course: str  # side the diverging leg leaves to, seen from the toe: "left" / "right"
    frog_m: float  # distance from the switch node to the frog along the diverging leg [m]
    name: str = ""


@dataclass(frozen=True)
class PointOfInterest:
    id: str
    kind: str
    edge: str
    km: float
    name: str = ""
    direction: str = ""  # "up" / "down" where the element acts in one direction, else ""
    telegram: bytes = b""  # balise groups: the stored telegram (virtual balises)


@dataclass(frozen=True)
class SectionBoundary:
    id: str
    edge: str
    km: float
    name: str = ""


@dataclass(frozen=True)
class NearestPoint:
    edge: str
    km: float  # chainage of the nearest point [km]
    along_m: float  # arc length from the edge's begin node [m]
    distance_m: float  # 3-D distance from the query position [m]
    point_ecef_m: np.ndarray = field(compare=False)


@dataclass(frozen=True)
class Step:
    """An edge entered from one of its ends, travelling in `direction` (up: increasing chainage)."""

    edge: str
    direction: str


class Topology:
    """A validated track topology.  Construction validates; a bad element raises `TopologyError`."""

    def __init__(self, name: str, nodes: Iterable[Node], edges: Iterable[Edge], turnouts: Iterable[Turnout] = (),
                 points: Iterable[PointOfInterest] = (), sections: Iterable[SectionBoundary] = (),
                 accuracy: dict | None = None):
        self.name = name
        # a map built from a survey carries its verified accuracy (augnet.track.survey_map.verify), else None
        self.accuracy = dict(accuracy) if accuracy is not None else None
        self.nodes = _unique("node", nodes)
        self.edges = _unique("edge", edges)
        self.turnouts = _unique("turnout", turnouts)
        self.points = _unique("point of interest", points)
        self.sections = _unique("section boundary", sections)
        self._ecef = {e.id: geodetic_deg_to_ecef(e.points_llh[:, 0], e.points_llh[:, 1], e.points_llh[:, 2])
                      for e in self.edges.values() if _edge_shape_ok(e)}
        self._validate()
        self._arc = {eid: np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
                     for eid, x in self._ecef.items()}
        # every chord of every edge in one array, for nearest_edges (one numpy pass per position)
        ids = list(self.edges)
        self._seg_edge = np.concatenate([np.full(len(self._ecef[i]) - 1, k) for k, i in enumerate(ids)])
        self._seg_a = np.concatenate([self._ecef[i][:-1] for i in ids])
        self._seg_d = np.concatenate([np.diff(self._ecef[i], axis=0) for i in ids])
        self._seg_ids = ids

    # ------------------------------------------------------------------------------------------
    # validation

    def _validate(self) -> None:
        ends: dict[str, list[tuple[str, str]]] = {n: [] for n in self.nodes}
        for e in self.edges.values():
            el = f"edge {e.id}"
            if e.kind not in EDGE_KINDS:
                raise TopologyError(el, f"kind {e.kind!r} is not one of {', '.join(EDGE_KINDS)}")
            if not _edge_shape_ok(e):
                raise TopologyError(el, "needs >= 2 finite [lat, lon, h] points and one finite km per point")
            seg = np.linalg.norm(np.diff(self._ecef[e.id], axis=0), axis=1)
            if np.any(seg < MIN_SEGMENT_M):
                i = int(np.argmax(seg < MIN_SEGMENT_M))
                raise TopologyError(el, f"points {i} and {i + 1} coincide ({seg[i]:.4f} m apart)")
            if np.any(np.diff(e.km) <= 0):
                i = int(np.argmax(np.diff(e.km) <= 0))
                raise TopologyError(el, f"chainage not increasing: km {e.km[i]:.6f} then {e.km[i + 1]:.6f} "
                                        f"at points {i} and {i + 1}")
            for side, nid in (("begin", e.begin), ("end", e.end)):
                if nid not in self.nodes:
                    raise TopologyError(el, f"dangling connection: {side} node {nid!r} does not exist")
                ends[nid].append((e.id, side))
                node_xyz = geodetic_deg_to_ecef(*self.nodes[nid].position_llh)
                xyz = self._ecef[e.id][0 if side == "begin" else -1]
                gap = float(np.linalg.norm(xyz - node_xyz))
                if gap > GEOMETRY_GAP_TOLERANCE_M:
                    raise TopologyError(el, f"geometry gap: its {side} is {gap:.2f} m from node {nid} "
                                            f"(tolerance {GEOMETRY_GAP_TOLERANCE_M} m)")
        for n in self.nodes.values():
            el = f"node {n.id}"
            if n.kind not in NODE_KINDS:
                raise TopologyError(el, f"kind {n.kind!r} is not one of {', '.join(NODE_KINDS)}")
            if not all(math.isfinite(v) for v in n.position_llh):
                raise TopologyError(el, "position must be finite [lat, lon, h]")
            got = len(ends[n.id])
            if got != NODE_DEGREE[n.kind]:
                joined = ", ".join(f"{eid} {side}" for eid, side in ends[n.id]) or "no edge"
                raise TopologyError(el, f"dangling connection: a {n.kind} joins {NODE_DEGREE[n.kind]} edge "
                                        f"end(s), this one {got} ({joined})")
        self._ends = ends
        for n in self.nodes.values():
            if n.kind == "switch" and n.id not in self.turnouts:
                raise TopologyError(f"node {n.id}", "a switch node without a turnout naming its legs")
        for t in self.turnouts.values():
            el = f"turnout {t.id}"
            if t.id not in self.nodes or self.nodes[t.id].kind != "switch":
                raise TopologyError(el, "names no switch node")
            attached = {eid for eid, _ in ends[t.id]}
            for leg in ("toe", "straight", "diverging"):
                eid = getattr(t, leg)
                if eid not in self.edges:
                    raise TopologyError(el, f"{leg} leg {eid!r} does not exist")
                if eid not in attached:
                    raise TopologyError(el, f"{leg} leg {eid!r} does not end at this switch")
            if len({t.toe, t.straight, t.diverging}) != 3:
                raise TopologyError(el, "toe, straight and diverging legs must be three different edges")
            if t.course not in COURSES:
                raise TopologyError(el, f"course {t.course!r} is not left or right")
            if not (math.isfinite(t.frog_m) and 0.0 < t.frog_m <= self.length_m(t.diverging)):
                raise TopologyError(el, f"frog at {t.frog_m} m is not on the diverging leg")
        for p in self.points.values():
            self._check_on_edge(f"point of interest {p.id}", p.edge, p.km)
            if p.kind not in POI_KINDS:
                raise TopologyError(f"point of interest {p.id}",
                                    f"kind {p.kind!r} is not one of {', '.join(POI_KINDS)}")
            if p.direction not in ("", *DIRECTIONS):
                raise TopologyError(f"point of interest {p.id}", f"direction {p.direction!r} is not up, down or empty")
        for s in self.sections.values():
            self._check_on_edge(f"section boundary {s.id}", s.edge, s.km)

    def _check_on_edge(self, el: str, edge: str, km: float) -> None:
        if edge not in self.edges:
            raise TopologyError(el, f"on edge {edge!r}, which does not exist")
        e = self.edges[edge]
        if not (math.isfinite(km) and e.km_begin - CHAINAGE_TOLERANCE_KM <= km <= e.km_end + CHAINAGE_TOLERANCE_KM):
            raise TopologyError(el, f"km {km} is outside edge {edge} (km {e.km_begin:.6f}-{e.km_end:.6f})")

    # ------------------------------------------------------------------------------------------
    # geometry queries

    def length_m(self, edge: str) -> float:
        x = self._ecef[self._edge(edge).id]
        return float(np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1)))

    def along_m(self, edge: str, km: float) -> float:
        """Arc length [m] from the edge's begin node to chainage `km` (chainage interpolated by arc)."""
        e = self._edge(edge)
        self._check_on_edge(f"edge {edge}", edge, km)
        return float(np.interp(km, e.km, self._arc[edge]))

    def km_at(self, edge: str, along_m: float) -> float:
        e = self._edge(edge)
        return float(np.interp(along_m, self._arc[edge], e.km))

    def position_ecef(self, edge: str, km: float) -> np.ndarray:
        return self.point_at_m(edge, self.along_m(edge, km))

    def point_at_m(self, edge: str, along_m: float) -> np.ndarray:
        """ECEF position [m] at arc length `along_m` from the edge's begin node (on its chords)."""
        self._edge(edge)
        s = float(along_m)
        x, arc = self._ecef[edge], self._arc[edge]
        if not (math.isfinite(s) and -MIN_SEGMENT_M <= s <= arc[-1] + MIN_SEGMENT_M):
            raise TopologyError(f"edge {edge}", f"{along_m} m is outside the edge (0-{arc[-1]:.3f} m)")
        i = int(np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 2))
        f = (s - arc[i]) / (arc[i + 1] - arc[i])
        return x[i] + f * (x[i + 1] - x[i])

    def nearest_point(self, edge: str, position_ecef_m) -> NearestPoint:
        """The point of `edge` nearest to an ECEF position (projection onto every chord at once)."""
        self._edge(edge)
        x, arc = self._ecef[edge], self._arc[edge]
        p = np.asarray(position_ecef_m, dtype=float)
        a, d = x[:-1], np.diff(x, axis=0)
        t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
        q = a + t[:, None] * d
        dist = np.linalg.norm(q - p, axis=1)
        i = int(np.argmin(dist))
        s = float(arc[i] + t[i] * (arc[i + 1] - arc[i]))
        return NearestPoint(edge, self.km_at(edge, s), s, float(dist[i]), q[i])

    def nearest_edges(self, position_ecef_m, radius_m: float) -> list[NearestPoint]:
        """Every edge passing within `radius_m` of a position, nearest first."""
        p = np.asarray(position_ecef_m, dtype=float)
        a, d = self._seg_a, self._seg_d
        t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
        dist = np.linalg.norm(a + t[:, None] * d - p, axis=1)
        near = np.unique(self._seg_edge[dist <= radius_m])
        hits = [self.nearest_point(self._seg_ids[k], p) for k in near]
        return sorted(hits, key=lambda h: h.distance_m)

    # ------------------------------------------------------------------------------------------
    # connectivity queries

    def edges_at(self, node: str) -> list[tuple[str, str]]:
        """The edge ends a node joins: (edge id, "begin" | "end")."""
        if node not in self.nodes:
            raise TopologyError(f"node {node}", "does not exist")
        return list(self._ends[node])

    def node_ahead(self, step: Step) -> str:
        e = self._edge(step.edge)
        _check_direction(step.direction)
        return e.end if step.direction == "up" else e.begin

    def next_steps(self, step: Step) -> list[Step]:
        """Edges a train on `step.edge` travelling `step.direction` may be on after the node ahead."""
        node_id = self.node_ahead(step)
        arriving_end = "end" if step.direction == "up" else "begin"
        node = self.nodes[node_id]
        others = [(eid, side) for eid, side in self._ends[node_id] if (eid, side) != (step.edge, arriving_end)]
        if node.kind == "switch":
            t = self.turnouts[node_id]
            if step.edge == t.toe:
                allowed = {t.straight, t.diverging}
            else:
                allowed = {t.toe}  # from a leg only to the toe: straight <-> diverging is no route
            others = [(eid, side) for eid, side in others if eid in allowed]
        # leaving from an edge's begin runs up the chainage, from its end down
        return [Step(eid, "up" if side == "begin" else "down") for eid, side in others]

    def reachable(self, step: Step, distance_m: float, from_km: float | None = None) -> list[Step]:
        """Every edge (with its direction of travel) a train may reach within `distance_m` ahead,
        starting at `from_km` on `step.edge` (default: at the end it enters by, the whole edge ahead)."""
        e = self._edge(step.edge)
        _check_direction(step.direction)
        length = self.length_m(e.id)
        if from_km is None:
            remaining = distance_m - length
        else:
            s = self.along_m(e.id, from_km)
            remaining = distance_m - ((length - s) if step.direction == "up" else s)
        # best distance left at the far end of each step: a step reached again with more left is
        # walked again (the first path to it need not be the shortest)
        best = {step: remaining}
        frontier = [step]
        while frontier:
            cur = frontier.pop()
            left = best[cur]
            if left <= 0:
                continue
            for nxt in self.next_steps(cur):
                after = left - self.length_m(nxt.edge)
                if nxt not in best or after > best[nxt]:
                    best[nxt] = after
                    frontier.append(nxt)
        return list(best)

    def tracks_after_next_switch(self, step: Step) -> set[str]:
        """Tracks a train on `step` may be on once past the next switch ahead (joints are passed
        through; through a crossover edge the track at its far switch is reached as well)."""
        cur = [step]
        seen: set[Step] = set()
        while cur:
            sw = [s for s in cur if self.nodes[self.node_ahead(s)].kind == "switch"]
            if sw:
                tracks: set[str] = set()
                for s in sw:
                    for nxt in self.next_steps(s):
                        tracks.add(self.edges[nxt.edge].track)
                        if self.edges[nxt.edge].kind == "crossover":
                            tracks |= {self.edges[x.edge].track for x in self.next_steps(nxt)}
                return tracks
            nxt_all = [n for s in cur for n in self.next_steps(s) if n not in seen]
            seen.update(nxt_all)
            cur = nxt_all
        return set()

    def check_route(self, route: list[Step]) -> None:
        """A route is a list of steps each reachable from the previous one; raise naming the break."""
        if not route:
            raise TopologyError("route", "empty")
        for a, b in zip(route, route[1:]):
            if b not in self.next_steps(a):
                raise TopologyError("route", f"{b.edge} ({b.direction}) does not follow {a.edge} ({a.direction}) "
                                             f"at node {self.node_ahead(a)}")

    def route_distance_m(self, route: list[Step], edge: str, km: float, start_km: float | None = None) -> float:
        """Distance [m] along `route` from its start (its first edge at `start_km`, default the end the
        train enters by) to chainage `km` on `edge` (the first visit of that edge on the route)."""
        self.check_route(route)
        first = route[0]
        if start_km is None:
            start_s = 0.0 if first.direction == "up" else self.length_m(first.edge)
        else:
            start_s = self.along_m(first.edge, start_km)
        total = 0.0
        for i, st in enumerate(route):
            length = self.length_m(st.edge)
            entry = start_s if i == 0 else (0.0 if st.direction == "up" else length)
            if st.edge == edge:
                s = self.along_m(edge, km)
                d = (s - entry) if st.direction == "up" else (entry - s)
                if d >= -CHAINAGE_TOLERANCE_KM * 1000.0:
                    return total + d
            total += (length - entry) if st.direction == "up" else entry
        raise TopologyError("route", f"does not pass edge {edge} at km {km} ahead of its start")

    def edges_of_track(self, track: str) -> list[str]:
        return sorted((e.id for e in self.edges.values() if e.track == track), key=lambda i: self.edges[i].km_begin)

    def _edge(self, edge: str) -> Edge:
        try:
            return self.edges[edge]
        except KeyError:
            raise TopologyError(f"edge {edge}", "does not exist") from None

    # ------------------------------------------------------------------------------------------
    # JSON dictionary (docs/track-topology.md) and GeoJSON

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "name": self.name,
            "nodes": [{"id": n.id, "kind": n.kind, "position": list(n.position_llh)} for n in self.nodes.values()],
            "edges": [{"id": e.id, "track": e.track, "kind": e.kind, "begin": e.begin, "end": e.end,
                       "station": e.station, "name": e.name, "points": e.points_llh.tolist(), "km": e.km.tolist()}
                      for e in self.edges.values()],
            "turnouts": [{"id": t.id, "toe": t.toe, "straight": t.straight, "diverging": t.diverging,
                          "course": t.course, "frog_m": t.frog_m, "name": t.name} for t in self.turnouts.values()],
            "points_of_interest": [{"id": p.id, "kind": p.kind, "edge": p.edge, "km": p.km, "name": p.name,
                                    "direction": p.direction, "telegram": p.telegram.hex()}
                                   for p in self.points.values()],
            "section_boundaries": [{"id": s.id, "edge": s.edge, "km": s.km, "name": s.name}
                                   for s in self.sections.values()],
            **({"accuracy": self.accuracy} if self.accuracy is not None else {}),
        }

    @classmethod
    def from_dict(cls, d: Any) -> "Topology":
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            got = d.get("format") if isinstance(d, dict) else type(d).__name__
            raise TopologyError("file", f"format {got!r}, expected {FORMAT!r}")
        el = "file"
        try:
            nodes = []
            for n in d["nodes"]:
                el = f"node {n.get('id')}"
                pos = tuple(float(v) for v in n["position"])
                if len(pos) != 3:
                    raise TopologyError(el, "position must be [lat, lon, h]")
                nodes.append(Node(str(n["id"]), str(n["kind"]), pos))
            edges = []
            for e in d["edges"]:
                el = f"edge {e.get('id')}"
                edges.append(Edge(str(e["id"]), str(e["track"]), str(e["kind"]), str(e["begin"]), str(e["end"]),
                                  np.asarray(e["points"], dtype=float), np.asarray(e["km"], dtype=float),
                                  str(e.get("station", "")), str(e.get("name", ""))))
            turnouts = []
            for t in d.get("turnouts", []):
                el = f"turnout {t.get('id')}"
                turnouts.append(Turnout(str(t["id"]), str(t["toe"]), str(t["straight"]), str(t["diverging"]),
                                        str(t["course"]), float(t["frog_m"]), str(t.get("name", ""))))
            points = []
            for p in d.get("points_of_interest", []):
                el = f"point of interest {p.get('id')}"
                points.append(PointOfInterest(str(p["id"]), str(p["kind"]), str(p["edge"]), float(p["km"]),
                                              str(p.get("name", "")), str(p.get("direction", "")),
                                              bytes.fromhex(p.get("telegram", ""))))
            sections = []
            for s in d.get("section_boundaries", []):
                el = f"section boundary {s.get('id')}"
                sections.append(SectionBoundary(str(s["id"]), str(s["edge"]), float(s["km"]), str(s.get("name", ""))))
        except TopologyError:
            raise
        except KeyError as exc:
            raise TopologyError(el, f"missing field {exc}") from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise TopologyError(el, f"malformed: {exc}") from None
        acc = d.get("accuracy")
        if acc is not None and not isinstance(acc, dict):
            raise TopologyError("accuracy", "must be an object")
        return cls(str(d.get("name", "")), nodes, edges, turnouts, points, sections, acc)

    def to_geojson(self) -> dict[str, Any]:
        """RFC 7946 FeatureCollection: tracks (LineString), switches, points of interest, section
        boundaries (Point); coordinates [lon, lat, h] in WGS 84 (RFC 7946 section 3.1.1 order)."""
        feats = []
        for e in self.edges.values():
            feats.append(_feature("LineString", [[p[1], p[0], p[2]] for p in e.points_llh.tolist()],
                                  {"feature": "track", "id": e.id, "track": e.track, "kind": e.kind,
                                   "station": e.station, "km_begin": e.km_begin, "km_end": e.km_end,
                                   "begin": e.begin, "end": e.end}))
        for t in self.turnouts.values():
            lat, lon, h = self.nodes[t.id].position_llh
            feats.append(_feature("Point", [lon, lat, h],
                                  {"feature": "switch", "id": t.id, "name": t.name, "toe": t.toe,
                                   "straight": t.straight, "diverging": t.diverging, "course": t.course,
                                   "frog_m": t.frog_m}))
        for kind, items in (("poi", self.points.values()), ("section_boundary", self.sections.values())):
            for p in items:
                lat, lon, h = ecef_to_geodetic(self.position_ecef(p.edge, p.km))
                props = {"feature": p.kind if kind == "poi" else kind, "id": p.id, "edge": p.edge, "km": p.km,
                         "name": p.name}
                if kind == "poi":
                    props["direction"] = p.direction
                feats.append(_feature("Point", [math.degrees(float(lon)), math.degrees(float(lat)), float(h)], props))
        return {"type": "FeatureCollection", "name": self.name, "features": feats}

    def to_track_database_dict(self, line: str = "") -> dict[str, Any]:
        """This topology as an augnet-trackmap/1 dictionary (one track per edge, balise groups as
        virtual balises) for `augnet.onboard.trackmap.TrackDatabase.from_dict`."""
        return {
            "format": "augnet-trackmap/1",  # augnet.onboard.trackmap.FORMAT
            "name": self.name,
            "tracks": [{"id": e.id, "line": line or e.track, "name": e.name or e.track,
                        "points": e.points_llh.tolist(), "km": e.km.tolist()} for e in self.edges.values()],
            "km_posts": [{"track": p.edge, "km": p.km, "label": p.name} for p in self.points.values()
                         if p.kind == "km_post"],
            "balises": [{"id": p.id, "track": p.edge, "km": p.km, "telegram": p.telegram.hex(), "linked": True}
                        for p in self.points.values() if p.kind == "balise_group"],
        }


def frog_distance_m(straight_ecef: np.ndarray, diverging_ecef: np.ndarray, diverging_from_switch: bool = True,
                    gauge_m: float = STANDARD_GAUGE_M) -> float | None:
    """Distance along the diverging leg from the switch to where the legs' centre lines are one gauge
    apart (the frog's nose), or None when they never separate that far.  Polylines in ECEF [m];
    `diverging_from_switch` False when the diverging leg's polyline ends at the switch."""
    d = diverging_ecef if diverging_from_switch else diverging_ecef[::-1]
    seg = np.diff(d, axis=0)
    lengths = np.linalg.norm(seg, axis=1)
    arc = np.concatenate([[0.0], np.cumsum(lengths)])
    s = np.arange(0.0, arc[-1] + FROG_SEARCH_STEP_M / 2, FROG_SEARCH_STEP_M)
    i = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(lengths) - 1)
    pts = d[i] + ((s - arc[i]) / lengths[i])[:, None] * seg[i]
    a, b = straight_ecef[:-1], np.diff(straight_ecef, axis=0)
    t = np.clip(np.einsum("pij,ij->pi", pts[:, None, :] - a[None], b) / np.einsum("ij,ij->i", b, b), 0.0, 1.0)
    dist = np.linalg.norm(a[None] + t[..., None] * b[None] - pts[:, None, :], axis=2).min(axis=1)
    apart = np.nonzero(dist >= gauge_m)[0]
    return float(s[apart[0]]) if len(apart) else None


def _feature(kind: str, coords: Any, props: dict[str, Any]) -> dict[str, Any]:
    return {"type": "Feature", "geometry": {"type": kind, "coordinates": coords}, "properties": props}


def _edge_shape_ok(e: Edge) -> bool:
    p, k = e.points_llh, e.km
    return (isinstance(p, np.ndarray) and p.ndim == 2 and p.shape[1] == 3 and len(p) >= 2
            and bool(np.all(np.isfinite(p))) and isinstance(k, np.ndarray) and k.shape == (len(p),)
            and bool(np.all(np.isfinite(k))))


def _unique(what: str, items: Iterable[Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for it in items:
        if it.id in out:
            raise TopologyError(f"{what} {it.id}", "duplicate id")
        out[it.id] = it
    return out


def _check_direction(direction: str) -> None:
    if direction not in DIRECTIONS:
        raise TopologyError("direction", f"{direction!r} is not up or down")
