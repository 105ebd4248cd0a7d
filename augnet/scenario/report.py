"""The run report: figures per train, per baseline and for the interpolation, each against the truth, and
the issue's targets with measured value and pass/fail. Written as `report.json` (keys below; the README's
"Scenario runs" section documents each), plus `epochs.csv` (one row per train and epoch).

report.json (version "augnet-scenario-report/1"); times in seconds since the scenario start, lengths in m:

    version, scenario {name, seed, start, duration_s, rate_hz, ionosphere, stations, check_points, trains},
    run {epochs, warm_up_s, centre_start_s, world_epochs, network_epochs, wall_s, real_time_factor},
    latency_model {...}, definitions {...},
    trains {<id>: {epochs, epochs_without_sky, status_counts, session_opened_s, vrs_moves, gga_sent, vrs_masters,
                   vrs_master_changes [{t_s, from, to}],
                   corrections_usable_s, first_fix_s, ttff_s, acquisitions [...], acquisition_time_median_s,
                   fix_rate_after_first_fix, fix_rate_after_first_fix_incl_no_sky,
                   horizontal_error_m, vertical_error_m, along_track_error_m, cross_track_error_m
                       (fixed epochs: n, p50, p95, p99, rms, max of absolute values),
                   horizontal_error_all_m, vertical_error_all_m (every epoch with a position), wrong_fixes,
                   track_id {epochs_with_position, right, wrong, off_map, confirmed, confirmed_wrong},
                   virtual_balises {expected, captured, missed, missed_in_gnss_outage, missed_with_gnss, false,
                                    capture_error_m, events [...], missed_ids, false_ids},
                   protection_level {integrity_risk, k, alert_limit_m, hpl_m, vpl_m, h_error_over_hpl,
                                     v_error_over_vpl, misleading, hazardously_misleading, unavailable},
                   correction_age_s {n, p50, p95, max, over_limit, limit_s, epochs_without},
                   along_track_fusion {<method>: {epochs, available, availability, alarms, hmi, rejected_fixes,
                                       available_from_newest_fix,
                                       error_available_m, pl_available_m, epochs_without_sky,
                                       available_without_sky, hmi_without_sky}}}},
    baselines {<name>: {station_a, station_b, length_km, first_fix_s (since the centre's start),
                        fixed_fraction_mean, arcs, arcs_fixed, arc_time_to_fix_s {median, p75}, checked,
                        wrong_fixes, wrong_examples}},
    network {arcs, arcs_fixed, arc_time_to_fix_median_s, checked, wrong_fixes},
    interpolation {dd_iono_error_m {n, p50, p95, rms, max}, dd_iono_error_from_truth_residuals_m {...},
                   points {<id>: {network {...}, from_truth_residuals {...}}}},
    targets [{id, subject, description, target, measured, unit, pass}], passed, files
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from augnet.onboard.rtk import Status
from augnet.onboard.trackmap import gaussian_k
from augnet.scenario import metrics as M
from augnet.scenario.truth import passages
from stations.kinematics import train_motion

VERSION = "augnet-scenario-report/1"
REPORT_JSON = "report.json"
EPOCHS_CSV = "epochs.csv"
# Horizontal alert limit of the Stanford plot and the availability count: 1.7 m, the track-discrimination
# and odometry-correction alert limit of the Helmet project (../shared/design/railway.md).
DEFAULT_ALERT_LIMIT_M = 1.7

# --- the targets (issue 8: step 5 per train, step 4 for the network) ---------------------------
TARGET_FIX_RATE = 0.99  # fixed in >= 99 % of epochs (with sky) after the first fix
TARGET_TTFF_S = 10.0  # median time to (re-)fix
TARGET_H95_M = 0.02
TARGET_V95_M = 0.04
TARGET_BALISE_ERROR_M = 0.5
TARGET_BASELINE_FIX_S = 60.0  # median time for a satellite arc to fix on a baseline
TARGET_INTERP_RMS_M = 0.01  # interpolated DD ionosphere, quiet ionosphere only

# The schema: the keys every report has (nested dicts by path), checked by `schema_problems`.
SCHEMA = {
    "version": str, "scenario": dict, "run": dict, "latency_model": dict, "definitions": dict,
    "trains": dict, "baselines": dict, "network": dict, "interpolation": dict, "targets": list,
    "passed": bool, "files": list,
}
TRAIN_KEYS = ("epochs", "epochs_without_sky", "status_counts", "corrections_usable_s", "first_fix_s", "ttff_s",
              "acquisitions", "acquisition_time_median_s", "fix_rate_after_first_fix",
              "fix_rate_after_first_fix_incl_no_sky", "horizontal_error_m", "vertical_error_m",
              "along_track_error_m", "cross_track_error_m", "horizontal_error_all_m", "wrong_fixes", "track_id",
              "virtual_balises", "protection_level", "correction_age_s", "along_track_fusion")
BASELINE_KEYS = ("station_a", "station_b", "length_km", "first_fix_s", "fixed_fraction_mean", "arcs", "arcs_fixed",
                 "arc_time_to_fix_s", "checked", "wrong_fixes")
TARGET_KEYS = ("id", "subject", "description", "target", "measured", "unit", "pass")
STAT_KEYS = ("n", "p50", "p95", "rms", "max")


@dataclass
class Report:
    scenario: dict
    run: dict
    latency_model: dict
    definitions: dict
    trains: dict
    baselines: dict
    network: dict
    interpolation: dict
    targets: list
    files: list = field(default_factory=list)
    version: str = VERSION

    @property
    def passed(self) -> bool:
        return all(t["pass"] is not False for t in self.targets)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["passed"] = self.passed
        order = ["version", "scenario", "run", "latency_model", "definitions", "trains", "baselines", "network",
                 "interpolation", "targets", "passed", "files"]
        return _clean({k: d[k] for k in order})

    def write(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n")

    def target(self, target_id: str) -> dict:
        for t in self.targets:
            if t["id"] == target_id:
                return t
        raise KeyError(target_id)


def _clean(x):
    """JSON-safe: NaN/inf -> None, numpy scalars -> Python, floats rounded to 0.1 mm / 4 significant places."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        v = float(x)
        if not math.isfinite(v):
            return None
        return round(v, 4) if abs(v) >= 1e-3 or v == 0.0 else float(f"{v:.4g}")
    return x


