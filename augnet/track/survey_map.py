"""The track map built from a survey run: topology from the layout description, geometry from the survey.

Input: a layout description (`Topology`: nodes, edges with their chainage range, turnouts; its geometry is
not used) and a survey record (`augnet-survey/1`: per run the edge it ran, the direction, the positions of
the track centre line at rail level with their sigmas).  Per edge:

1. **Parameter**: the points in begin -> end order; a first arc length from the running median of 5
   positions (an isolated outlier does not bend it), later the arc length of each point's foot on the fit.
2. **Fit**: a uniform cubic B-spline in arc length per ENU coordinate (`KNOT_SPACING_M`), weighted least
   squares with a small third-difference penalty (`PENALTY`): curvature-continuous (C2), and across a gap
   the curvature carries on instead of the curve cutting the chord.
3. **Outliers**: points whose horizontal residual exceeds `OUTLIER_K` x max(robust sigma, reported sigma)
   are dropped and the fit repeated (`FIT_ITERATIONS`).  Gaps over `GAP_REPORT_M` are reported; a gap over
   `MAX_GAP_M` is refused naming the edge (the map there would be a guess).
4. **Reduce**: the fit sampled every `SAMPLE_M`, reduced by Douglas-Peucker to the vertices within
   `VERTEX_TOLERANCE_M` of it (the map is chords between vertices, docs/track-topology.md).

Nodes are the mean of the fitted edge ends meeting there, each edge end moved onto its node; chainage is
linear in arc length between the description's km at the ends; frogs are computed from the built geometry.
`verify` measures the built map against an independent survey run: the horizontal distance of its
points (outliers dropped by the same rule) to their edge, 95 % and max: the map's accuracy figure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation, geodetic_deg_to_ecef
from augnet.track.topology import (Edge, Node, Topology, TopologyError, Turnout, frog_distance_m)

SURVEY_FORMAT = "augnet-survey/1"
# B-spline knot spacing [m]: a cubic spline's error h^4 f''''/384 is < 1 um for a 1:13 crossover's reverse
# curve (f'''' ~ 1.3e-4 /m^3) at 5 m, and ~5 survey points (1 m apart) per knot interval keep it determined.
KNOT_SPACING_M = 5.0
# Third-difference penalty weight [1/m^2 per (m)^2 of coefficient difference]: ~1e-4 of one 1 cm point's
# weight (1e4 /m^2), so it only acts where there are no points (gaps, ends).
PENALTY = 1.0
OUTLIER_K = 5.0  # residual / sigma beyond which a point is an outlier
FIT_ITERATIONS = 4
GAP_REPORT_M = 10.0  # gaps longer than this are listed in the build report
MAX_GAP_M = 100.0  # a longer gap is refused: the spline across it is not a survey
SAMPLE_M = 0.5  # dense sampling of the fit before reduction
VERTEX_TOLERANCE_M = 0.003  # chords within 3 mm of the fitted curve (railway.md: asset mapping 0.2 m)
MIN_POINTS = 8  # fewer points than this cannot fit an edge


@dataclass
class EdgeFit:
    edge: str
    points: int
    outliers: int
    gaps_m: list[tuple[float, float]]  # (from, to) arc length of gaps over GAP_REPORT_M
    rms_h_m: float  # horizontal residual RMS of the inliers
    vertices: int


@dataclass
class BuiltMap:
    topology: Topology
    fits: dict[str, EdgeFit] = field(default_factory=dict)
    accuracy: dict | None = None  # set by `verify`


def _frame(topology: Topology):
    pts = np.concatenate([e.points_llh for e in topology.edges.values()])
    lat0, lon0 = float(np.mean(pts[:, 0])), float(np.mean(pts[:, 1]))
    origin = geodetic_deg_to_ecef(lat0, lon0, float(np.mean(pts[:, 2])))
    return origin, enu_rotation(math.radians(lat0), math.radians(lon0))


def _to_enu(llh, origin, rot) -> np.ndarray:
    llh = np.asarray(llh, float)
    ecef = geodetic_deg_to_ecef(llh[:, 0], llh[:, 1], llh[:, 2])
    return (ecef - origin) @ rot.T


def _to_llh(enu, origin, rot) -> np.ndarray:
    ecef = np.asarray(enu) @ rot + origin
    g = ecef_to_geodetic(ecef)
    return np.column_stack([np.degrees(g[:, 0]), np.degrees(g[:, 1]), g[:, 2]])


def _basis(s: np.ndarray, length: float, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Uniform cubic B-spline basis on [0, length] with m intervals (m + 3 functions): for each s the index
    of its first non-zero function and the 4 values (len(s), 4)."""
    h = length / m
    t = np.clip(np.asarray(s, float) / h, 0.0, m)
    j = np.minimum(np.floor(t).astype(int), m - 1)
    u = t - j
    vals = np.column_stack([(1 - u) ** 3 / 6, (3 * u ** 3 - 6 * u ** 2 + 4) / 6,
                            (-3 * u ** 3 + 3 * u ** 2 + 3 * u + 1) / 6, u ** 3 / 6])
    return j, vals


