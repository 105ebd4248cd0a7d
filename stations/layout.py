"""A track layout the simulated trains run on: the truth geometry of a line with turnouts, and routes over it.

The layout file is an `augnet-topology/1` JSON file (docs/track-topology.md): the line as designed (nodes,
edges with their chainage, turnouts).  This module reads it itself (the simulated world may import only
`augnet.gnss`; the estimator reads the same file with `augnet.track.topology_file`, independently) and
builds the track **as built** from it, which is the truth:

* every edge is a chain of quintic Hermite pieces through its design vertices, with zero second
  derivative at every vertex: the curvature is continuous along the edge and zero at its ends;
* the tangent at an edge end is the direction the neighbouring track continues in: at a switch the toe's
  (so a diverging leg leaves its switch tangentially, with zero curvature, and the through route is
  curvature-continuous through the turnout); at a joint the longer of the two adjoining design segments';
  elsewhere the edge's own end segment.  A design chord between two switches of a crossover becomes the
  reverse curve a real crossover is (1:13 over 60 m, 4.6 m: minimum radius ~136 m);
* sampled every `SAMPLE_M` (chord sagitta 0.9 mm at R = 136 m); a point on a track is linear between
  those vertices, so truth positions lie on the exported truth polyline exactly.

The difference between the design chords and the as-built curves (up to ~0.4 m on a crossover) is why the
estimator's map is built from a survey run (stations/survey.py, augnet/track/survey_map.py), not from the
design file.

A train's route is a list of edges in travel order; its speed limit along the route is the line speed and,
on curves, sqrt(`LATERAL_ACCEL_M_S2` * R): turnouts and crossovers are passed at their own speed.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from pyproj import Transformer

from stations.scenario import ScenarioError

FORMAT = "augnet-topology/1"  # same tag as augnet.track.topology.FORMAT (stations may not import augnet.track)
# Truth sampling along every edge [m]: sagitta step^2 / (8 R) = 0.9 mm at the crossover's ~136 m radius.
SAMPLE_M = 1.0
# Uncompensated lateral acceleration allowed through turnouts [m/s^2]: 0.65 m/s^2, the usual limit for
# the diverging track of a turnout (EN 13803-2 / DB Ril 800.0110 normal value).
LATERAL_ACCEL_M_S2 = 0.65
# Built-in layouts (stations/layouts/<name>.json).
BUILTIN_LAYOUTS = ("alpha-beta",)
NODE_DEGREE = {"joint": 2, "switch": 3, "buffer_stop": 1, "open_end": 1}
# Standard gauge (UIC, 1435 mm): the frog is where the legs' centre lines are one gauge apart (as
# augnet.track.topology.STANDARD_GAUGE_M; located here on the 1 m truth samples, to the next sample).
STANDARD_GAUGE_M = 1.435


class LayoutError(ScenarioError):
    """A layout file or route that cannot be used; names the element (a scenario error: the CLIs report it)."""


@dataclass(frozen=True)
class LayoutEdge:
    id: str
    track: str
    kind: str
    begin: str
    end: str
    design_xy: np.ndarray  # (n, 2) design vertices in the layout plane [m]
    design_km: np.ndarray  # (n,)
    h: np.ndarray  # (n,) design heights [m]
    xy: np.ndarray = None  # (m, 2) truth vertices [m]
    s_m: np.ndarray = None  # (m,) arc length from the begin node [m]
    km: np.ndarray = None  # (m,) chainage of each truth vertex [km]
    z: np.ndarray = None  # (m,) ellipsoidal height [m]

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])


def layout_path(name_or_path: str | Path) -> Path:
    """A built-in layout by name, or a file path."""
    if str(name_or_path) in BUILTIN_LAYOUTS:
        return Path(str(resources.files("stations.layouts").joinpath(f"{name_or_path}.json")))
    return Path(name_or_path)


class Layout:
    """The truth geometry of a layout file's tracks, in a local transverse Mercator plane."""

    def __init__(self, data: dict):
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise LayoutError(f"layout: format {data.get('format') if isinstance(data, dict) else None!r}, "
                              f"expected {FORMAT!r}")
        self.name = str(data.get("name", ""))
        try:
            self.node_kind = {str(n["id"]): str(n["kind"]) for n in data["nodes"]}
            raw_edges = list(data["edges"])
            self.turnouts = {str(t["id"]): {k: str(t[k]) for k in ("toe", "straight", "diverging")}
                             for t in data.get("turnouts", [])}
        except (KeyError, TypeError) as exc:
            raise LayoutError(f"layout {self.name}: malformed ({exc})") from None
        pts = np.concatenate([np.asarray(e["points"], float) for e in raw_edges])
        lat0, lon0 = float(pts[:, 0].mean()), float(pts[:, 1].mean())
        proj = f"+proj=tmerc +lat_0={lat0:.9f} +lon_0={lon0:.9f} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
        self._to_plane = Transformer.from_crs("EPSG:4326", proj, always_xy=True)
        self._from_plane = Transformer.from_crs(proj, "EPSG:4326", always_xy=True)
        self._to_ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
        self.edges: dict[str, LayoutEdge] = {}
        for e in raw_edges:
            p = np.asarray(e["points"], float)
            km = np.asarray(e["km"], float)
            eid = str(e["id"])
            if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2 or km.shape != (len(p),) or np.any(np.diff(km) <= 0):
                raise LayoutError(f"layout {self.name}: edge {eid}: points/km malformed or km not increasing")
            for node in (e["begin"], e["end"]):
                if str(node) not in self.node_kind:
                    raise LayoutError(f"layout {self.name}: edge {eid}: node {node} does not exist")
            x, y = self._to_plane.transform(p[:, 1], p[:, 0])
            self.edges[eid] = LayoutEdge(eid, str(e["track"]), str(e["kind"]), str(e["begin"]), str(e["end"]),
                                         np.column_stack([x, y]), km, p[:, 2])
        self.ends: dict[str, list[tuple[str, str]]] = {n: [] for n in self.node_kind}
        for e in self.edges.values():
            self.ends[e.begin].append((e.id, "begin"))
            self.ends[e.end].append((e.id, "end"))
        for n, kind in self.node_kind.items():
            if len(self.ends[n]) != NODE_DEGREE.get(kind, -1):
                raise LayoutError(f"layout {self.name}: node {n} ({kind}) joins {len(self.ends[n])} edge ends")
            if kind == "switch" and n not in self.turnouts:
                raise LayoutError(f"layout {self.name}: switch {n} has no turnout")
        for eid in list(self.edges):
            self.edges[eid] = self._as_built(self.edges[eid])

    @classmethod
    def load(cls, name_or_path: str | Path) -> "Layout":
        path = layout_path(name_or_path)
        try:
            return cls(json.loads(path.read_text(encoding="utf-8")))
        except (OSError, json.JSONDecodeError) as exc:
            raise LayoutError(f"layout {name_or_path}: cannot read: {exc}") from None

    # -- truth geometry ----------------------------------------------------------------------------
    def _design_direction(self, eid: str, side: str) -> np.ndarray:
        """Unit design direction at an edge end, pointing away from the node into the edge."""
        xy = self.edges[eid].design_xy
        d = xy[1] - xy[0] if side == "begin" else xy[-2] - xy[-1]
        return d / np.linalg.norm(d)

    def _design_segment_m(self, eid: str, side: str) -> float:
        xy = self.edges[eid].design_xy
        return float(np.linalg.norm(xy[1] - xy[0] if side == "begin" else xy[-2] - xy[-1]))

    def _end_tangent(self, e: LayoutEdge, side: str) -> np.ndarray:
        """Unit tangent at an edge end, pointing into the edge (see the module docstring)."""
        node = e.begin if side == "begin" else e.end
        kind = self.node_kind[node]
        own = self._design_direction(e.id, side)
        others = [(x, s) for x, s in self.ends[node] if (x, s) != (e.id, side)]
        if kind == "switch":
            t = self.turnouts[node]
            toe_side = next(s for x, s in self.ends[node] if x == t["toe"])
            into_toe = self._design_direction(t["toe"], toe_side)
            # a leg continues the toe (travel toe -> leg); the toe itself continues away from the legs
            return into_toe if e.id == t["toe"] else -into_toe
        if kind == "joint" and others:
            x, s = others[0]
            if self._design_segment_m(x, s) > self._design_segment_m(e.id, side):
                return -self._design_direction(x, s)
        return own

    def _as_built(self, e: LayoutEdge) -> LayoutEdge:
        P = e.design_xy
        n = len(P)
        tang = np.zeros((n, 2))
        tang[0] = self._end_tangent(e, "begin")
        tang[-1] = -self._end_tangent(e, "end")
        for i in range(1, n - 1):
            a = (P[i] - P[i - 1]) / np.linalg.norm(P[i] - P[i - 1])
            b = (P[i + 1] - P[i]) / np.linalg.norm(P[i + 1] - P[i])
            tang[i] = (a + b) / np.linalg.norm(a + b)
        xy_parts, km_parts, h_parts = [P[:1]], [e.design_km[:1]], [e.h[:1]]
        for i in range(n - 1):
            chord = float(np.linalg.norm(P[i + 1] - P[i]))
            m = max(int(math.ceil(chord / SAMPLE_M)), 2)
            u = np.arange(1, m + 1) / m
            xy_parts.append(quintic_hermite(P[i], P[i + 1], tang[i] * chord, tang[i + 1] * chord, u))
            km_parts.append(e.design_km[i] + (e.design_km[i + 1] - e.design_km[i]) * u)  # re-spaced below
            h_parts.append(e.h[i] + (e.h[i + 1] - e.h[i]) * u)
        xy = np.concatenate(xy_parts)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
        # chainage linear in arc length within each design segment
        knots = np.concatenate([[0], np.cumsum([len(p) for p in xy_parts[1:]])])
        km = np.empty(len(xy))
        for i in range(n - 1):
            a, b = knots[i], knots[i + 1]
            km[a:b + 1] = e.design_km[i] + (e.design_km[i + 1] - e.design_km[i]) * (s[a:b + 1] - s[a]) / (s[b] - s[a])
        return LayoutEdge(e.id, e.track, e.kind, e.begin, e.end, e.design_xy, e.design_km, e.h, xy, s, km,
                          np.concatenate(h_parts))

    # -- conversions --------------------------------------------------------------------------------
    def plane_to_geodetic(self, xy: np.ndarray, h: np.ndarray) -> np.ndarray:
        lon, lat = self._from_plane.transform(np.asarray(xy)[..., 0], np.asarray(xy)[..., 1])
        return np.stack([np.asarray(lat), np.asarray(lon), np.asarray(h, float)], axis=-1)

    def plane_to_ecef(self, xy: np.ndarray, h: np.ndarray) -> np.ndarray:
        g = self.plane_to_geodetic(xy, h)
        x, y, z = self._to_ecef.transform(g[..., 1], g[..., 0], g[..., 2])
        return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1)

    def geodetic_to_plane(self, lat_deg, lon_deg) -> np.ndarray:
        x, y = self._to_plane.transform(np.asarray(lon_deg, float), np.asarray(lat_deg, float))
        return np.stack([np.asarray(x), np.asarray(y)], axis=-1)

    # -- movement --------------------------------------------------------------------------------------
    def next_edges(self, eid: str, direction: str) -> list[tuple[str, str]]:
        """(edge, direction) a train may run onto past the node ahead (toe <-> leg through a switch)."""
        e = self.edges[eid]
        node = e.end if direction == "up" else e.begin
        arriving = "end" if direction == "up" else "begin"
        others = [(x, s) for x, s in self.ends[node] if (x, s) != (eid, arriving)]
        if self.node_kind[node] == "switch":
            t = self.turnouts[node]
            allowed = {t["straight"], t["diverging"]} if eid == t["toe"] else {t["toe"]}
            others = [(x, s) for x, s in others if x in allowed]
        return [(x, "up" if s == "begin" else "down") for x, s in others]

    def route(self, edges: list[str], direction: int, start_km: float) -> "Route":
        """The route over `edges` in travel order, first edge run `direction` (+1: up the chainage) from
        `start_km`; every step must follow the movement rule and keep the direction (no reversal)."""
        if not edges:
            raise LayoutError("route: empty")
        for x in edges:
            if x not in self.edges:
                raise LayoutError(f"route: edge {x} is not in layout {self.name}")
        dirs = ["up" if direction > 0 else "down"]
        for a, b in zip(edges, edges[1:]):
            nxt = dict(self.next_edges(a, dirs[-1]))
            if b not in nxt:
                raise LayoutError(f"route: {b} does not follow {a} ({dirs[-1]}) in layout {self.name}")
            dirs.append(nxt[b])
        if any(d != dirs[0] for d in dirs):
            raise LayoutError(f"route {edges}: reverses its direction of travel (not supported)")
        first = self.edges[edges[0]]
        if not first.km[0] <= start_km <= first.km[-1]:
            raise LayoutError(f"route: start_km {start_km} outside edge {first.id} "
                              f"({first.km[0]:.4f}-{first.km[-1]:.4f} km)")
        xy, z, km, eidx, along = [], [], [], [], []
        for i, (x, d) in enumerate(zip(edges, dirs)):
            e = self.edges[x]
            sl = slice(None) if d == "up" else slice(None, None, -1)
            exy, ez, ekm, es = e.xy[sl], e.z[sl], e.km[sl], e.s_m[sl]
            if i == 0:
                s0 = float(np.interp(start_km, e.km, e.s_m))
                keep = es > s0 if d == "up" else es < s0
                p0 = np.array([np.interp(s0, e.s_m, e.xy[:, 0]), np.interp(s0, e.s_m, e.xy[:, 1])])
                exy = np.vstack([p0, exy[keep]])
                ez = np.r_[np.interp(s0, e.s_m, e.z), ez[keep]]
                ekm = np.r_[start_km, ekm[keep]]
                es = np.r_[s0, es[keep]]
            else:
                exy, ez, ekm, es = exy[1:], ez[1:], ekm[1:], es[1:]  # the joining node once
            xy.append(exy)
            z.append(ez)
            km.append(ekm)
            along.append(es)
            eidx.append(np.full(len(es), i))
        xy = np.concatenate(xy)
        u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
        return Route(tuple(edges), tuple(dirs), xy, np.concatenate(z), np.concatenate(km), u,
                     np.concatenate(eidx), np.concatenate(along))

    def truth_topology_dict(self) -> dict:
        """The as-built layout as an augnet-topology/1 dictionary (truth: for the evaluation and, like
        stations/trackmap_export.py, for the runner's onboard track database of a truth-map run)."""
        nodes = []
        for n, kind in self.node_kind.items():
            eid, side = self.ends[n][0]
            e = self.edges[eid]
            i = 0 if side == "begin" else -1
            nodes.append({"id": n, "kind": kind, "position": self.plane_to_geodetic(e.xy[i], e.z[i]).tolist()})
        edges = [{"id": e.id, "track": e.track, "kind": e.kind, "begin": e.begin, "end": e.end,
                  "points": np.round(self.plane_to_geodetic(e.xy, e.z), 10).tolist(),
                  "km": np.round(e.km, 7).tolist()} for e in self.edges.values()]
        turnouts = [dict(id=t, course=self._course(t), frog_m=self.frog_m(t), **legs)
                    for t, legs in self.turnouts.items()]
        return {"format": FORMAT, "name": f"{self.name} (as built, truth)", "nodes": nodes, "edges": edges,
                "turnouts": turnouts}

    def _course(self, sw: str) -> str:
        t = self.turnouts[sw]
        toe_side = next(s for x, s in self.ends[sw] if x == t["toe"])
        fwd = -self._design_direction(t["toe"], toe_side)
        div_side = next(s for x, s in self.ends[sw] if x == t["diverging"])
        d = self._design_direction(t["diverging"], div_side)
        return "left" if fwd[0] * d[1] - fwd[1] * d[0] > 0 else "right"

    def frog_m(self, sw: str, gauge_m: float = STANDARD_GAUGE_M) -> float:
        """Distance along the as-built diverging leg to where it is one standard gauge from the straight."""
        t = self.turnouts[sw]
        div, st = self.edges[t["diverging"]], self.edges[t["straight"]]
        side = next(s for x, s in self.ends[sw] if x == t["diverging"])
        xy, s = (div.xy, div.s_m) if side == "begin" else (div.xy[::-1], div.s_m[-1] - div.s_m[::-1])
        a, b = st.xy[:-1], np.diff(st.xy, axis=0)
        for p, sp in zip(xy, s):
            w = np.clip(np.einsum("ij,ij->i", p - a, b) / np.einsum("ij,ij->i", b, b), 0.0, 1.0)
            if np.min(np.linalg.norm(a + w[:, None] * b - p, axis=1)) >= gauge_m:
                return float(sp)
        return float(s[-1])