def schema_problems(d: dict) -> list[str]:
    """What is missing or mistyped in a report dictionary (empty when it follows the schema)."""
    problems = []
    for k, typ in SCHEMA.items():
        if k not in d:
            problems.append(f"missing key {k!r}")
        elif not isinstance(d[k], typ):
            problems.append(f"{k!r} is {type(d[k]).__name__}, expected {typ.__name__}")
    if problems:
        return problems
    if d["version"] != VERSION:
        problems.append(f"version {d['version']!r}, expected {VERSION!r}")
    for tid, tr in d["trains"].items():
        problems += [f"trains.{tid}: missing {k!r}" for k in TRAIN_KEYS if k not in tr]
        for k in ("horizontal_error_m", "vertical_error_m", "along_track_error_m", "cross_track_error_m"):
            if isinstance(tr.get(k), dict):
                problems += [f"trains.{tid}.{k}: missing {s!r}" for s in STAT_KEYS if s not in tr[k]]
    for name, b in d["baselines"].items():
        problems += [f"baselines.{name}: missing {k!r}" for k in BASELINE_KEYS if k not in b]
    for i, t in enumerate(d["targets"]):
        problems += [f"targets[{i}]: missing {k!r}" for k in TARGET_KEYS if k not in t]
        if "pass" in t and t["pass"] not in (True, False, None):
            problems.append(f"targets[{i}].pass must be true, false or null")
    if "dd_iono_error_m" not in d["interpolation"]:
        problems.append("interpolation: missing 'dd_iono_error_m'")
    return problems


# --- building ---------------------------------------------------------------------------------------------

def _arrays(tl):
    t = np.array(tl.t_s, float)
    pos = np.array(tl.position, float).reshape(-1, 3)
    cov = np.array(tl.covariance, float).reshape(-1, 3, 3)
    truth = np.array(tl.truth_position, float).reshape(-1, 3)
    status = np.array(tl.status, int)
    return t, pos, cov, truth, status


