"""RTKLIB's second opinion on the network's integers: `rnx2rtkp` static on a baseline, its fixed DD
ambiguities read back, compared with ours in reference-free form (docs/decisions/0163-rtklib-second-opinion.md).

RTKLIB 2.4.3 writes no ambiguity values to its solution status file; its trace (level 4) writes the best integer
vector of each LAMBDA search (`N(1)=`), followed by `resamb : validation ok` when it is accepted. The vector is
in RTKLIB's double-difference order (rtkpos.c `ddidx`): per frequency, the reference is the lowest-numbered
satellite taking part and the others follow in satellite order, each entry the reference's single-difference
(rover minus base) ambiguity minus the other's. Which satellites took part is the solution status file's `$SAT`
fix field (2 fix, 3 hold). Both programs start their ambiguities from the raw RINEX phase, so a DD integer is the
same number on both sides: per epoch and satellite pair (i, j) fixed by both, N(i) - N(j) per frequency.

The comparison rule: within a pair's continuous arc on both sides (no slip, no gap, on either program, for either
satellite) the difference of the two programs' N(i) - N(j) must stay constant; each epoch where it differs from
the arc's most frequent value is a disagreement. The arc's value itself is reported apart (`offset_arcs`): with
the same raw phase it is 0, and a non-zero one means one side held a wrong integer for the whole arc.
"""

from __future__ import annotations

import datetime as _dt
import re
import subprocess
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

GPS_EPOCH = _dt.datetime(1980, 1, 6)
SECONDS_PER_WEEK = 604800.0

# rnx2rtkp settings of the second opinion (option table of RTKLIB 2.4.3 b34, options.c). Static, L1+L2, GPS;
# the slant ionosphere estimated per satellite (130-290 km at 30 s: the DD ionosphere is decimetres) with a
# 3 mm/sqrt(s) random walk; troposphere estimated; fix-and-hold, ratio 3, ambiguities above 15 degrees (the
# network's fixing mask). Measured on catnet (decision 0163): first fix after 2 h 15 min on CREU-GARR.
RNX2RTKP_OPTIONS = {
    "pos1-posmode": "static",
    "pos1-frequency": "l1+2",
    "pos1-soltype": "forward",
    "pos1-elmask": "10",
    "pos1-dynamics": "off",
    "pos1-tidecorr": "off",
    "pos1-ionoopt": "est-stec",
    "pos1-tropopt": "est-ztd",
    "pos1-sateph": "brdc",
    "pos1-navsys": "1",
    "pos2-armode": "fix-and-hold",
    "pos2-gloarmode": "off",
    "pos2-arthres": "3",
    "pos2-arlockcnt": "0",
    "pos2-arelmask": "15",
    "pos2-arminfix": "10",
    "pos2-elmaskhold": "15",
    "pos2-aroutcnt": "5",
    "pos2-slipthres": "0.05",
    "pos2-maxage": "30",
    "pos2-rejionno": "30",
    "pos2-niter": "1",
    "out-solformat": "xyz",
    "out-outhead": "on",
    "out-solstatic": "all",
    "out-outstat": "residual",
    "stats-prniono": "0.003",
    "stats-prntrop": "0.0001",
    "ant1-antdele": "0", "ant1-antdeln": "0", "ant1-antdelu": "0",
    "ant2-postype": "xyz",
    "ant2-antdele": "0", "ant2-antdeln": "0", "ant2-antdelu": "0",
    "misc-timeinterp": "off",
}
# RTKLIB trace level that writes the LAMBDA integer vectors (rtkpos.c: trace(4, "N(1)=")).
TRACE_LEVEL_INTEGERS = 4
# $SAT fix field values of an ambiguity taking part in the accepted integer vector (rtkpos.c: 2 fix, 3 hold).
RTKLIB_FIXED_FLAGS = (2, 3)


def gpst_to_text(t_gpst: float) -> str:
    """GPS seconds since 1980-01-06 -> 'YYYY/MM/DD HH:MM:SS' (rnx2rtkp -ts/-te)."""
    return (GPS_EPOCH + _dt.timedelta(seconds=float(t_gpst))).strftime("%Y/%m/%d %H:%M:%S")


