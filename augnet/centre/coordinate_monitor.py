"""Live monitoring of the published station coordinates from the fixed network (issue 15, decision 0254).

A station published off its true position by d puts (u_j - u_r) . d into every fixed DD phase residual of its
baselines (u: unit vector station -> satellite; `BaselineEpoch.dd_trop_m`, the non-dispersive residual, so the
ionosphere does not hide it). With the DD integers fixed, each baseline a-b is a vector solution: per sampled
epoch a least-squares fit of its residuals by a relative offset x = d_b - d_a (east, north, up at b), and over a
window of samples the mean with its covariance. That is what a network operator's coordinate monitoring does
(Trimble Pivot's / Leica Spider's station position monitors compare the network's baseline solutions with the
published coordinates); here it runs on every network epoch, in the centre engine (campaign and `augnet up`).

Test per baseline: the horizontal offset against its covariance, chi-square with 2 degrees of freedom at the false
alarm probability `BASELINE_FALSE_ALARM`. The covariance is the window's formal one (a posteriori DD sigma,
inflated for the residuals' correlation time) plus a systematic part of the relative solution that does not
average down: broadcast orbit errors give db/b = dr/rho (2 m over 20,200 km: 0.1 ppm per horizontal component).
The vertical is not tested: over minutes it cannot be separated from the residual wet delay (measured: clean
simulated baselines 2-6 cm up, catnet 10-min windows up to 31 cm); the 3 h station check (station_check.py)
covers it.

Attribution: a station is flagged when every one of its baselines with a verdict fires, it has at least
`MIN_NEIGHBOURS` of them, and a baseline not touching it has a verdict and is clean (with one wrong station
among three, the wrong one is off from both others, each good one from one only). A flagged station raises a
`station-coordinates` alarm, is excluded from VRS synthesis (no master, no interpolation node) by the engine,
and its estimated offset enters the correction bound of the sessions it serves until it is excluded. The flag
clears once its baselines' statistics fall below `CLEAR_FRACTION` of the threshold (the coordinates corrected:
`move_station` restarts its baselines and their windows).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.integrity import Alarm
from augnet.gnss.ephemeris import NavigationData, transit
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.gnss.statistics import chi2_quantile

KIND = "station-coordinates"  # alarm kind
# Network epochs are sampled at most this often [s]: the geometry changes over minutes, the residuals are
# correlated over seconds; 1 Hz networks stay cheap (one transit per station per sample).
SAMPLE_INTERVAL_S = 5.0
# Samples per window (5 s sampling: one minute; catnet's 30 s epochs: six minutes); a verdict needs a full one.
WINDOW_SAMPLES = 12
# Fixed DDs (non-reference, above the mask) a sample needs: 3 unknowns and enough redundancy for the sigma.
MIN_DDS = 6
MIN_ELEVATION_DEG = 15.0  # the network's fixing mask (station_check.MIN_ELEVATION_DEG)
# Correlation time of the DD phase residuals [s]: the baseline filter's phase multipath time constant
# (BaselineConfig.phase_multipath_tau_s, decision 0101); samples within it are not independent.
CORRELATION_TIME_S = 120.0
# Floor of the a posteriori DD sigma at zenith [m] (station_check.PHASE_SIGMA_M): a lucky window is not exact.
MIN_DD_SIGMA_M = 0.005
# Systematic part of a relative horizontal solution per metre of baseline: broadcast orbit error dr over the
# satellite distance rho, db/b = dr/rho (Bauersima 1983; Hofmann-Wellenhof et al., GNSS 2008, sec. 7.3):
# 2 m / 20,200 km = 1e-7.
SYSTEMATIC_PER_M = 1.0e-7
# Per baseline and window; two baselines must fire together to flag a station.
BASELINE_FALSE_ALARM = 1.0e-4
THRESHOLD = chi2_quantile(2, BASELINE_FALSE_ALARM)  # 18.4
CLEAR_FRACTION = 0.25  # hysteresis: cleared only well inside the threshold
MIN_NEIGHBOURS = 2


@dataclass
class BaselineVerdict:
    """The window's solution of one baseline a-b: x = d_b - d_a (east, north, up at b) [m]."""

    name: str
    a: str
    b: str
    length_m: float
    x_m: np.ndarray
    cov_m2: np.ndarray  # (3, 3), systematic part included
    statistic: float  # horizontal chi-square (2 dof)
    samples: int

    @property
    def fires(self) -> bool:
        return self.statistic > THRESHOLD