def train_figures(log, tl, alert_limit_m: float) -> tuple[dict, dict]:
    """(figures for report.json, per-epoch series for the plots and CSV) of one train."""
    t, pos, cov, truth, status = _arrays(tl)
    n = len(t)
    sky = np.array(tl.n_tracked) > 0
    has_pos = np.all(np.isfinite(pos), axis=1)
    fixed = status == Status.FIX
    enu = np.full((n, 3), np.nan)
    if has_pos.any():
        enu[has_pos] = M.enu_errors(pos[has_pos], truth[has_pos])
    h = np.hypot(enu[:, 0], enu[:, 1])
    v = np.abs(enu[:, 2])
    err3 = np.linalg.norm(enu, axis=1)
    # along / cross track at the truth's place on the map
    db = log.track_db
    along = np.full(n, np.nan)
    cross = np.full(n, np.nan)
    if db is not None:
        for i in np.flatnonzero(has_pos):
            m = db.match(truth[i])
            if m.track is None:
                continue
            T, N, _ = db.tangent_at(m.track, m.km)
            d = pos[i] - truth[i]
            along[i], cross[i] = float(d @ T), float(d @ N)
    # corrections usable / first fix / acquisitions
    min_sats = log.min_rtk_satellites
    usable = np.flatnonzero((np.array(tl.base_sats) >= min_sats) & sky)
    usable_from = int(usable[0]) if usable.size else None
    acq = M.acquisitions(t, fixed, sky, usable_from)
    first_fix = int(np.flatnonzero(fixed)[0]) if fixed.any() else None
    after = np.arange(n) >= (first_fix if first_fix is not None else n)
    denom = after & sky
    fix_rate = float(fixed[denom].mean()) if denom.any() else None
    fix_rate_all = float(fixed[after].mean()) if after.any() else None
    # protection levels
    k = gaussian_k(log.integrity_risk)
    hpl, vpl = M.protection_levels(pos, cov, k)
    over_h = has_pos & (h > hpl)
    over_v = has_pos & (v > vpl)
    mi = over_h & (h <= alert_limit_m)
    hmi = over_h & (h > alert_limit_m) & (hpl <= alert_limit_m)
    unavailable = has_pos & (hpl > alert_limit_m)
    # track identity
    track = np.array(tl.track, dtype=object)
    confirmed = np.array(tl.confirmed, bool)
    truth_track = np.array(tl.truth_edge, dtype=object) if tl.truth_edge else tl.truth_track  # layout: per epoch
    right = has_pos & (track == truth_track)
    off_map = has_pos & (track == "")
    wrong = has_pos & ~right & ~off_map
    # correction age
    age = np.array(tl.age_s, float)
    has_age = np.isfinite(age)
    age_stats = M.pct(age[has_age], (50, 95))
    age_stats.update({"over_limit": int((age[has_age] > log.age_limit_s).sum()), "limit_s": log.age_limit_s,
                      "epochs_without": int((~has_age).sum())})
    balises = balise_figures(log, tl, t, sky)
    figures = {
        "epochs": n, "epochs_without_sky": int((~sky).sum()),
        "status_counts": {s.name.lower(): int((status == s).sum()) for s in Status},
        "session_opened_s": tl.session_opened_s, "vrs_moves": tl.vrs_moves, "gga_sent": tl.gga_sent,
        "vrs_masters": sorted({m for m in tl.vrs_master if m}),
        "vrs_master_changes": [{"t_s": float(t[i]), "from": tl.vrs_master[i - 1], "to": tl.vrs_master[i]}
                               for i in range(1, n) if tl.vrs_master[i] and tl.vrs_master[i - 1]
                               and tl.vrs_master[i] != tl.vrs_master[i - 1]],
        "corrections_usable_s": float(t[usable_from]) if usable_from is not None else None,
        "first_fix_s": float(t[first_fix]) if first_fix is not None else None,
        "ttff_s": acq[0]["time_s"] if acq else None,
        "acquisitions": acq,
        # an acquisition that never fixed counts as infinitely long (written as null)
        "acquisition_time_median_s": float(np.median([math.inf if a["time_s"] is None else a["time_s"] for a in acq]))
        if acq else None,
        "fix_rate_after_first_fix": fix_rate, "fix_rate_after_first_fix_incl_no_sky": fix_rate_all,
        "horizontal_error_m": M.pct(h[fixed]), "vertical_error_m": M.pct(v[fixed]),
        "along_track_error_m": M.pct(np.abs(along[fixed])), "cross_track_error_m": M.pct(np.abs(cross[fixed])),
        "horizontal_error_all_m": M.pct(h[has_pos]),
        "vertical_error_all_m": M.pct(v[has_pos]),
        "wrong_fixes": int((fixed & (err3 > M.WRONG_FIX_ERROR_M)).sum()),
        "track_id": {"epochs_with_position": int(has_pos.sum()), "right": int(right.sum()), "wrong": int(wrong.sum()),
                     "off_map": int(off_map.sum()), "confirmed": int((has_pos & confirmed).sum()),
                     "confirmed_wrong": int((wrong & confirmed).sum())},
        "virtual_balises": balises,
        "protection_level": {"integrity_risk": log.integrity_risk, "k": k, "alert_limit_m": alert_limit_m,
                             "hpl_m": M.pct(hpl[has_pos], (50, 95)), "vpl_m": M.pct(vpl[has_pos], (50, 95)),
                             "h_error_over_hpl": int(over_h.sum()), "v_error_over_vpl": int(over_v.sum()),
                             "misleading": int(mi.sum()), "hazardously_misleading": int(hmi.sum()),
                             "unavailable": int(unavailable.sum())},
        "correction_age_s": age_stats,
        "along_track_fusion": fusion_figures(tl),
    }
    series = {"t": t, "status": status, "h": h, "v": v, "along": along, "cross": cross, "hpl": hpl, "vpl": vpl,
              "sky": sky, "age": age, "enu": enu, "position": pos}
    return figures, series


