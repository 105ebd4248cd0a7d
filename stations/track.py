"""Track geometry: a railway line from waypoints, with curves, grades, parallel tracks and blockages.

The line is built in a local transverse Mercator plane centred on the line (scale error < 2e-4 within
150 km of the centre: kilometre posts are plane distances, which is what a simulated line needs):

* the centre line is the waypoint polyline with every interior corner rounded by a circular arc
  (`curve_radius_m`, reduced where two corners are too close for it), the arcs sampled every
  `ARC_STEP_M` (chord sagitta 2.5 mm at R = 5 km);
* heights are linear in chainage between waypoints (constant grade per section);
* main-line tracks are offsets of the centre line, `track_spacing_m` apart, track 1 on the left
  looking towards increasing km; station areas add loop tracks further out;
* each track is a polyline of (E, N, h) vertices; a point on a track at chainage s is the linear
  interpolation between its vertices, so truth positions lie on the polyline exactly.

Blockage intervals (tunnels, cuttings, overbridges) are chainage ranges along the line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pyproj import Transformer

from stations.scenario import Line, Scenario, ScenarioError

ARC_STEP_M = 10.0  # curve sampling: sagitta = step^2 / (8 R) = 2.5 mm at R = 5,000 m
MAX_SEGMENT_M = 200.0  # straight sections are sampled too, so chainage lookups stay local
GEODETIC_CRS = "EPSG:4979"  # WGS 84 lat, lon, ellipsoidal h
ECEF_CRS = "EPSG:4978"


@dataclass(frozen=True)
class TrackPolyline:
    track_id: str  # e.g. "L1-1" (main-line track 1), "L1-S2-L1" (station 2, loop track 1)
    s_m: np.ndarray  # chainage of each vertex along the line centre [m]
    enu: np.ndarray  # (n, 3) plane east, north [m] and ellipsoidal height of rail level [m]
    ecef: np.ndarray  # (n, 3) same vertices in ECEF [m]


class TrackLine:
    """A line: centre line, main-line tracks, loop tracks in stations, blockages."""

    def __init__(self, line: Line):
        self.line = line
        lat = np.array([w.lat_deg for w in line.waypoints])
        lon = np.array([w.lon_deg for w in line.waypoints])
        h = np.array([w.h_m for w in line.waypoints])
        lat0, lon0 = float(lat.mean()), float(lon.mean())
        proj = (f"+proj=tmerc +lat_0={lat0:.9f} +lon_0={lon0:.9f} +k=1 +x_0=0 +y_0=0 "
                "+ellps=WGS84 +units=m +no_defs")
        self._to_plane = Transformer.from_crs("EPSG:4326", proj, always_xy=True)
        self._from_plane = Transformer.from_crs(proj, "EPSG:4326", always_xy=True)
        self._to_ecef = Transformer.from_crs(GEODETIC_CRS, ECEF_CRS, always_xy=True)
        e, n = self._to_plane.transform(lon, lat)
        xy, s, s_wp = _rounded_centre_line(np.column_stack([e, n]), line.curve_radius_m)
        self.s_m = s
        self.length_m = float(s[-1])
        self.centre_xy = xy
        self.waypoint_s_m = s_wp
        self.rail_h = np.interp(s, s_wp, h)
        # Unit left normal at each vertex: average of the adjacent segment normals.
        d = np.diff(xy, axis=0)
        d /= np.linalg.norm(d, axis=1)[:, None]
        t = np.vstack([d[:1], d[:-1] + d[1:], d[-1:]])
        t /= np.linalg.norm(t, axis=1)[:, None]
        self.tangent_xy = t
        self.left_xy = np.column_stack([-t[:, 1], t[:, 0]])
        self.tracks: dict[str, TrackPolyline] = {}
        for k in range(1, line.tracks + 1):
            self.tracks[self.track_id(k)] = self._offset_polyline(self.track_id(k), self.track_offset_m(k))
        for si, st in enumerate(line.stations, start=1):
            outer = self.track_offset_m(1)
            for j in range(1, st.loop_tracks + 1):
                side = 1.0 if j % 2 else -1.0
                offset = side * (abs(outer) + line.track_spacing_m * ((j + 1) // 2))
                tid = f"{line.id}-S{si}-{j}"
                self.tracks[tid] = self._offset_polyline(tid, offset, st.start_km * 1e3, st.end_km * 1e3)

    # -- tracks ---------------------------------------------------------------------------------
    def track_id(self, k: int) -> str:
        return f"{self.line.id}-{k}"

    def track_offset_m(self, k: int) -> float:
        """Lateral offset of main-line track k from the centre line, positive to the left."""
        return ((self.line.tracks + 1) / 2.0 - k) * self.line.track_spacing_m

    def _offset_polyline(self, tid: str, offset_m: float, s0: float = 0.0, s1: float | None = None):
        s1 = self.length_m if s1 is None else min(s1, self.length_m)
        keep = (self.s_m >= s0) & (self.s_m <= s1)
        xy = self.centre_xy[keep] + offset_m * self.left_xy[keep]
        enu = np.column_stack([xy, self.rail_h[keep]])
        return TrackPolyline(tid, self.s_m[keep], enu, self.plane_to_ecef(enu))

    # -- conversions ----------------------------------------------------------------------------
    def plane_to_geodetic(self, enu: np.ndarray) -> np.ndarray:
        lon, lat = self._from_plane.transform(enu[..., 0], enu[..., 1])
        return np.stack([np.asarray(lat), np.asarray(lon), enu[..., 2]], axis=-1)

    def plane_to_ecef(self, enu: np.ndarray) -> np.ndarray:
        g = self.plane_to_geodetic(enu)
        x, y, z = self._to_ecef.transform(g[..., 1], g[..., 0], g[..., 2])
        return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1)

    def geodetic_to_plane(self, lat, lon) -> np.ndarray:
        e, n = self._to_plane.transform(np.asarray(lon, float), np.asarray(lat, float))
        return np.stack([np.asarray(e), np.asarray(n)], axis=-1)

    # -- points on the line -----------------------------------------------------------------------
    def point(self, s_m, offset_m=0.0, above_rail_m=0.0) -> np.ndarray:
        """Plane (E, N, h) of points at chainage s, lateral offset (left +) and height above rail.

        Linear between the centre-line vertices, so a point on a track lies on that track's polyline.
        """
        s = np.clip(np.asarray(s_m, float), 0.0, self.length_m)
        i = np.clip(np.searchsorted(self.s_m, s, side="right") - 1, 0, len(self.s_m) - 2)
        w = ((s - self.s_m[i]) / (self.s_m[i + 1] - self.s_m[i]))[..., None]
        base = (self.centre_xy[i] + offset_m * self.left_xy[i]) * (1 - w) + \
               (self.centre_xy[i + 1] + offset_m * self.left_xy[i + 1]) * w
        h = self.rail_h[i] * (1 - w[..., 0]) + self.rail_h[i + 1] * w[..., 0] + above_rail_m
        return np.concatenate([base, h[..., None]], axis=-1)

    def grade(self, s_m) -> np.ndarray:
        """Grade dh/ds (dimensionless, + rising towards increasing km)."""
        s = np.clip(np.asarray(s_m, float), 0.0, self.length_m)
        i = np.clip(np.searchsorted(self.waypoint_s_m, s, side="right") - 1, 0,
                    len(self.waypoint_s_m) - 2)
        h = np.array([w.h_m for w in self.line.waypoints])
        return (h[i + 1] - h[i]) / (self.waypoint_s_m[i + 1] - self.waypoint_s_m[i])

    def heading_xy(self, s_m) -> np.ndarray:
        """Unit tangent (E, N) of the centre line at chainage s (towards increasing km)."""
        s = np.clip(np.asarray(s_m, float), 0.0, self.length_m)
        i = np.clip(np.searchsorted(self.s_m, s, side="right") - 1, 0, len(self.s_m) - 2)
        d = self.centre_xy[i + 1] - self.centre_xy[i]
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def station_point(self, km: float, offset_m: float, mast_m: float) -> np.ndarray:
        return self.point(km * 1e3, offset_m, mast_m)

    # -- blockages ------------------------------------------------------------------------------
    def blockage_mask_deg(self, s_from_m, s_to_m) -> tuple[np.ndarray, np.ndarray]:
        """Sky hidden over the swept interval [s_from, s_to]: (all-sky mask, cutting wall angle) [deg].

        Tunnels and overbridges hide the whole sky (all-sky mask 90 deg), so any touch between two
        epochs means loss of lock, even under a 15 m bridge passed in 0.2 s.  A cutting's walls hide
        satellites across the track below `mask_deg`, less towards its ends (see `cutting_mask`).
        0 where the sky is open.
        """
        a = np.minimum(s_from_m, s_to_m)
        b = np.maximum(s_from_m, s_to_m)
        full = np.zeros(np.shape(a))
        wall = np.zeros(np.shape(a))
        for blk in self.line.blockages:
            hit = (a <= blk.end_km * 1e3) & (b >= blk.start_km * 1e3)
            if blk.kind in ("tunnel", "bridge"):
                full = np.where(hit, 90.0, full)
            else:
                wall = np.where(hit, np.maximum(wall, blk.mask_deg), wall)
        return full, wall

    # -- inverse: nearest track (used by tests and tools, independent of how points were made) --
    def nearest_track(self, enu: np.ndarray) -> tuple[list[str], np.ndarray, np.ndarray]:
        """For plane points (E, N, h): nearest track id, its chainage [m], horizontal distance [m]."""
        pts = np.atleast_2d(enu)[:, :2]
        best_d = np.full(len(pts), np.inf)
        best_s = np.zeros(len(pts))
        best_id = [""] * len(pts)
        for tid, poly in self.tracks.items():
            a = poly.enu[:-1, :2]
            b = poly.enu[1:, :2]
            ab = b - a
            ab2 = np.einsum("ij,ij->i", ab, ab)
            for k, p in enumerate(pts):
                u = np.clip(np.einsum("ij,ij->i", p - a, ab) / ab2, 0.0, 1.0)
                q = a + u[:, None] * ab
                d = np.linalg.norm(p - q, axis=1)
                j = int(np.argmin(d))
                if d[j] < best_d[k]:
                    best_d[k] = d[j]
                    best_s[k] = poly.s_m[j] + u[j] * (poly.s_m[j + 1] - poly.s_m[j])
                    best_id[k] = tid
        return best_id, best_s, best_d


def _rounded_centre_line(pts: np.ndarray, radius_m: float):
    """Waypoint polyline with circular arcs at interior corners, densely sampled.

    Returns (xy vertices, chainage of each vertex, chainage of each waypoint's station on the line).
    """
    n = len(pts)
    seg = np.diff(pts, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    if np.any(seg_len < 1.0):
        raise ValueError("line waypoints must be at least 1 m apart")
    u = seg / seg_len[:, None]
    # Tangent lengths at each interior corner, limited to 45 % of the adjacent sections.
    tangents = np.zeros(n)
    radii = np.zeros(n)
    for k in range(1, n - 1):
        cosang = float(np.clip(np.dot(u[k - 1], u[k]), -1.0, 1.0))
        theta = np.arccos(cosang)  # deflection angle
        if theta < 1e-6:
            continue
        t = radius_m * np.tan(theta / 2.0)
        t = min(t, 0.45 * seg_len[k - 1], 0.45 * seg_len[k])
        tangents[k] = t
        radii[k] = t / np.tan(theta / 2.0)
    out = [pts[0]]
    wp_points = [pts[0]]
    for k in range(1, n):
        # straight from the end of the previous arc to the start of this corner's arc
        start = pts[k - 1] + u[k - 1] * tangents[k - 1]
        end = pts[k] - u[k - 1] * tangents[k] if k < n - 1 else pts[k]
        length = np.linalg.norm(end - start)
        m = max(int(np.ceil(length / MAX_SEGMENT_M)), 1)
        for j in range(1, m + 1):
            out.append(start + (end - start) * j / m)
        if k == n - 1:
            wp_points.append(pts[k])
            break
        if tangents[k] == 0.0:
            wp_points.append(pts[k])
            continue
        # circular arc from `end` to pts[k] + u[k] * t, centre on the inside of the turn
        r = radii[k]
        cross = u[k - 1][0] * u[k][1] - u[k - 1][1] * u[k][0]
        left = np.array([-u[k - 1][1], u[k - 1][0]])
        centre = end + np.sign(cross) * left * r
        a0 = np.arctan2(*(end - centre)[::-1])
        theta = np.arccos(np.clip(np.dot(u[k - 1], u[k]), -1.0, 1.0))
        arc_len = r * theta
        m = max(int(np.ceil(arc_len / ARC_STEP_M)), 2)
        angles = a0 + np.sign(cross) * theta * np.arange(1, m + 1) / m
        arc = centre + r * np.column_stack([np.cos(angles), np.sin(angles)])
        out.extend(arc)
        wp_points.append(centre + r * np.array([np.cos(a0 + np.sign(cross) * theta / 2),
                                                np.sin(a0 + np.sign(cross) * theta / 2)]))
    xy = np.array(out)
    # drop repeated vertices (zero-length pieces)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(xy, axis=0), axis=1) > 1e-6])
    xy = xy[keep]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    # chainage of each waypoint: the nearest centre-line vertex to its station on the line
    s_wp = np.array([s[int(np.argmin(np.linalg.norm(xy - p, axis=1)))] for p in wp_points])
    s_wp[0], s_wp[-1] = 0.0, s[-1]
    return xy, s, s_wp


def check_on_line(sc: Scenario, line: TrackLine) -> None:
    """Refuse kilometre posts beyond the end of the line (known only once the curves are built)."""
    end_km = line.length_m / 1e3
    bad = []
    for i, st in enumerate(sc.stations):
        if st.km is not None and st.km > end_km:
            bad.append(f"stations.{i}.km = {st.km}")
    for i, tr in enumerate(sc.trains):
        if tr.start_km > end_km:
            bad.append(f"trains.{i}.start_km = {tr.start_km}")
    for i, blk in enumerate(sc.line.blockages):
        if blk.start_km > end_km:
            bad.append(f"line.blockages.{i}.start_km = {blk.start_km}")
    if bad:
        raise ScenarioError(f"scenario {sc.name}: " + "; ".join(f"{b}: beyond the end of the line (0 to "
                                                                  f"{end_km:.3f} km)" for b in bad))


def cutting_mask_rad(wall_deg, azimuth_rad, heading_rad):
    """Elevation below which a cutting's walls hide a satellite [rad].

    The walls run along the track: a satellite straight across it is hidden below the wall angle,
    one along the track sees down the cutting (tan(mask) scales with |sin(azimuth - heading)|).
    """
    return np.arctan(np.tan(np.radians(wall_deg)) * np.abs(np.sin(azimuth_rad - heading_rad)))