def fit_curve(s: np.ndarray, xyz: np.ndarray, w: np.ndarray, length: float):
    """Weighted penalised cubic B-spline fit of xyz (n, 3) against arc length s; returns f(s') -> (n', 3)."""
    m = max(int(math.ceil(length / KNOT_SPACING_M)), 1)
    j, v = _basis(s, length, m)
    n_c = m + 3
    a = np.zeros((n_c, n_c))
    rhs = np.zeros((n_c, 3))
    for k in range(4):
        np.add.at(rhs, j + k, v[:, k:k + 1] * w[:, None] * xyz)
        for l in range(4):
            np.add.at(a, (j + k, j + l), w * v[:, k] * v[:, l])
    d3 = np.diff(np.eye(n_c), 3, axis=0)
    coef = np.linalg.solve(a + PENALTY * d3.T @ d3, rhs)

    def f(q):
        jq, vq = _basis(q, length, m)
        return sum(vq[:, k:k + 1] * coef[jq + k] for k in range(4))
    return f


def _nearest_on_polyline(curve: np.ndarray, pts: np.ndarray, chunk: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """(horizontal distance, segment index + fraction) of each point to a polyline (every segment tried)."""
    a, d = curve[:-1, :2], np.diff(curve[:, :2], axis=0)
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-12)
    dist = np.empty(len(pts))
    pos = np.empty(len(pts))
    for c in range(0, len(pts), chunk):
        p = pts[c:c + chunk, None, :2]
        t = np.clip(np.einsum("pij,ij->pi", p - a[None], d) / dd, 0.0, 1.0)
        r = np.linalg.norm(a[None] + t[..., None] * d[None] - p, axis=2)
        k = np.argmin(r, axis=1)
        dist[c:c + chunk] = r[np.arange(len(k)), k]
        pos[c:c + chunk] = k + t[np.arange(len(k)), k]
    return dist, pos