def fusion_figures(tl) -> dict:
    """The along-track methods side by side over every epoch of the run (tunnels included), against the truth.

    Per method: available (a position with PL under the alert limit), alarms (the position withdrawn),
    HMI (|error| > PL while available), errors of the available epochs, and the same over the epochs
    without sky; rejected fixes and lockouts (the residual check)."""
    truth = np.array(tl.truth_km, float) * 1000.0
    no_sky = np.array(tl.n_tracked) == 0
    out = {}
    for method, fused in tl.fused.items():
        if len(fused) != len(truth):
            continue
        x = np.array([f.position_m for f in fused], float)
        pl = np.array([f.pl_m for f in fused], float)
        avail = np.array([f.available for f in fused], bool)
        err = np.abs(x - truth)
        hmi = avail & (err > pl)
        n = len(fused)
        out[method] = {
            "epochs": n, "available": int(avail.sum()), "availability": float(avail.mean()) if n else None,
            "alarms": int(sum(f.alarm for f in fused)), "hmi": int(hmi.sum()),
            "rejected_fixes": int(sum(f.rejected for f in fused)),
            "available_from_newest_fix": int(sum(f.available and f.from_fix for f in fused)),
            "error_available_m": M.pct(err[avail], (50, 95)), "pl_available_m": M.pct(pl[avail], (50, 95)),
            "epochs_without_sky": int(no_sky.sum()), "available_without_sky": int((avail & no_sky).sum()),
            "hmi_without_sky": int((hmi & no_sky).sum()),
        }
    return out