def run_rnx2rtkp(exe: str, rover_obs: Path, base_obs: Path, nav: Path, base_xyz_m, t_start: float, t_end: float,
                 workdir: Path, name: str) -> tuple[Path, Path, Path]:
    """rnx2rtkp static on one baseline (rover = the baseline's station b, base = a, at `base_xyz_m`, its antenna
    reference point); returns (solution, status, trace) paths. Inputs must be uncompressed (RTKLIB unpacks .gz
    next to the file)."""
    workdir = Path(workdir)
    conf = workdir / f"{name}.conf"
    conf.write_text("".join(f"{k:<18} ={v}\n" for k, v in RNX2RTKP_OPTIONS.items()))
    out = workdir / f"{name}.pos"
    cmd = [exe, "-k", str(conf), "-x", str(TRACE_LEVEL_INTEGERS), "-ts", *gpst_to_text(t_start).split(),
           "-te", *gpst_to_text(t_end).split(), "-r", *(f"{v:.4f}" for v in base_xyz_m), "-o", str(out),
           str(rover_obs), str(base_obs), str(nav)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=1800)
    return out, Path(str(out) + ".stat"), Path(str(out) + ".trace")


@dataclass
class SatStatus:
    fix: int
    slip: int
    lock: int
    outc: int


def read_sat_status(path: Path) -> dict[float, dict[tuple[str, int], SatStatus]]:
    """`$SAT` lines of a solution status file: {t_gpst: {(sat, frequency 1/2): status}}."""
    out: dict[float, dict[tuple[str, int], SatStatus]] = defaultdict(dict)
    with open(path) as f:
        for line in f:
            if not line.startswith("$SAT,"):
                continue
            p = line.strip().split(",")
            # $SAT,week,tow,sat,frq,az,el,resp,resc,vsat,snr,fix,slip,lock,outc,slipc,rejc
            t = round(int(p[1]) * SECONDS_PER_WEEK + float(p[2]), 3)
            out[t][(p[3], int(p[4]))] = SatStatus(int(p[11]), int(p[12]), int(p[13]), int(p[14]))
    return dict(out)


_TRACE_TIME = re.compile(r"rtkpos  : time=(\d{4})/(\d\d)/(\d\d) (\d\d):(\d\d):(\d\d(?:\.\d+)?)")


def read_accepted_integers(path: Path) -> dict[float, np.ndarray]:
    """The accepted LAMBDA integer vector of each epoch of an rnx2rtkp trace (level 4): {t_gpst: (nb,)}."""
    out: dict[float, np.ndarray] = {}
    t = None
    best = None
    with open(path, errors="replace") as f:
        for line in f:
            if "rtkpos  : time=" in line:
                m = _TRACE_TIME.search(line)
                y, mo, d, h, mi, s = m.groups()
                dt = _dt.datetime(int(y), int(mo), int(d), int(h), int(mi)) - GPS_EPOCH
                t = round(dt.total_seconds() + float(s), 3)
                best = None
            elif line.startswith("4 N(1)="):
                best = np.array([float(x) for x in line[7:].split()])
            elif "resamb : validation ok" in line and t is not None and best is not None:
                out[t] = best
    return out


def rtklib_fixed(status: dict[float, dict[tuple[str, int], SatStatus]],
                 accepted: dict[float, np.ndarray]) -> dict[float, dict[int, dict[str, int]]]:
    """Per accepted epoch and frequency index (0, 1): {sat: N(sat) - N(reference)} of RTKLIB's single-difference
    (rover minus base) ambiguities, the reference at 0."""
    out: dict[float, dict[int, dict[str, int]]] = {}
    for t, vec in accepted.items():
        st = status.get(t)
        if st is None:
            continue
        per_f: dict[int, dict[str, int]] = {}
        k = 0
        for f in (1, 2):
            sats = sorted((s for (s, fr), v in st.items() if fr == f and v.fix in RTKLIB_FIXED_FLAGS),
                          key=lambda s: (s[0], int(s[1:])))
            if len(sats) < 2:
                continue
            n = len(sats) - 1
            # entries are N(ref) - N(sat): the satellite's integer against the reference is minus that
            per_f[f - 1] = {sats[0]: 0, **{s: -int(round(v)) for s, v in zip(sats[1:], vec[k:k + n])}}
            k += n
        if k != len(vec):
            raise ValueError(f"RTKLIB epoch {t}: {len(vec)} integers but {k} fixed ambiguities in $SAT")
        out[t] = per_f
    return out