def _nearest_near(curve_s: np.ndarray, curve: np.ndarray, pts: np.ndarray, s_guess: np.ndarray,
                  window: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """(horizontal distance, arc length of the foot) of each point to a densely sampled curve, searching the
    segments within `window` samples of its guessed arc length."""
    ds = curve_s[1] - curve_s[0]
    k0 = np.clip(np.round(s_guess / ds).astype(int), 0, len(curve) - 2)
    idx = np.clip(k0[:, None] + np.arange(-window, window + 1)[None], 0, len(curve) - 2)
    a = curve[idx, :2]
    d = curve[idx + 1, :2] - a
    p = pts[:, None, :2]
    t = np.clip(np.einsum("pij,pij->pi", p - a, d) / np.maximum(np.einsum("pij,pij->pi", d, d), 1e-12), 0.0, 1.0)
    r = np.linalg.norm(a + t[..., None] * d - p, axis=2)
    k = np.argmin(r, axis=1)
    rows = np.arange(len(pts))
    return r[rows, k], curve_s[idx[rows, k]] + t[rows, k] * ds


def _horizontal_residual(curve: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return _nearest_on_polyline(curve, pts)[0]


def fit_edge(edge_id: str, pts: np.ndarray, sigma_h_m: float, sigma_v_m: float) -> tuple[np.ndarray, EdgeFit]:
    """Fit one edge's survey points (ENU, begin -> end order): (reduced vertices ENU, report)."""
    n = len(pts)
    if n < MIN_POINTS:
        raise TopologyError(f"edge {edge_id}", f"survey has {n} points, at least {MIN_POINTS} needed")
    # symmetric windows, shrinking at the ends (the end points keep their own place)
    med = np.array([np.median(pts[i - r:i + r + 1], axis=0) for i in range(n) for r in [min(2, i, n - 1 - i)]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(med[:, :2], axis=0), axis=1))])
    inlier = np.ones(n, bool)
    w_h = 1.0 / max(sigma_h_m, 1e-3) ** 2
    curve = None
    for it in range(FIT_ITERATIONS):
        s = s - s[inlier].min()
        length = float(s[inlier].max())
        if length <= 0:
            raise TopologyError(f"edge {edge_id}", "survey points do not advance along the track")
        f = fit_curve(s[inlier], pts[inlier], np.full(int(inlier.sum()), w_h), length)
        cs = np.linspace(0.0, length, max(int(math.ceil(length / SAMPLE_M)), 2) + 1)
        curve = f(cs)
        res, foot = _nearest_near(cs, curve, pts, s)
        # the next fit's parameter: the arc length of each foot along this curve
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
        s = np.interp(foot, cs, arc)
        robust = 1.4826 * float(np.median(res[inlier]))  # |2-D residual| median ~ 1.18 sigma: conservative
        new = res <= OUTLIER_K * max(robust, sigma_h_m)
        if it > 0 and np.array_equal(new, inlier):
            break  # (the first pass also refines the parameter: always at least two)
        inlier = new
    s_in = np.sort(s[inlier])
    gaps = np.diff(s_in)
    big = [(float(s_in[i]), float(s_in[i + 1])) for i in np.flatnonzero(gaps > GAP_REPORT_M)]
    if any(b - a > MAX_GAP_M for a, b in big):
        a, b = max(big, key=lambda g: g[1] - g[0])
        raise TopologyError(f"edge {edge_id}", f"survey gap of {b - a:.0f} m ({a:.0f}-{b:.0f} m from its begin) "
                                              f"exceeds {MAX_GAP_M:.0f} m")
    verts = douglas_peucker(curve, VERTEX_TOLERANCE_M)
    rms = float(np.sqrt(np.mean(res[inlier] ** 2)))
    return verts, EdgeFit(edge_id, n, int((~inlier).sum()), big, rms, len(verts))