def balise_figures(log, tl, t: np.ndarray, sky: np.ndarray) -> dict:
    """Expected passages from the truth motion, against the unit's captures."""
    db = log.track_db
    empty = {"expected": 0, "captured": 0, "missed": 0, "missed_in_gnss_outage": 0, "missed_with_gnss": 0,
             "false": 0, "capture_error_m": M.pct([], (50, 95)), "events": [], "missed_ids": [], "false_ids": []}
    if db is None:
        return empty
    train = next(x for x in log.scenario.trains if x.id == tl.id)
    t0 = log.t0
    bal = [b for b in db.balises if b.track == tl.truth_track]
    truth_s = np.array(tl.truth_km, float) * 1000.0
    if len(t) < 2 or not bal:
        return empty
    pass_t = passages(truth_s, t, np.array([b.km * 1000.0 for b in bal]))
    expected = {b.id: (b, pt) for b, pt in zip(bal, pass_t) if np.isfinite(pt)}
    # outage windows: from the last epoch with sky before a run without sky to the first one after it
    windows = [(t[max(a - 1, 0)], t[min(b, len(t) - 1)]) for a, b in M.runs(~sky)]
    events = []
    captured = set()
    false_ids = []
    cap_times = np.array([ev.time - t0 for ev in tl.events], float)
    s_at_capture = train_motion(train, log.line_length_m, cap_times).s_m if len(cap_times) else np.zeros(0)
    errors = []
    for ev, s_true in zip(tl.events, s_at_capture):
        if ev.balise_id not in expected or ev.balise_id in captured:
            false_ids.append(ev.balise_id)
            continue
        captured.add(ev.balise_id)
        direction = 1 if train.direction > 0 else -1
        err = (s_true - ev.km * 1000.0) * direction  # > 0: captured after the train's antenna passed it
        errors.append(abs(err))
        events.append({"id": ev.balise_id, "t_s": ev.time - t0, "error_m": err, "along_pl_m": ev.along_pl_m,
                       "late": ev.late})
    missed = [bid for bid in expected if bid not in captured]
    in_outage = [bid for bid in missed if any(a <= expected[bid][1] <= b for a, b in windows)]
    out = {"expected": len(expected), "captured": len(captured), "missed": len(missed),
           "missed_in_gnss_outage": len(in_outage), "missed_with_gnss": len(missed) - len(in_outage),
           "false": len(false_ids), "capture_error_m": M.pct(errors, (50, 95)), "events": events,
           "missed_ids": missed, "false_ids": false_ids, "outage_ids": in_outage}
    return out


def baseline_figures(bl, warm_up_s: float = 0.0) -> dict:
    """One baseline's figures; `first_fix_s` since the centre's start (`warm_up_s` before the scenario's)."""
    ff = np.array(bl.fixed_fraction, float)
    ts = np.array(bl.t_s, float) + warm_up_s
    first = np.flatnonzero(ff >= 0.5)
    ttf = np.array(list(bl.time_to_fix.values()), float)
    return {"station_a": bl.station_a, "station_b": bl.station_b, "length_km": bl.length_m / 1000.0,
            "first_fix_s": float(ts[first[0]]) if first.size else None,
            "fixed_fraction_mean": float(ff[first[0]:].mean()) if first.size else (float(ff.mean()) if ff.size else None),
            "arcs": len(bl.arc_start), "arcs_fixed": len(bl.time_to_fix),
            "arc_time_to_fix_s": {"median": float(np.median(ttf)) if ttf.size else None,
                                  "p75": float(np.percentile(ttf, 75)) if ttf.size else None},
            "checked": bl.checked, "wrong_fixes": bl.wrong,
            "wrong_examples": [{"t_s": a, "sat": s} for a, s in bl.wrong_examples]}


def _target(tid, subject, description, target, measured, unit, ok):
    return {"id": tid, "subject": subject, "description": description, "target": target, "measured": measured,
            "unit": unit, "pass": ok}