def rtklib_arcs(status: dict[float, dict[tuple[str, int], SatStatus]]) -> dict[float, dict[tuple[str, int], int]]:
    """An arc number per epoch, satellite and frequency: a new arc after a slip or when the lock count does not
    follow on (a reset or a gap)."""
    arcs: dict[float, dict[tuple[str, int], int]] = {}
    last: dict[tuple[str, int], tuple[int, int]] = {}  # key -> (lock, arc)
    counter = 0
    for t in sorted(status):
        arcs[t] = {}
        for key, v in status[t].items():
            prev = last.get(key)
            if prev is None or v.slip & 1 or v.lock != prev[0] + 1:
                counter += 1
                arc = counter
            else:
                arc = prev[1]
            last[key] = (v.lock, arc)
            arcs[t][(key[0], key[1] - 1)] = arc
    return arcs


@dataclass
class OurIntegers:
    """Our fixed DD integers of one baseline, epoch by epoch, with an arc number per satellite (new after a slip
    or an absence)."""

    fixed: dict[float, dict[str, tuple[float, float]]] = field(default_factory=dict)  # t -> sat -> (N1, N2)
    arcs: dict[float, dict[str, int]] = field(default_factory=dict)
    _last_t: float | None = None
    _arc: dict[str, int] = field(default_factory=dict)
    _counter: int = 0

    def add(self, res) -> None:
        """One epoch's `BaselineEpoch`."""
        t = round(float(res.t_gpst), 3)
        prev = self.arcs.get(self._last_t, {}) if self._last_t is not None else {}
        cur: dict[str, int] = {}
        slipped = set(map(str, res.slips))
        for s in map(str, res.sats):
            if s in prev and s not in slipped:
                cur[s] = prev[s]
            else:
                self._counter += 1
                cur[s] = self._counter
        self.arcs[t] = cur
        self._last_t = t
        self.fixed[t] = {str(s): (float(n[0]), float(n[1])) for s, n, ok in zip(res.sats, res.dd_n, res.fixed)
                         if ok and np.isfinite(n).all()}


@dataclass
class Comparison:
    pair_epochs: int = 0  # satellite-pair-epochs (per frequency) fixed by both
    agreements: int = 0
    disagreements: int = 0
    ours_only: int = 0  # pair-epochs we fixed and RTKLIB did not (at epochs RTKLIB has a status for)
    rtklib_only: int = 0
    arcs: int = 0
    offset_arcs: int = 0  # arcs whose constant difference is not 0
    examples: list[str] = field(default_factory=list)


def _pairs(n: int) -> int:
    return n * (n - 1) // 2


def compare(ours: OurIntegers, rtk_fixed: dict[float, dict[int, dict[str, int]]],
            rtk_arcs: dict[float, dict[tuple[str, int], int]], max_examples: int = 10) -> Comparison:
    """Reference-free comparison of the two programs' DD integers on one baseline (the rule in the docstring)."""
    cmp = Comparison()
    diffs: dict[tuple, list[tuple[float, int]]] = defaultdict(list)
    for t, mine in ours.fixed.items():
        if t not in rtk_arcs:
            continue
        theirs_f = rtk_fixed.get(t, {})
        for f in (0, 1):
            theirs = theirs_f.get(f, {})
            a = sorted(mine)
            both = [s for s in a if s in theirs]
            n_mine, n_theirs, n_both = len(a), len(theirs), len(both)
            cmp.ours_only += _pairs(n_mine) - _pairs(n_both)
            cmp.rtklib_only += _pairs(n_theirs) - _pairs(n_both)
            for x in range(n_both):
                for y in range(x + 1, n_both):
                    i, j = both[x], both[y]
                    d = int(round((mine[i][f] - mine[j][f]) - (theirs[i] - theirs[j])))
                    key = (i, j, f, ours.arcs[t][i], ours.arcs[t][j], rtk_arcs[t][(i, f)], rtk_arcs[t][(j, f)])
                    diffs[key].append((t, d))
    for key, vals in diffs.items():
        counts = Counter(d for _, d in vals)
        mode, n_mode = counts.most_common(1)[0]
        cmp.arcs += 1
        cmp.pair_epochs += len(vals)
        cmp.agreements += n_mode
        cmp.disagreements += len(vals) - n_mode
        if mode != 0:
            cmp.offset_arcs += 1
        if (mode != 0 or len(vals) > n_mode) and len(cmp.examples) < max_examples:
            i, j, f = key[:3]
            cmp.examples.append(f"{i}-{j} L{f + 1} from t={vals[0][0]:.0f}: {dict(counts)}")
    return cmp