def douglas_peucker(p: np.ndarray, tol: float) -> np.ndarray:
    """The vertices of polyline p (n, 3) such that every point of p is within tol of the reduced chords."""
    keep = np.zeros(len(p), bool)
    keep[[0, -1]] = True
    stack = [(0, len(p) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg = p[b] - p[a]
        q = p[a + 1:b] - p[a]
        t = np.clip(q @ seg / max(float(seg @ seg), 1e-12), 0.0, 1.0)
        d = np.linalg.norm(q - t[:, None] * seg, axis=1)
        k = int(np.argmax(d))
        if d[k] > tol:
            i = a + 1 + k
            keep[i] = True
            stack.extend([(a, i), (i, b)])
    return p[keep]


def _check_survey(survey) -> None:
    if not isinstance(survey, dict) or survey.get("format") != SURVEY_FORMAT:
        got = survey.get("format") if isinstance(survey, dict) else type(survey).__name__
        raise TopologyError("survey", f"format {got!r}, expected {SURVEY_FORMAT!r}")


def _runs_by_edge(survey, description: Topology, origin, rot) -> dict[str, list[tuple[np.ndarray, float, float]]]:
    out: dict[str, list] = {}
    for run in survey["runs"]:
        eid = str(run["edge"])
        if eid not in description.edges:
            raise TopologyError(f"survey run {run.get('id')}", f"edge {eid} is not in the layout description")
        pts = _to_enu(run["points"], origin, rot) if len(run["points"]) else np.zeros((0, 3))
        if run["direction"] == "down":
            pts = pts[::-1]
        out.setdefault(eid, []).append((pts, float(run["sigma_h_m"]), float(run["sigma_v_m"])))
    return out


def build_map(description: Topology, survey: dict, name: str | None = None) -> BuiltMap:
    """The map: `description`'s topology (nodes, edges' km ranges, turnouts, points of interest, section
    boundaries) with every edge's geometry fitted to `survey`; an edge the survey did not run is refused."""
    _check_survey(survey)
    origin, rot = _frame(description)
    runs = _runs_by_edge(survey, description, origin, rot)
    fits, verts = {}, {}
    for eid in description.edges:
        if eid not in runs:
            raise TopologyError(f"edge {eid}", "not in the survey: its geometry is unknown")
        pts = np.concatenate([r[0] for r in runs[eid]])
        v, fit = fit_edge(eid, pts, max(r[1] for r in runs[eid]), max(r[2] for r in runs[eid]))
        verts[eid], fits[eid] = v, fit
    # nodes: the mean of the fitted ends meeting there; every edge end moved onto its node
    ends: dict[str, list[np.ndarray]] = {n: [] for n in description.nodes}
    for e in description.edges.values():
        ends[e.begin].append(verts[e.id][0])
        ends[e.end].append(verts[e.id][-1])
    node_enu = {n: np.mean(p, axis=0) for n, p in ends.items()}
    nodes = [Node(n.id, n.kind, tuple(float(x) for x in _to_llh(node_enu[n.id][None], origin, rot)[0]))
             for n in description.nodes.values()]
    edges = []
    for e in description.edges.values():
        v = verts[e.id].copy()
        v[0], v[-1] = node_enu[e.begin], node_enu[e.end]
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(v, axis=0), axis=1))])
        km = e.km_begin + (e.km_end - e.km_begin) * arc / arc[-1]
        edges.append(Edge(e.id, e.track, e.kind, e.begin, e.end, _to_llh(v, origin, rot), km, e.station, e.name))
    # frogs from the built geometry (the straight leg against the diverging leg, both from the switch)
    built_edges = {e.id: e for e in edges}
    turnouts = []
    for t in description.turnouts.values():
        def ecef(eid):
            p = built_edges[eid].points_llh
            x = geodetic_deg_to_ecef(p[:, 0], p[:, 1], p[:, 2])
            return x if built_edges[eid].begin == t.id else x[::-1]
        frog = frog_distance_m(ecef(t.straight), ecef(t.diverging))
        turnouts.append(Turnout(t.id, t.toe, t.straight, t.diverging, t.course,
                                frog if frog is not None else t.frog_m, t.name))
    topo = Topology(name or f"{description.name} (built from survey {survey.get('seed', '')})", nodes, edges,
                    turnouts, description.points.values(), description.sections.values())
    return BuiltMap(topo, fits)


def verify(built: BuiltMap, survey: dict) -> dict:
    """The built map's accuracy against an independent survey run: horizontal distance of each of its
    points to the edge it ran (outliers dropped by the builder's rule), 95 % and max [m]."""
    _check_survey(survey)
    topo = built.topology
    origin, rot = _frame(topo)
    runs = _runs_by_edge(survey, topo, origin, rot)
    dist, dropped, total = [], 0, 0
    for eid, rs in runs.items():
        p = topo.edges[eid].points_llh
        curve = _to_enu(p, origin, rot)
        for pts, sig_h, _ in rs:
            if not len(pts):
                continue
            d = _horizontal_residual(curve, pts)
            robust = 1.4826 * float(np.median(d))
            ok = d <= OUTLIER_K * max(robust, sig_h)
            dist.append(d[ok])
            dropped += int((~ok).sum())
            total += len(d)
    d = np.concatenate(dist) if dist else np.zeros(0)
    acc = {"horizontal_95_m": float(np.percentile(d, 95)) if len(d) else math.nan,
           "horizontal_max_m": float(np.max(d)) if len(d) else math.nan,
           "points": int(len(d)), "outliers_dropped": dropped, "points_total": total,
           "verified_against": f"survey seed {survey.get('seed', '')}"}
    built.accuracy = acc
    built.topology.accuracy = acc  # the map carries its accuracy figure (written with it)
    return acc


def map_error_m(built: Topology, truth: Topology, step_m: float = 1.0) -> np.ndarray:
    """Horizontal distance [m] of points every `step_m` along each truth edge to the same edge of the built
    map (evaluation: the truth map is the simulator's)."""
    origin, rot = _frame(truth)
    out = []
    for eid, e in truth.edges.items():
        tp = _to_enu(e.points_llh, origin, rot)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(tp, axis=0), axis=1))])
        s = np.arange(0.0, arc[-1], step_m)
        q = np.column_stack([np.interp(s, arc, tp[:, k]) for k in range(3)])
        out.append(_horizontal_residual(_to_enu(built.edges[eid].points_llh, origin, rot), q))
    return np.concatenate(out)