def targets(trains: dict, baselines: dict, network: dict, interp: dict, quiet: bool) -> list[dict]:
    out = []
    def le(x, lim):  # a figure that could not be measured (never fixed) fails
        return x is not None and bool(x <= lim)

    for tid, f in trains.items():
        b = f["virtual_balises"]
        pl = f["protection_level"]
        tr = f["track_id"]
        out += [
            _target(f"{tid}.fix_rate", tid, "fixed epochs after the first fix (epochs with sky)", f">= {TARGET_FIX_RATE}",
                    f["fix_rate_after_first_fix"], "fraction",
                    f["fix_rate_after_first_fix"] is not None and f["fix_rate_after_first_fix"] >= TARGET_FIX_RATE),
            _target(f"{tid}.ttff", tid, "median time to fix over acquisitions (first fix, after each outage)",
                    f"<= {TARGET_TTFF_S}", f["acquisition_time_median_s"], "s",
                    le(f["acquisition_time_median_s"], TARGET_TTFF_S)),
            _target(f"{tid}.h95", tid, "horizontal error at 95 % (fixed epochs)", f"<= {TARGET_H95_M}",
                    f["horizontal_error_m"]["p95"], "m", le(f["horizontal_error_m"]["p95"], TARGET_H95_M)),
            _target(f"{tid}.v95", tid, "vertical error at 95 % (fixed epochs)", f"<= {TARGET_V95_M}",
                    f["vertical_error_m"]["p95"], "m", le(f["vertical_error_m"]["p95"], TARGET_V95_M)),
            _target(f"{tid}.wrong_fixes", tid, f"fixed epochs over {M.WRONG_FIX_ERROR_M} m from the truth", "0",
                    f["wrong_fixes"], "epochs", f["wrong_fixes"] == 0),
            _target(f"{tid}.track_id", tid, "epochs with a position on the wrong track or off the map", "0",
                    tr["wrong"] + tr["off_map"], "epochs", tr["wrong"] + tr["off_map"] == 0),
            _target(f"{tid}.balise_error", tid, "largest virtual balise capture error", f"<= {TARGET_BALISE_ERROR_M}",
                    b["capture_error_m"]["max"], "m",
                    le(b["capture_error_m"]["max"], TARGET_BALISE_ERROR_M) if b["captured"] else
                    (False if b["expected"] else None)),
            _target(f"{tid}.balise_missed", tid, "virtual balises missed where GNSS was available "
                    f"(missed in GNSS outages, the odometer's: {b['missed_in_gnss_outage']})", "0",
                    b["missed_with_gnss"], "balises", b["missed_with_gnss"] == 0),
            _target(f"{tid}.balise_false", tid, "false virtual balise captures", "0", b["false"], "balises",
                    b["false"] == 0),
            _target(f"{tid}.pl_violations", tid, "epochs whose error exceeds its protection level (H or V)", "0",
                    pl["h_error_over_hpl"] + pl["v_error_over_vpl"], "epochs",
                    pl["h_error_over_hpl"] + pl["v_error_over_vpl"] == 0),
        ]
    med = network["arc_time_to_fix_median_s"]
    out.append(_target("network.baseline_fix", "network", "median time for a satellite arc to fix on a baseline",
                       f"<= {TARGET_BASELINE_FIX_S}", med, "s", le(med, TARGET_BASELINE_FIX_S)))
    out.append(_target("network.wrong_fixes", "network", "fixed DD ambiguity-epochs not equal to the truth", "0",
                       network["wrong_fixes"], "ambiguity-epochs", network["wrong_fixes"] == 0))
    rms = interp["dd_iono_error_m"]["rms"]
    out.append(_target("network.interpolation", "network",
                       "interpolated DD ionosphere at the trains and check points, RMS against the truth"
                       + ("" if quiet else " (target for a quiet ionosphere: not applicable)")
                       + ("" if interp["dd_iono_error_m"]["n"] else " (no train or check point: not applicable)"),
                       f"<= {TARGET_INTERP_RMS_M}", rms, "m",
                       le(rms, TARGET_INTERP_RMS_M) if quiet and interp["dd_iono_error_m"]["n"] else None))
    return out


