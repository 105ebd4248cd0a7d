"""Station coordinates checked against the data: a network fixed on a wrong position poisons every train.

Once the baselines fix, their ionosphere-free DD phase residuals (`BaselineEpoch.dd_trop_m`: the non-dispersive
residual beyond the troposphere model, integers removed) carry what the coordinates and the model miss. Over the
first hours of fixed data (`CHECK_WINDOW_S`) a least-squares adjustment explains them by an offset of each
station (east, north, up), each station's residual zenith wet delay (piecewise constant over `ZWD_BLOCK_S`,
Niell wet mapping) and a constant per satellite's single-difference arc: the integers fixed on a wrong position
absorb what they can of its error (measured: 10 cm east vanishes from the residuals without these constants),
so the evidence is how the error changes with the geometry. DD observations see only relative positions, so one station is held; each
station is held in turn, and a station is flagged when its offset from every other station exceeds the limits:
with three stations and one wrong, the wrong one is off from both others, while each good one is off from one.
With two stations a flagged pair says only that one of them is wrong.

Limits (docs/decisions/0163-rtklib-second-opinion.md): on catnet as recorded (130-290 km, GPS only, broadcast
orbits, no antenna models) 3 h windows put the stations within 3.9 cm of each other horizontally and 13 cm
vertically (the vertical trades off against the wet delays) in 7 of the day's 8 windows; hence 5 cm and 15 cm.
A station 10 cm off horizontally shows 8-9 cm from both others and is flagged; 1 cm is not. The 8th window
(06-09 h) put CREU 9-12 cm east of both others: every station is flagged there, cause not found. Spans shorter
than the window get no verdict (1-2 h scatter by 10-30 cm).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from augnet.centre.satellite_geometry import MIN_MODEL_ELEVATION_RAD
from augnet.gnss import troposphere
from augnet.gnss.ephemeris import NavigationData, transit
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.gnss.time import to_datetime

# Data the check uses: the first hours of fixed satellites [s] from the network's first epoch (first fixes come
# after 20-25 min on catnet; 3 h give each satellite pair enough change of geometry to separate the offsets).
CHECK_WINDOW_S = 3 * 3600.0
# Epochs used at most this often [s]: the geometry changes over minutes, and 1 Hz networks stay cheap.
CHECK_INTERVAL_S = 30.0
# Fixed DD residual epochs below which the check gives no verdict (a baseline that never fixed).
MIN_ROWS = 500
# Residual zenith wet delay of each station: constant over blocks of this length [s] (the wet delay moves by
# about a centimetre per hour).
ZWD_BLOCK_S = 1800.0
ZWD_PRIOR_SIGMA_M = 0.10  # of each block's residual zenith wet delay
OFFSET_PRIOR_SIGMA_M = 1.0  # weak: the datum comes from the held station
# Satellites lower than this at either station are not used [deg] (the network's fixing mask).
MIN_ELEVATION_DEG = 15.0
PHASE_SIGMA_M = 0.01  # ionosphere-free DD phase at zenith, for the weights only
OUTLIER_SIGMAS = 4.0  # residuals beyond this many RMS are dropped
OUTLIER_PASSES = 3
# A satellite's single-difference arc ends at a gap longer than this [s].
ARC_GAP_S = 300.0
ARC_BIAS_PRIOR_SIGMA_M = 10.0  # weak: only the arcs' common constant of a baseline is not observed
# Flagging limits [m] of a station's offset from another (measured scatter on catnet: decision 0163).
HORIZONTAL_LIMIT_M = 0.05
VERTICAL_LIMIT_M = 0.15


@dataclass
class StationOffset:
    name: str
    held: str  # the station held at its coordinates
    enu_m: np.ndarray  # (3,) data minus coordinates: where the data put the antenna, from the coordinates
    sigma_enu_m: np.ndarray  # (3,) formal

    @property
    def horizontal_m(self) -> float:
        return float(np.hypot(self.enu_m[0], self.enu_m[1]))

    def exceeds(self, horizontal_limit_m: float = HORIZONTAL_LIMIT_M,
                vertical_limit_m: float = VERTICAL_LIMIT_M) -> bool:
        return self.horizontal_m > horizontal_limit_m or abs(float(self.enu_m[2])) > vertical_limit_m


@dataclass
class CheckResult:
    rows: int  # fixed DD residuals used
    span_s: float
    offsets: list[StationOffset] = field(default_factory=list)  # every station against every held one
    flagged: list[str] = field(default_factory=list)
    window_s: float = CHECK_WINDOW_S
    rms_m: float = float("nan")
    verdict: bool = False  # False: too little fixed data, or too short a span, to judge

    def lines(self) -> list[str]:
        if not self.verdict:
            return [f"station coordinates: not checked ({self.rows} fixed DD residuals over {self.span_s / 3600:.1f} h; "
                    f"the check needs {MIN_ROWS} over {self.window_s / 3600:.0f} h)"]
        out = [f"station coordinates checked against {self.rows} fixed DD residuals over {self.span_s / 3600:.1f} h "
               f"(RMS {self.rms_m * 1e3:.1f} mm); limits {HORIZONTAL_LIMIT_M * 100:.0f} cm horizontal, "
               f"{VERTICAL_LIMIT_M * 100:.0f} cm vertical"]
        names = sorted({o.name for o in self.offsets})
        for n in names:
            parts = [f"from {o.held} E {o.enu_m[0] * 100:+.1f} N {o.enu_m[1] * 100:+.1f} U {o.enu_m[2] * 100:+.1f} cm"
                     for o in self.offsets if o.name == n]
            state = "FLAGGED" if n in self.flagged else "ok"
            out.append(f"station {n} {state}: " + "; ".join(parts))
        if self.flagged and 2 * len(self.flagged) >= len(names):
            out.append(f"station coordinates unconfirmed: {len(self.flagged)} of {len(names)} stations flagged, so the "
                       "check singles out none (not refused)")
        return out


class StationCheck:
    """Collects the fixed DD residuals of the network's first hours and judges the station coordinates."""

    def __init__(self, stations: dict[str, np.ndarray], baselines: dict[str, tuple[str, str]], nav: NavigationData,
                 window_s: float = CHECK_WINDOW_S):
        self.names = list(stations)
        self.xyz = {n: np.asarray(v, float).reshape(3) for n, v in stations.items()}
        self.baselines = baselines  # baseline name -> (station a, station b); residuals are b minus a
        self.nav = nav
        self.window_s = window_s
        llh = {n: ecef_to_geodetic(x) for n, x in self.xyz.items()}
        self._rot = {n: enu_rotation(v[0], v[1]) for n, v in llh.items()}
        self._llh = llh
        self.t_first: float | None = None
        self.t_last: float | None = None
        self._t_used: float | None = None
        # (t, a, b, coef_a (3,), coef_b (3,), map_a, map_b, weight, y, arc of the satellite, arc of the reference)
        self._rows: list[tuple] = []
        self._labels: dict[str, dict[str, tuple[np.ndarray, int, float]]] = {}
        self._arc_count = 0

    @property
    def complete(self) -> bool:
        return self.t_first is not None and self.t_last is not None and self.t_last - self.t_first >= self.window_s

    def add(self, ne) -> None:
        """One `NetworkEpoch` (epochs after the window are ignored)."""
        t = float(ne.t_gpst)
        if not np.isfinite(t):
            return
        if self.t_first is None:
            self.t_first = t
        if t - self.t_first > self.window_s:
            return
        self.t_last = t
        if self._t_used is not None and t - self._t_used < CHECK_INTERVAL_S - 1e-3:
            return
        self._t_used = t
        for name, res in ne.baselines.items():
            if res is None or name not in self.baselines:
                continue
            a, b = self.baselines[name]
            sats = [str(s) for s in res.sats]
            ref_of = np.array([res.refs.get(s[0], "") for s in sats])
            use = (res.fixed & ~res.is_reference() & np.isfinite(res.dd_trop_m)
                   & (np.minimum(res.elevation_a_deg, res.elevation_b_deg) >= MIN_ELEVATION_DEG))
            if not use.any():
                continue
            geo = {n: self._geometry(n, t - ne.clocks.get(n, 0.0), sats) for n in (a, b)}
            pos = {s: k for k, s in enumerate(sats)}
            arc_of = self._sd_arcs(name, t, sats, res)
            for k in np.flatnonzero(use):
                r = pos.get(ref_of[k])
                if r is None:
                    continue
                ua, ma = geo[a]
                ub, mb = geo[b]
                # a coordinate error d (true minus given) changes a range by -u.d: the DD (b - a, k - ref) by
                # -(u_bk - u_br).d_b + (u_ak - u_ar).d_a
                coef_a = self._rot[a] @ (ua[k] - ua[r])
                coef_b = -(self._rot[b] @ (ub[k] - ub[r]))
                el = min(res.elevation_a_deg[k], res.elevation_b_deg[k])
                w = np.sin(np.radians(el)) ** 2 / PHASE_SIGMA_M ** 2
                self._rows.append((t, a, b, coef_a, coef_b, -(ma[k] - ma[r]), mb[k] - mb[r], w,
                                   float(res.dd_trop_m[k]), arc_of[sats[k]], arc_of[sats[r]]))

    def _sd_arcs(self, name: str, t: float, sats: list[str], res) -> dict[str, int]:
        """An arc number per fixed satellite of a baseline: its single-difference integers stay the same through
        changes of reference (the new reference's integers against the old one carry the labels over) and end
        at a slip, a new integer or a gap."""
        prev = self._labels.setdefault(name, {})  # sat -> (label (2,), arc, last t)
        slipped = set(map(str, res.slips))
        fixed = [k for k in range(len(sats)) if res.fixed[k] and np.isfinite(res.dd_n[k]).all()]
        shift = {}  # per system (each has its reference): what most continuing satellites' labels moved by
        for system in {s[0] for s in sats}:
            moved = Counter(tuple(prev[sats[k]][0] - res.dd_n[k]) for k in fixed
                            if sats[k][0] == system and sats[k] in prev and sats[k] not in slipped
                            and t - prev[sats[k]][2] <= ARC_GAP_S)
            shift[system] = np.array(moved.most_common(1)[0][0]) if moved else np.zeros(2)
        out = {}
        for k in fixed:
            s = sats[k]
            label = res.dd_n[k] + shift[s[0]]
            old = prev.get(s)
            if old is None or s in slipped or t - old[2] > ARC_GAP_S or not np.array_equal(old[0], label):
                self._arc_count += 1
                arc = self._arc_count
            else:
                arc = old[1]
            prev[s] = (label, arc, t)
            out[s] = arc
        return out

    def _geometry(self, name: str, t_rx: float, sats: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(S, 3) unit vectors station -> satellite and (S,) Niell wet mapping."""
        tr = transit(self.nav, sats, self.xyz[name], t_rx)
        u = tr.line_of_sight
        up = self._rot[name][2]
        el = np.arcsin(np.clip(u @ up, -1.0, 1.0))
        lat, _, h = self._llh[name]
        doy = to_datetime(t_rx).timetuple().tm_yday
        _, mw = troposphere.niell(np.clip(el, MIN_MODEL_ELEVATION_RAD, None), lat, h, doy)
        return u, mw

    def solve(self, held: str) -> tuple[dict[str, StationOffset], float, int]:
        """Offsets of every other station with `held` at its coordinates: ({name: offset}, RMS [m], rows used).

        Each single-difference arc (`_sd_arcs`) has a free constant: the integers of a wrong coordinate absorb
        what they can of its DD range error, so only the change of that error with the geometry over an arc is
        evidence. Rows touch at most ten parameters: the normal equations are summed from them."""
        if not self._rows:
            return {}, float("nan"), 0
        free = [n for n in self.names if n != held]
        col = {n: 3 * i for i, n in enumerate(free)}
        t = np.array([r[0] for r in self._rows])
        block = ((t - self.t_first) // ZWD_BLOCK_S).astype(int)
        nblk = int(block.max()) + 1
        zcol0 = 3 * len(free)
        zcol = {n: zcol0 + i * nblk for i, n in enumerate(self.names)}
        acol0 = zcol0 + nblk * len(self.names)
        arc_ids = sorted({r[9] for r in self._rows} | {r[10] for r in self._rows})
        acol = {a: acol0 + i for i, a in enumerate(arc_ids)}
        npar = acol0 + len(arc_ids)
        nrow = len(self._rows)
        idx = np.zeros((nrow, 10), int)  # unused slots point at column 0 with a zero coefficient
        val = np.zeros((nrow, 10))
        y = np.empty(nrow)
        w = np.empty(nrow)
        for i, (_, a, b, ca, cb, ma, mb, wi, yi, arc_k, arc_r) in enumerate(self._rows):
            if a in col:
                idx[i, 0:3], val[i, 0:3] = range(col[a], col[a] + 3), ca
            if b in col:
                idx[i, 3:6], val[i, 3:6] = range(col[b], col[b] + 3), cb
            idx[i, 6:10] = (zcol[a] + block[i], zcol[b] + block[i], acol[arc_k], acol[arc_r])
            val[i, 6:10] = (ma, mb, 1.0, -1.0)
            y[i], w[i] = yi, wi
        prior = np.r_[np.full(zcol0, OFFSET_PRIOR_SIGMA_M ** -2), np.full(acol0 - zcol0, ZWD_PRIOR_SIGMA_M ** -2),
                      np.full(npar - acol0, ARC_BIAS_PRIOR_SIGMA_M ** -2)]
        keep = np.ones(nrow, bool)
        for _ in range(OUTLIER_PASSES):
            wk = np.where(keep, w, 0.0)
            N = np.diag(prior)
            np.add.at(N, (idx[:, :, None], idx[:, None, :]), wk[:, None, None] * val[:, :, None] * val[:, None, :])
            rhs = np.zeros(npar)
            np.add.at(rhs, idx, (wk * y)[:, None] * val)
            x = np.linalg.solve(N, rhs)
            v = y - (val * x[idx]).sum(axis=1)
            rms = float(np.sqrt(np.mean(v[keep] ** 2)))
            keep = np.abs(v) <= OUTLIER_SIGMAS * rms
        cov = np.linalg.inv(N)[:zcol0, :zcol0]
        out = {n: StationOffset(n, held, x[col[n]:col[n] + 3].copy(), np.sqrt(np.diag(cov)[col[n]:col[n] + 3]))
               for n in free}
        return out, rms, int(keep.sum())

    def result(self) -> CheckResult:
        """Every station against every other held, and the stations flagged."""
        span = (self.t_last - self.t_first) if self.t_first is not None and self.t_last is not None else 0.0
        res = CheckResult(rows=len(self._rows), span_s=span, window_s=self.window_s)
        # shorter spans are not judged: 1-2 h solutions on catnet scatter by 10-30 cm (decision 0163)
        if len(self._rows) < MIN_ROWS or len(self.names) < 2 or not self.complete:
            return res
        res.verdict = True
        rms = []
        for h in self.names:
            offs, r, _ = self.solve(h)
            rms.append(r)
            res.offsets.extend(offs.values())
        res.rms_m = float(np.median(rms))
        for n in self.names:
            against = [o for o in res.offsets if o.name == n]
            if against and all(o.exceeds() for o in against):
                res.flagged.append(n)
        return res

