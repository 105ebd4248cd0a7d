"""Track map: a track database, map matching among parallel tracks, along/cross-track protection levels.

Track database file (JSON, `"format": "augnet-trackmap/1"`; one per scenario; the simulator exports
its track geometry to it, onboard never imports the simulator):

    {
      "format": "augnet-trackmap/1",
      "name": "scenario name",
      "tracks": [
        {"id": "UP", "line": "L1", "name": "up main line", "km_start": 0.0,
         "points": [[lat_deg, lon_deg, h_m], ...],          # WGS 84, ellipsoidal height, in km order
         "km": [0.0, 0.02, ...]}                             # optional: the line's chainage per point
      ],
      "km_posts": [{"track": "UP", "km": 1.0, "label": "K1"}],               # optional, informative
      "balises": [{"id": "VB-0001", "track": "UP", "km": 1.2345,
                   "telegram": "hex string", "linked": true}]                 # virtual balises
    }

Points are joined by straight chords in ECEF (export them densely on curves: a chord 100 m long on
a 1 km radius curve deviates 1.25 m; 20 m deviates 5 cm).  Chainage: with a per-point "km" list
(a line's chainage is usually that of its centre line, so parallel tracks share km posts), km is
interpolated between points by arc length; without it km = km_start + arc length / 1000.

Map matching projects the antenna position onto every track segment at once (numpy over segments),
keeps the nearest point per track, and picks the track with the smallest cross-track offset.
Cross-track is measured in the local horizontal plane, to the left of the direction of increasing
km.  Protection levels: PL = max(K sigma, b_i + K_md,i sigma) with sigma the filter's standard deviation
projected on the track's tangent (along) and horizontal normal (cross), K the two-sided Gaussian quantile
for the allocated integrity risk and b_i, K_md,i the per-fault bounds of the satellite and wrong-correction
modes (integrity_allocation.py, decisions 0250 and 0253).  The track is *confirmed* only when the cross-track PL is below half the
distance to the nearest other candidate track (so the protection region cannot reach it) and the
offset itself is inside the gate; otherwise the match is reported as not confirmed.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation, geodetic_deg_to_ecef
from augnet.onboard.integrity_allocation import ALLOCATED_PER_DECISION_RISK, gaussian_k  # noqa: F401 (re-export)
from augnet.onboard.integrity_allocation import DEFAULT_ALLOCATION, GNSS_FAULT_MODES, IntegrityAllocation
from augnet.onboard.integrity_allocation import correction_sigma_on_axis

FORMAT = "augnet-trackmap/1"
# Fault-free integrity risk per independent decision: the Helmet 1e-9/h split over the decisions of an
# hour (integrity_allocation.py; was a per-epoch 1e-7, too small a K for the hourly requirement).
DEFAULT_INTEGRITY_RISK = ALLOCATED_PER_DECISION_RISK
# A position farther than this [m] from every track is off the map (a siding not in the database,
# or a wrong position): no track is reported.
DEFAULT_MATCH_GATE_M = 10.0
# Parallel tracks are 4.5-5 m apart (railway.md); candidates are tracks within this many metres.
CANDIDATE_RADIUS_M = 25.0


class TrackMapError(ValueError):
    """A track database file that cannot be used (wrong format, too few points, unknown track)."""


@dataclass(frozen=True)
class Track:
    id: str
    line: str
    name: str
    km_start: float
    points_llh: np.ndarray  # (n, 3) lat deg, lon deg, h m
    km_points: np.ndarray | None = None  # (n,) chainage of each point [km], or None


@dataclass(frozen=True)
class VirtualBalise:
    id: str
    track: str
    km: float
    telegram: bytes
    linked: bool = True


@dataclass(frozen=True)
class KmPost:
    track: str
    km: float
    label: str


@dataclass
class MapMatch:
    """Where the train is on the map, and how sure."""

    track: str | None  # None when off the map
    line: str | None
    km: float  # chainage [km]
    along_m: float  # arc length from the track's first point [m]
    cross_m: float  # horizontal offset, positive to the left of increasing km [m]
    vertical_m: float  # height above the track's polyline [m]
    along_pl_m: float
    cross_pl_m: float
    confirmed: bool
    nearest_other_m: float  # cross-track distance to the nearest other candidate track [m]
    candidates: dict[str, float] = field(default_factory=dict)  # track id -> cross offset [m]
    message: str = ""
    # the centre's correction-error sigma carried to each axis [m] (RTCM 4001; 0: none received, inf: unbounded)
    correction_along_m: float = 0.0
    correction_cross_m: float = 0.0
    # the 1-sigma on each axis the PLs were made from (receiver's, with the correction bound in quadrature) [m]
    along_sigma_m: float = math.inf
    cross_sigma_m: float = math.inf


class TrackDatabase:
    def __init__(self, name: str, tracks: list[Track], balises: list[VirtualBalise] | None = None,
                 km_posts: list[KmPost] | None = None):
        if not tracks:
            raise TrackMapError("a track database needs at least one track")
        ids = [t.id for t in tracks]
        if len(set(ids)) != len(ids):
            raise TrackMapError("duplicate track ids")
        self.name = name
        self.tracks = {t.id: t for t in tracks}
        self.balises = list(balises or [])
        self.km_posts = list(km_posts or [])
        for b in self.balises:
            if b.track not in self.tracks:
                raise TrackMapError(f"balise {b.id} on unknown track {b.track}")
        self._build_segments(tracks)

    # ------------------------------------------------------------------------------------------
    # file format

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrackDatabase":
        if d.get("format") != FORMAT:
            raise TrackMapError(f"not a track database (format {d.get('format')!r}, expected {FORMAT!r})")
        try:
            tracks = []
            for t in d["tracks"]:
                pts = np.asarray(t["points"], dtype=float)
                if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2 or not np.all(np.isfinite(pts)):
                    raise TrackMapError(f"track {t.get('id')}: points must be >= 2 finite [lat, lon, h]")
                kms = None
                if t.get("km") is not None:
                    kms = np.asarray(t["km"], dtype=float)
                    if kms.shape != (len(pts),) or not np.all(np.isfinite(kms)) or np.any(np.diff(kms) < 0):
                        raise TrackMapError(f"track {t.get('id')}: 'km' must give one increasing chainage per point")
                tracks.append(Track(str(t["id"]), str(t.get("line", "")), str(t.get("name", "")),
                                    float(kms[0] if kms is not None else t.get("km_start", 0.0)), pts, kms))
            balises = [VirtualBalise(str(b["id"]), str(b["track"]), float(b["km"]), bytes.fromhex(b.get("telegram", "")),
                                     bool(b.get("linked", True))) for b in d.get("balises", [])]
            posts = [KmPost(str(p["track"]), float(p["km"]), str(p.get("label", ""))) for p in d.get("km_posts", [])]
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, TrackMapError):
                raise
            raise TrackMapError(f"malformed track database: {exc}") from None
        return cls(str(d.get("name", "")), tracks, balises, posts)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "name": self.name,
            "tracks": [{"id": t.id, "line": t.line, "name": t.name, "km_start": t.km_start,
                        "points": t.points_llh.tolist(),
                        **({"km": t.km_points.tolist()} if t.km_points is not None else {})}
                       for t in self.tracks.values()],
            "km_posts": [{"track": p.track, "km": p.km, "label": p.label} for p in self.km_posts],
            "balises": [{"id": b.id, "track": b.track, "km": b.km, "telegram": b.telegram.hex(), "linked": b.linked}
                        for b in self.balises],
        }

    @classmethod
    def load(cls, path: str | os.PathLike) -> "TrackDatabase":
        try:
            with open(path, encoding="utf-8") as f:
                d = json.load(f)
        except (OSError, json.JSONDecodeError) as exc:
            raise TrackMapError(f"cannot read track database {path}: {exc}") from None
        return cls.from_dict(d)

    def save(self, path: str | os.PathLike) -> None:
        with open(path, "w", encoding="utf-8") as f:
            json.dump(self.to_dict(), f, indent=1)

    # ------------------------------------------------------------------------------------------
    # geometry

    def _build_segments(self, tracks: list[Track]) -> None:
        A, B, trk, s0, K0, K1 = [], [], [], [], [], []
        self.track_length_m: dict[str, float] = {}
        for ti, t in enumerate(tracks):
            xyz = geodetic_deg_to_ecef(t.points_llh[:, 0], t.points_llh[:, 1], t.points_llh[:, 2])
            seg = np.diff(xyz, axis=0)
            length = np.linalg.norm(seg, axis=1)
            keep = length > 1e-6  # repeated points make no segment
            cum = np.concatenate(([0.0], np.cumsum(length)))
            kms = t.km_points if t.km_points is not None else t.km_start + cum / 1000.0
            K0.append(kms[:-1][keep])
            K1.append(kms[1:][keep])
            A.append(xyz[:-1][keep])
            B.append(xyz[1:][keep])
            s0.append(cum[:-1][keep])
            trk.append(np.full(int(keep.sum()), ti))
            self.track_length_m[t.id] = float(cum[-1])
        self._track_ids = [t.id for t in tracks]
        self._A = np.concatenate(A)
        B = np.concatenate(B)
        self._s0 = np.concatenate(s0)
        self._km0 = np.concatenate(K0)
        self._km1 = np.concatenate(K1)
        self._trk = np.concatenate(trk)
        d = B - self._A
        self._len = np.linalg.norm(d, axis=1)
        self._T = d / self._len[:, None]
        mid = 0.5 * (self._A + B)
        llh = ecef_to_geodetic(mid)
        R = enu_rotation(llh[:, 0], llh[:, 1])
        self._U = R[:, 2, :]
        n = np.cross(self._U, self._T)
        self._N = n / np.linalg.norm(n, axis=1)[:, None]  # horizontal, left of the tangent

    def position_at(self, track: str, km: float) -> np.ndarray:
        """ECEF point on a track at a chainage (for tests, balise placement, simulators)."""
        j, u = self._locate(track, km)
        return self._A[j] + u * self._T[j]

    def along_m(self, track: str, km: float) -> float:
        """Arc length from the track's first point to a chainage [m]."""
        j, u = self._locate(track, km)
        return float(self._s0[j] + u)

    def _locate(self, track: str, km: float) -> tuple[int, float]:
        ti = self._track_ids.index(track)
        m = np.flatnonzero(self._trk == ti)
        j = m[np.clip(np.searchsorted(self._km0[m], km, side="right") - 1, 0, len(m) - 1)]
        span = self._km1[j] - self._km0[j]
        frac = (km - self._km0[j]) / span if span > 0 else 0.0
        return int(j), float(np.clip(frac, 0.0, 1.0) * self._len[j])

    def tangent_at(self, track: str, km: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(tangent, left horizontal normal, up) unit vectors in ECEF at a chainage."""
        j, _ = self._locate(track, km)
        return self._T[j], self._N[j], self._U[j]

    # ------------------------------------------------------------------------------------------
    # map matching

    def match(self, position_m, covariance_m2=None, integrity_risk: float = DEFAULT_INTEGRITY_RISK,
              gate_m: float = DEFAULT_MATCH_GATE_M, correction_gain=None, correction_sigma_m=None,
              allocation: IntegrityAllocation | None = DEFAULT_ALLOCATION) -> MapMatch:
        """Match an ECEF antenna position (with its 3x3 ECEF covariance) to the track map.

        `correction_sigma_m` (S,): the centre's 4001 overbound sigmas of the satellites' correction errors,
        `correction_gain` (3, S): the position's ECEF gain on them (`correction_bound.dd_position_gain`);
        their sigma on each axis inflates that axis's in quadrature before K (decision 0280). A sigma
        without a usable gain, or a used satellite without a sigma (NaN), makes the PLs infinite.
        `allocation`: each PL is at least its per-fault bounds b_i + K_md sigma for the faults a GNSS fix can
        carry (satellite, wrong correction; decisions 0250, 0253); None: the fault-free K sigma alone."""
        p = np.asarray(position_m, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            return _off_map("no valid position")
        rel = p - self._A
        u = np.clip(np.einsum("ij,ij->i", rel, self._T), 0.0, self._len)
        d = rel - u[:, None] * self._T
        dist = np.linalg.norm(d, axis=1)
        # best segment per track
        n_tr = len(self._track_ids)
        best = np.full(n_tr, -1)
        best_d = np.full(n_tr, np.inf)
        order = np.lexsort((dist, self._trk))
        first = np.ones(len(order), bool)
        first[1:] = self._trk[order][1:] != self._trk[order][:-1]
        for j in order[first]:
            best[self._trk[j]] = j
            best_d[self._trk[j]] = dist[j]
        cross = {self._track_ids[k]: float(d[best[k]] @ self._N[best[k]]) for k in range(n_tr) if best[k] >= 0}
        # a candidate lies within the radius horizontally: beyond a track's end the offset to its end point
        # has an along-track part (a collinear track segment 1 km ahead is no candidate, whatever its cross)
        horiz = {self._track_ids[k]: math.sqrt(max(best_d[k] ** 2 - float(d[best[k]] @ self._U[best[k]]) ** 2, 0.0))
                 for k in range(n_tr) if best[k] >= 0}
        near = {k: v for k, v in cross.items() if abs(v) <= CANDIDATE_RADIUS_M and horiz[k] <= CANDIDATE_RADIUS_M}
        k_best = int(np.argmin(best_d))
        j = best[k_best]
        tid = self._track_ids[k_best]
        c = cross[tid]
        if abs(c) > gate_m or best_d[k_best] > gate_m + 50.0:
            m = _off_map(f"{abs(c):.1f} m from the nearest track {tid}, outside the {gate_m:.0f} m gate")
            m.candidates = near
            return m
        # nearest track by horizontal distance among candidates (= the cross-track offset within a track's span)
        if near:
            tid = min(near, key=lambda k: horiz[k])
            k_best = self._track_ids.index(tid)
            j = best[k_best]
            c = near[tid]
        tr = self.tracks[tid]
        along = float(self._s0[j] + u[j])
        vertical = float(d[j] @ self._U[j])
        others = [abs(v - c) for k, v in near.items() if k != tid]
        nearest_other = min(others) if others else math.inf
        if covariance_m2 is None or not np.all(np.isfinite(covariance_m2)):
            sig_a = sig_c = math.inf
        else:
            C = np.asarray(covariance_m2, dtype=float)
            sig_a = math.sqrt(max(float(self._T[j] @ C @ self._T[j]), 0.0))
            sig_c = math.sqrt(max(float(self._N[j] @ C @ self._N[j]), 0.0))
        corr_a = corr_c = 0.0
        if correction_sigma_m is not None:
            g = None if correction_gain is None else np.asarray(correction_gain, dtype=float)
            if g is None or not np.all(np.isfinite(g)):
                corr_a = corr_c = math.inf
            else:
                corr_a = float(correction_sigma_on_axis(self._T[j] @ g, correction_sigma_m))
                corr_c = float(correction_sigma_on_axis(self._N[j] @ g, correction_sigma_m))
        k = gaussian_k(integrity_risk)
        s_a, s_c = math.hypot(sig_a, corr_a), math.hypot(sig_c, corr_c)
        apl, xpl = k * s_a, k * s_c
        if allocation is not None:
            # a satellite fault or a wrong correction the checks let through biases the fix (decision 0250)
            apl = max(apl, allocation.fault_bound(s_a, "along", GNSS_FAULT_MODES))
            xpl = max(xpl, allocation.fault_bound(s_c, "cross", GNSS_FAULT_MODES))
        # confirmed when the protection region around the estimate stays on this track's side of the
        # midline to every other track
        confirmed = bool(math.isfinite(xpl) and (abs(c) + xpl < 0.5 * nearest_other if others else xpl < gate_m))
        msg = "track confirmed" if confirmed else (
            f"track not confirmed: cross-track PL {xpl:.2f} m against {nearest_other:.2f} m to the next track")
        km = float(self._km0[j] + (self._km1[j] - self._km0[j]) * u[j] / self._len[j])
        return MapMatch(tid, tr.line, km, along, c, vertical, apl, xpl, confirmed, nearest_other, near, msg,
                        corr_a, corr_c, s_a, s_c)


def _off_map(msg: str) -> MapMatch:
    return MapMatch(None, None, math.nan, math.nan, math.nan, math.nan, math.inf, math.inf, False, math.inf, {}, msg)