@dataclass(frozen=True)
class Route:
    """A route's truth polyline: vertices in travel order with the edge and chainage of each."""

    edges: tuple[str, ...]
    directions: tuple[str, ...]
    xy: np.ndarray  # (n, 2) plane [m]
    z: np.ndarray  # (n,) rail-level ellipsoidal height [m]
    km: np.ndarray  # (n,) chainage [km]
    u_m: np.ndarray  # (n,) distance along the route from the start [m]
    edge_index: np.ndarray  # (n,) index into `edges` of the edge each vertex lies on
    edge_along_m: np.ndarray  # (n,) arc length from that edge's begin node [m]

    @property
    def length_m(self) -> float:
        return float(self.u_m[-1])

    def curvature_1_m(self) -> np.ndarray:
        """Curvature at each vertex [1/m] (circle through it and its neighbours; 0 at the ends)."""
        p = self.xy
        k = np.zeros(len(p))
        if len(p) >= 3:
            a, b, c = p[:-2], p[1:-1], p[2:]
            ab, bc, ca = (np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1))
            cross = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
            k[1:-1] = 2.0 * cross / np.maximum(ab * bc * ca, 1e-12)
        return k

    def speed_limit_m_s(self, u_m: np.ndarray, line_speed_m_s: float) -> np.ndarray:
        """Line speed, and sqrt(LATERAL_ACCEL_M_S2 * R) on curves, at route distances `u_m` (the lowest
        limit of the vertices within 5 m, so a short curve is not stepped over)."""
        k = self.curvature_1_m()
        lim = np.minimum(line_speed_m_s, np.sqrt(LATERAL_ACCEL_M_S2 / np.maximum(k, 1e-12)))
        out = np.empty(len(u_m))
        lo = np.searchsorted(self.u_m, np.asarray(u_m) - 5.0)
        hi = np.searchsorted(self.u_m, np.asarray(u_m) + 5.0, side="right")
        for i, (a, b) in enumerate(zip(lo, hi)):
            out[i] = lim[a:max(b, a + 1)].min() if a < len(lim) else lim[-1]
        return out

    def at(self, u_m) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(xy, z, km, edge index, edge arc length) at route distances `u_m` (linear between vertices)."""
        u = np.clip(np.asarray(u_m, float), 0.0, self.length_m)
        i = np.clip(np.searchsorted(self.u_m, u, side="right") - 1, 0, len(self.u_m) - 2)
        w = (u - self.u_m[i]) / (self.u_m[i + 1] - self.u_m[i])
        xy = self.xy[i] * (1 - w)[:, None] + self.xy[i + 1] * w[:, None]
        z = self.z[i] * (1 - w) + self.z[i + 1] * w
        km = self.km[i] * (1 - w) + self.km[i + 1] * w
        # the edge of the segment's far vertex (a segment ending at a node belongs to the edge it ends on)
        ei = self.edge_index[i + 1]
        same = self.edge_index[i] == ei
        along = np.where(same, self.edge_along_m[i] * (1 - w) + self.edge_along_m[i + 1] * w,
                         self.edge_along_m[i + 1] + 0.0)
        # the first vertex of a new edge is one segment past the node: interpolate from the node's end
        start_of_edge = ~same
        if np.any(start_of_edge):
            d = np.array([1.0 if self.directions[j] == "up" else -1.0 for j in ei[start_of_edge]])
            seg = self.u_m[i + 1][start_of_edge] - u[start_of_edge]
            along[start_of_edge] = self.edge_along_m[i + 1][start_of_edge] - d * seg
        return xy, z, km, ei, along


def quintic_hermite(p0, p1, m0, m1, u) -> np.ndarray:
    """Points of the quintic Hermite curve from p0 to p1 with end derivatives m0, m1 and zero second
    derivatives at both ends, at parameters u in [0, 1]."""
    u = np.asarray(u, float)[:, None]
    u2, u3, u4, u5 = u * u, u ** 3, u ** 4, u ** 5
    h0 = 1 - 10 * u3 + 15 * u4 - 6 * u5
    h1 = u - 6 * u3 + 8 * u4 - 3 * u5
    h4 = -4 * u3 + 7 * u4 - 3 * u5
    h5 = 10 * u3 - 15 * u4 + 6 * u5
    return h0 * p0 + h1 * m0 + h4 * m1 + h5 * p1