def build(log, alert_limit_m: float = DEFAULT_ALERT_LIMIT_M) -> Report:
    sc = log.scenario
    trains, series = {}, {}
    for tid, tl in log.trains.items():
        trains[tid], series[tid] = train_figures(log, tl, alert_limit_m)
    log.series = series  # for the plots
    baselines = {name: baseline_figures(bl, log.warm_up_s) for name, bl in log.baselines.items()}
    all_ttf = [x for bl in log.baselines.values() for x in bl.time_to_fix.values()]
    network = {"arcs": sum(b["arcs"] for b in baselines.values()),
               "arcs_fixed": sum(b["arcs_fixed"] for b in baselines.values()),
               "arc_time_to_fix_median_s": float(np.median(all_ttf)) if all_ttf else None,
               "checked": sum(b["checked"] for b in baselines.values()),
               "wrong_fixes": sum(b["wrong_fixes"] for b in baselines.values())}
    all_err = [x for v in log.interpolation.values() for x in v]
    floor = [x for v in log.interpolation_floor.values() for x in v]
    interp = {"dd_iono_error_m": M.pct(np.abs(all_err), (50, 95)),
              "dd_iono_error_from_truth_residuals_m": M.pct(np.abs(floor), (50, 95)),
              "points": {p: {"network": M.pct(np.abs(v), (50, 95)),
                             "from_truth_residuals": M.pct(np.abs(log.interpolation_floor[p]), (50, 95))}
                         for p, v in log.interpolation.items()}}
    # pct of absolute values; the RMS of the signed errors is the same number
    quiet = sc.errors.ionosphere.level == "quiet"
    tg = targets(trains, baselines, network, interp, quiet)
    scenario = {"name": sc.name, "seed": sc.seed, "start": sc.start.isoformat(), "duration_s": sc.duration_s,
                "rate_hz": sc.rate_hz, "ionosphere": sc.errors.ionosphere.level,
                "stations": sorted(log.stations), "check_points": sorted(log.check_points),
                "trains": [{"id": x.id, "track": x.track, "start_km": x.start_km, "direction": x.direction,
                            "speed_kmh": x.speed_kmh} for x in sc.trains]}
    simulated = sc.n_epochs * sc.interval_s + log.warm_up_s
    run = {"epochs": log.epochs, "warm_up_s": log.warm_up_s,
           "centre_start_s": -log.warm_up_s if log.warm_up_s else 0.0,  # on the scenario's clock
           "world_epochs": log.world_epochs, "network_epochs": log.network_epochs, "wall_s": log.wall_s,
           "real_time_factor": simulated / log.wall_s if log.wall_s > 0 else None}
    definitions = {"wrong_fix_error_m": M.WRONG_FIX_ERROR_M, "min_rtk_satellites": log.min_rtk_satellites,
                   "no_sky": "epochs where the train receiver tracks no satellite (tunnel, under a bridge); left out "
                             "of fix_rate_after_first_fix, counted in fix_rate_after_first_fix_incl_no_sky",
                   "warm_up": "the reference stations and the centre start run.warm_up_s before the scenario's "
                              "start, the trains' time 0 (they switch on into a network in service); 0: centre and "
                              "trains start together",
                   "baseline_first_fix": "first epoch with half of the baseline's satellites fixed, in seconds since "
                                         "the centre's (cold) start",
                   "ttff": "from the first epoch whose VRS carries min_rtk_satellites to the first fixed epoch",
                   "accuracy": "absolute errors of fixed epochs against the truth antenna position",
                   "protection_level": "K sigma, K two-sided Gaussian quantile of integrity_risk",
                   "alert_limit_m": alert_limit_m}
    return Report(scenario, run, log.latency, definitions, trains, baselines, network, interp, tg)


def write_epochs_csv(log, path: str | Path) -> None:
    """One row per train and epoch: status, errors against the truth, protection levels, track, age."""
    series = getattr(log, "series", None)
    if series is None:
        raise ValueError("build the report first (it computes the per-epoch series)")
    cols = ["train", "t_s", "status", "n_tracked", "base_sats", "vrs_master", "age_s", "east_m", "north_m", "up_m",
            "h_error_m", "v_error_m", "along_m", "cross_m", "hpl_m", "vpl_m", "track", "truth_track",
            "confirmed", "message"]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for tid, tl in log.trains.items():
            s = series[tid]
            for i in range(len(s["t"])):
                def num(x, nd=4):
                    return "" if not np.isfinite(x) else f"{x:.{nd}f}"
                w.writerow([tid, f"{s['t'][i]:.1f}", Status(int(s["status"][i])).name.lower(), tl.n_tracked[i],
                            tl.base_sats[i], tl.vrs_master[i], num(s["age"][i], 2), num(s["enu"][i, 0]), num(s["enu"][i, 1]),
                            num(s["enu"][i, 2]), num(s["h"][i]), num(s["v"][i]), num(s["along"][i]),
                            num(s["cross"][i]), num(s["hpl"][i]), num(s["vpl"][i]), tl.track[i], tl.truth_edge[i] if tl.truth_edge else tl.truth_track,
                            int(tl.confirmed[i]), tl.message[i]])