@dataclass
class StationOffset:
    """A station's estimated offset (published minus true, east/north/up) [m] from its baselines."""

    station: str
    offset_enu_m: np.ndarray
    cov_m2: np.ndarray
    statistic: float
    baselines: list[str]
    flagged: bool = False
    flagged_at: float = float("nan")


@dataclass
class _Window:
    a: str
    b: str
    length_m: float
    samples: deque = field(default_factory=lambda: deque(maxlen=WINDOW_SAMPLES))  # (t, N, Hr, rr, n)


class StationCoordinateMonitor:
    def __init__(self, sample_interval_s: float = SAMPLE_INTERVAL_S, window_samples: int = WINDOW_SAMPLES):
        self.sample_interval_s = sample_interval_s
        self.window_samples = window_samples
        self.windows: dict[str, _Window] = {}
        self.verdicts: dict[str, BaselineVerdict] = {}
        self.offsets: dict[str, StationOffset] = {}
        self.flagged: dict[str, float] = {}  # station -> t flagged
        self.alarms: list[Alarm] = []  # every alarm raised
        self.new_alarms: list[Alarm] = []
        self._t_sample = -np.inf

    # --- per network epoch ------------------------------------------------------------------------------

    def update(self, ne, nav: NavigationData) -> list[Alarm]:
        """Take one network epoch (`NetworkEpoch`); returns the alarms raised now."""
        t = float(ne.t_gpst)
        if not np.isfinite(t) or t - self._t_sample < self.sample_interval_s - 1e-6:
            return []
        self._t_sample = t
        xyz = {n: ne.station_xyz_m[k] for k, n in enumerate(ne.stations)}
        live = set()
        geo: dict[str, tuple] = {}
        for name, r in ne.baselines.items():
            a, b = name.split("-", 1) if name.count("-") == 1 else _split(name, xyz)
            if a not in xyz or b not in xyz:
                continue
            live.add(name)
            w = self.windows.get(name)
            if w is None or w.a != a or w.b != b:
                w = self.windows[name] = _Window(a, b, float(np.linalg.norm(xyz[b] - xyz[a])))
            if r is None:
                continue
            sample = self._sample(r, xyz[b], b, geo, nav, t)
            if sample is not None:
                w.samples.append(sample)
        for gone in set(self.windows) - live:
            del self.windows[gone]
        self.verdicts = {n: v for n, w in self.windows.items() if (v := self._verdict(n, w)) is not None}
        self._attribute(t, list(xyz))
        out, self.new_alarms = self.new_alarms, []
        return out

    def _sample(self, r, xyz_b, b: str, geo: dict, nav: NavigationData, t: float):
        sats = np.asarray(r.sats).astype(str)
        if b not in geo:
            geo[b] = _geometry(nav, xyz_b, t)
        rot, cache = geo[b]
        missing = [s for s in sats if s not in cache]
        if missing:
            tr = transit(nav, missing, xyz_b, t)
            for s, u, ok in zip(missing, np.asarray(tr.line_of_sight), np.asarray(tr.valid)):
                cache[s] = rot @ u if ok else None
        rows, res, wts = [], [], []
        for system, ref in r.refs.items():
            ur = cache.get(ref)
            if ur is None:
                continue
            for k, s in enumerate(sats):
                u = cache.get(s)
                if s[0] != system or s == ref or u is None or not r.fixed[k] or not np.isfinite(r.dd_trop_m[k]):
                    continue
                sin_el = min(u[2], ur[2])
                if sin_el < np.sin(np.radians(MIN_ELEVATION_DEG)):
                    continue
                rows.append(u - ur)
                res.append(float(r.dd_trop_m[k]))
                wts.append(sin_el ** 2)  # sigma ~ 1 / sin(elevation) of the lower satellite
        if len(res) < MIN_DDS:
            return None
        H, y, wt = np.array(rows), np.array(res), np.array(wts)
        return t, H.T @ (H * wt[:, None]), H.T @ (wt * y), float(wt @ (y * y)), len(y)

    def _verdict(self, name: str, w: _Window) -> BaselineVerdict | None:
        if len(w.samples) < self.window_samples:
            return None
        N = sum(s[1] for s in w.samples)
        hr = sum(s[2] for s in w.samples)
        rr = sum(s[3] for s in w.samples)
        n = sum(s[4] for s in w.samples)
        try:
            Ninv = np.linalg.inv(N)
        except np.linalg.LinAlgError:
            return None
        x = Ninv @ hr
        dof = n - 3
        s2 = max((rr - float(x @ hr)) / dof if dof > 0 else np.inf, MIN_DD_SIGMA_M ** 2)
        span = w.samples[-1][0] - w.samples[0][0] + self.sample_interval_s
        # samples within a correlation time are one: the formal covariance of len(samples) samples, scaled up
        independent = max(1.0, span / CORRELATION_TIME_S)
        cov = s2 * Ninv * (len(w.samples) / min(independent, len(w.samples)))
        cov = cov + np.diag([1.0, 1.0, 0.0]) * (SYSTEMATIC_PER_M * w.length_m) ** 2
        h = x[:2]
        stat = float(h @ np.linalg.solve(cov[:2, :2], h))
        return BaselineVerdict(name, w.a, w.b, w.length_m, x, cov, stat, len(w.samples))

    def _attribute(self, t: float, stations: list[str]) -> None:
        self.offsets = {}
        for s in stations:
            mine = [v for v in self.verdicts.values() if s in (v.a, v.b)]
            if not mine:
                continue
            # d_s from each baseline: x = d_b - d_a, so d_s = x at b, -x at a (others held at their coordinates)
            info = np.zeros((3, 3))
            vec = np.zeros(3)
            for v in mine:
                sign = 1.0 if v.b == s else -1.0
                ci = np.linalg.inv(v.cov_m2 + np.diag([0.0, 0.0, 1e-12]))
                info += ci
                vec += ci @ (sign * v.x_m)
            cov = np.linalg.inv(info)
            d = cov @ vec
            stat = float(d[:2] @ np.linalg.solve(cov[:2, :2], d[:2]))
            others_clean = any(not v.fires for v in self.verdicts.values() if s not in (v.a, v.b))
            fires = len(mine) >= MIN_NEIGHBOURS and all(v.fires for v in mine) and others_clean
            calm = all(v.statistic < CLEAR_FRACTION * THRESHOLD for v in mine)
            was = s in self.flagged
            if fires and not was:
                self.flagged[s] = t
                self._raise(Alarm(KIND, s, "critical",
                                  f"station {s}: published coordinates off by {_enu_cm(d)} (east, north, up) "
                                  f"against {len(mine)} neighbours ({', '.join(v.name for v in mine)}; chi2 "
                                  f"{stat:.0f} > {THRESHOLD:.1f}); excluded from VRS synthesis", t))
            elif was and calm:
                del self.flagged[s]
                self._raise(Alarm(KIND, s, "info", f"station {s}: coordinates agree with the network again; back "
                                  "in VRS synthesis", t, cleared=True))
            self.offsets[s] = StationOffset(s, d, cov, stat, [v.name for v in mine], s in self.flagged,
                                            self.flagged.get(s, float("nan")))
        for s in list(self.flagged):
            if s not in stations:  # the station left the network: nothing to exclude any more
                del self.flagged[s]

    def forget(self, station: str) -> None:
        """A station left or moved: its windows restart (its baselines restart too)."""
        for name in [n for n, w in self.windows.items() if station in (w.a, w.b)]:
            del self.windows[name]
        self.verdicts = {n: v for n, v in self.verdicts.items() if station not in (v.a, v.b)}
        if self.flagged.pop(station, None) is not None:
            self._raise(Alarm(KIND, station, "info", f"station {station}: new coordinates; checked afresh",
                              self._t_sample, cleared=True))

    def _raise(self, alarm: Alarm) -> None:
        self.alarms.append(alarm)
        self.new_alarms.append(alarm)

    # --- what the engine uses ---------------------------------------------------------------------------

    @property
    def excluded(self) -> set[str]:
        return set(self.flagged)

    def unmodelled_offset(self, station: str) -> tuple[np.ndarray, np.ndarray] | None:
        """(offset east/north/up [m], its covariance) of a station that is not excluded, None without an estimate."""
        o = self.offsets.get(station)
        # below CLEAR_FRACTION of the threshold the offset is the windows' noise, which the bound already holds
        if o is None or o.flagged or o.statistic < CLEAR_FRACTION * THRESHOLD:
            return None
        return o.offset_enu_m, o.cov_m2


def _geometry(nav: NavigationData, xyz, t: float):
    llh = ecef_to_geodetic(np.asarray(xyz, float))
    return enu_rotation(llh[0], llh[1]), {}


def _split(name: str, xyz: dict) -> tuple[str, str]:
    """Station names with '-' in them: the split of `a-b` whose both halves are stations."""
    for k in range(1, len(name)):
        if name[k] == "-" and name[:k] in xyz and name[k + 1:] in xyz:
            return name[:k], name[k + 1:]
    return "", ""


def _enu_cm(d) -> str:
    return ", ".join(f"{v * 100:+.1f}" for v in d) + " cm"
