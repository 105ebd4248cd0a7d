"""`augnet scenario campaign`: a matrix of scenarios x seeds with injected faults, one report.

A campaign file (`augnet/scenario/campaigns/<name>.yaml`, or a path) lists cases: a built-in scenario, the
fields replaced in it (`set`: trains, faults, rail, errors merged key by key), and seeds. Each case-seed pair
is one `runner.simulate`; the faults are injected on the simulator's side (stations/scenario.py `Fault`)
and only their times are read back here, to measure what the estimator did about them.

Per method (the four along-track methods of `augnet.onboard.along_track_fusion` and the cross-track position
of the map match), over EVERY epoch of every train of every pair (tunnels included):

- available: a position with its PL under the axis's alert limit (1.7 m, railway.md / Helmet);
- HMI: |error| > PL while available (error against the simulator's truth);
- alarms: the position withdrawn (available -> unavailable) or the fusion's lockout;
- per injected fault and affected train, the outcome over the fault's watch window [at_s, end + watch]:
  `alarm` (raised before any HMI; time to alarm = alarm epoch - fault start, simulated time, at the train,
  and + `LatencyModel.train_to_rbc` at the RBC), `missed` (HMI before any alarm), `protected` (available,
  never misleading: no alarm was needed) or `unavailable` (not in use during the window).

The truth is read only in `_pair_series` (errors) and `resolve_auto_satellites` (choosing the satellite a
fault hits, the campaign designer's side); the estimator never sees either.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field

from augnet.gnss.ephemeris import transit
from augnet.gnss.geometry import ecef_to_geodetic, enu_rotation
from augnet.onboard.along_track_fusion import ALONG_TRACK_ALERT_LIMIT_M, METHODS
from augnet.onboard.integrity_allocation import CROSS_TRACK_ALERT_LIMIT_M
from augnet.scenario import metrics as M
from augnet.scenario.latency import LatencyModel
from rssp1.config import LinkTiming
from stations.scenario import Scenario, ScenarioError, load_scenario, parse_scenario

CROSS_TRACK = "cross_track"  # the map match's cross-track position, judged beside the along-track methods
FUSED_METHODS = ("median", "weighted_median", "residual_weighted_median")
# After a fault ends (or, for a step, after it happens) its effects linger: the VRS catches up, the filter
# re-converges, a slid odometer's window is rebuilt. Watch this long for the alarm or the HMI it causes.
FAULT_WATCH_S = 30.0
# Fault classes (`fault_class`): a fault in the train's own signal or odometer is an along-track fault, under
# the Helmet odometry-correction TTA < 1 s (railway.md); station faults (outage, wrong coordinates, a burst at
# a station's antenna) reach the train as a wrong or missing VRS and are reported as their own class.
# Must-show figures (issue 15): weighted-median availability over every epoch, TTA at the train and the RBC.
TARGET_AVAILABILITY = 0.998
TARGET_TTA_TRAIN_S = 1.0
TARGET_TTA_RBC_S = 2.0
RSSP1_CYCLE_S = LinkTiming().cycle_s  # the train's and the RBC's RSSP-I main cycle (rssp1.config default)
AUTO_SATELLITE = "auto"
CAMPAIGN_JSON = "campaign.json"
CAMPAIGN_MD = "campaign.md"
STANFORD_PNG = "stanford_{method}.png"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class CampaignCase(_Strict):
    id: str = Field(pattern=r"^[A-Za-z0-9_\-]{1,60}$")
    scenario: str  # built-in scenario name or YAML path
    seeds: list[int] = Field(min_length=1)
    duration_s: float | None = Field(default=None, gt=0.0)
    set: dict = Field(default_factory=dict)  # top-level scenario fields (dicts merged key by key)


class Campaign(_Strict):
    name: str
    description: str = ""
    warm_up_s: float = Field(default=60.0, ge=0.0)
    duration_s: float = Field(default=150.0, gt=0.0)
    cases: list[CampaignCase] = Field(min_length=1)


@dataclass
class Pair:
    case: str
    seed: int
    scenario: Scenario

    @property
    def id(self) -> str:
        return f"{self.case}/s{self.seed}"


def load_campaign(name_or_path: str | Path) -> Campaign:
    """A built-in campaign by name (`issue15`) or a campaign YAML file (ScenarioError naming the problem)."""
    path = Path(name_or_path)
    if path.is_file():
        text = path.read_text()
    else:
        res = resources.files("augnet.scenario.campaigns").joinpath(f"{name_or_path}.yaml")
        if not res.is_file():
            raise ScenarioError(f"campaign {name_or_path}: no such file, and not a built-in campaign")
        text = res.read_text()
    try:
        return Campaign.model_validate(yaml.safe_load(text))
    except Exception as exc:  # YAML or schema: one error type for the CLI
        raise ScenarioError(f"campaign {name_or_path}: {exc}") from None


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def expand(campaign: Campaign) -> list[Pair]:
    """Every case x seed as a validated scenario (auto satellites resolved)."""
    pairs = []
    for case in campaign.cases:
        base = load_scenario(case.scenario).model_dump(mode="json")
        for seed in case.seeds:
            d = _merge(base, copy.deepcopy(case.set))
            d.update(name=f"{case.id}-s{seed}", seed=seed, duration_s=case.duration_s or campaign.duration_s)
            auto = [i for i, f in enumerate(d.get("faults", [])) if f.get("satellite") == AUTO_SATELLITE]
            faults = d.get("faults", [])
            provisional = parse_scenario({**d, "faults": [f for i, f in enumerate(faults) if i not in auto]},
                                         f"campaign case {case.id}")
            for i, sat in zip(auto, resolve_auto_satellites(provisional, [faults[i] for i in auto])):
                faults[i] = {**faults[i], "satellite": sat}
            pairs.append(Pair(case.id, seed, parse_scenario(d, f"campaign case {case.id} seed {seed}")))
    return pairs


def resolve_auto_satellites(sc: Scenario, faults: list[dict]) -> list[str]:
    """For each fault naming `satellite: auto`: the satellite highest above its receiver (a multipath burst's
    `receiver`, else the first train) at the fault's start, from the world's truth (the designer's choice)."""
    if not faults:
        return []
    from stations.world import World

    world = World(sc)
    out = []
    for f in faults:
        rid = f.get("receiver") or sc.trains[0].id
        rx = world.receivers[world.receiver_ids.index(rid)]
        e = min(int(round(float(f["at_s"]) * sc.rate_hz)), world.n_epochs - 1)
        t = float(world.t_tags[e])
        tr = transit(world.nav, world.sats, rx.ecef[e], t)
        llh = ecef_to_geodetic(rx.ecef[e])
        up = enu_rotation(llh[0], llh[1])[2]
        el = np.where(tr.valid, np.nan_to_num(tr.line_of_sight @ up, nan=-1.0), -1.0)  # sin(elevation)
        out.append(world.sats[int(np.nanargmax(el))])
    return out


# --- evaluation (pure: arrays in, figures out) ----------------------------------------------------------

def withdrawals(available: np.ndarray) -> np.ndarray:
    """Epochs at which a position available at the previous epoch is not (the alarm of a withdrawal)."""
    a = np.asarray(available, bool)
    return np.concatenate([[False], a[:-1] & ~a[1:]])


def method_figures(err: np.ndarray, pl: np.ndarray, available: np.ndarray, alarm: np.ndarray,
                   alert_limit_m: float = ALONG_TRACK_ALERT_LIMIT_M) -> dict:
    """Availability over every epoch, HMI (error > PL while available: the issue's definition), of those the
    ones beyond the alert limit too (the Stanford plot's HMI region), alarms, error and PL percentiles."""
    n = len(err)
    hmi = available & (err > pl)
    return {"epochs": int(n), "available": int(available.sum()),
            "availability": float(available.mean()) if n else None,
            "hmi": int(hmi.sum()), "hmi_beyond_alert_limit": int((hmi & (err > alert_limit_m)).sum()),
            "alarms": int(np.asarray(alarm, bool).sum()),
            "error_available_m": M.pct(err[available], (50, 95, 99)),
            "pl_available_m": M.pct(pl[available], (50, 95))}


def fault_outcome(t: np.ndarray, err: np.ndarray, pl: np.ndarray, available: np.ndarray, alarm: np.ndarray,
                  at_s: float, end_s: float) -> dict:
    """What one method did about one fault over [at_s, end_s] (module docstring): outcome, TTA at the train."""
    w = (t >= at_s - 1e-9) & (t <= end_s + 1e-9)
    idx = np.flatnonzero(w)
    hmi = available & (err > pl)
    first_hmi = next((int(i) for i in idx if hmi[i]), None)
    first_alarm = next((int(i) for i in idx if alarm[i]), None)
    out = {"hmi_epochs": int(hmi[idx].sum()), "tta_train_s": None}
    if not available[idx].any():
        out.update(outcome="unavailable")  # not in use: nothing to warn about (a lockout then is no alarm)
    elif first_alarm is not None and (first_hmi is None or first_alarm <= first_hmi):
        out.update(outcome="alarm", tta_train_s=float(t[first_alarm] - at_s))
    elif first_hmi is not None:
        out.update(outcome="missed")
    else:
        out.update(outcome="protected")
    return out


def fault_window(f, sc: Scenario) -> tuple[float, float]:
    """[start, end] of a fault's watch window, seconds since the trains' time 0."""
    if f.kind == "station_coordinates":
        return 0.0, sc.duration_s  # published wrong for the whole run
    end = f.until_s if f.until_s is not None else (sc.duration_s if f.kind == "station_outage" else f.at_s)
    return f.at_s, min(end + FAULT_WATCH_S, sc.duration_s)


def fault_class(f, sc: Scenario) -> str:
    """'along' (the train's signal or odometer: the 1 s target) or 'station' (reaches it through the VRS)."""
    at_station = f.kind in ("station_outage", "station_coordinates") or (
        f.kind == "multipath_burst" and f.receiver not in {t.id for t in sc.trains})
    return "station" if at_station else "along"


def affected_trains(f, sc: Scenario) -> list[str]:
    if f.train is not None:
        return [f.train]
    if f.receiver is not None and f.receiver in {t.id for t in sc.trains}:
        return [f.receiver]
    return [t.id for t in sc.trains]  # satellite and station faults reach every train


# --- one pair ---------------------------------------------------------------------------------------------

@dataclass
class PairResult:
    pair: str
    case: str
    seed: int
    scenario: str
    line: str
    figures: dict  # train -> method -> method_figures
    faults: list[dict]  # one per (fault, train): kind, times, per method outcome
    series: dict = field(default_factory=dict)  # method -> train -> {"h": |error|, "hpl": PL} (plots)
    wall_s: float = 0.0


def _pair_series(log, rep) -> dict:
    """train -> method -> (t, |error|, PL, available, alarm) over every epoch; errors against the truth."""
    out = {}
    for tid, tl in log.trains.items():
        t = np.array(tl.t_s, float)
        truth_m = np.array(tl.truth_km, float) * 1000.0
        per = {}
        for m in METHODS:
            fused = tl.fused[m]
            x = np.array([f.position_m for f in fused], float)
            pl = np.array([f.pl_m for f in fused], float)
            per[m] = (t, np.abs(x - truth_m), pl, np.array([f.available for f in fused], bool),
                      np.array([f.alarm for f in fused], bool))
        cross = np.abs(np.asarray(log.series[tid]["cross"], float))
        cpl = np.array(tl.cross_pl_m, float)
        avail = np.isfinite(cross) & np.isfinite(cpl) & (cpl < CROSS_TRACK_ALERT_LIMIT_M)
        per[CROSS_TRACK] = (t, cross, cpl, avail, withdrawals(avail))
        out[tid] = per
    return out


def run_pair(pair: Pair, warm_up_s: float, fusion: dict | None = None) -> PairResult:
    """Simulate one pair and measure it (`fusion`: FusionSettings overrides, e.g. detection disabled)."""
    import time as wallclock

    from augnet.scenario import report as R
    from augnet.scenario.runner import simulate

    start = wallclock.perf_counter()
    log = simulate(pair.scenario, warm_up_s=warm_up_s, fusion=fusion)
    rep = R.build(log)
    series = _pair_series(log, rep)
    sc = pair.scenario
    latency = LatencyModel(sc.seed)
    figures = {}
    for tid, per in series.items():
        # start-up: the epochs before the train's first GNSS + RAIM position (switch-on, first fix)
        first = np.flatnonzero(per["gnss_raim"][3])
        s0 = int(first[0]) if first.size else len(per["gnss_raim"][0])
        figures[tid] = {}
        for m, x in per.items():
            f = method_figures(*x[1:], CROSS_TRACK_ALERT_LIMIT_M if m == CROSS_TRACK else ALONG_TRACK_ALERT_LIMIT_M)
            run = method_figures(*(a[s0:] for a in x[1:]))
            f["after_start_up"] = {"from_s": float(x[0][s0]) if s0 < len(x[0]) else None, "epochs": run["epochs"],
                                   "available": run["available"], "availability": run["availability"]}
            figures[tid][m] = f
    faults = []
    for f in sc.faults:
        a, b = fault_window(f, sc)
        for tid in affected_trains(f, sc):
            per = series[tid]
            if f.kind == "station_coordinates":
                # present from the first epoch: no onset to alarm on (an alarm then answers another cause), so
                # only its HMI count; outcome missed / protected / unavailable
                per = {m: (x[0], x[1], x[2], x[3], np.zeros_like(x[4])) for m, x in per.items()}
            outcomes = {m: fault_outcome(*per[m], a, b) for m in per}
            for o in outcomes.values():
                o["tta_rbc_s"] = (o["tta_train_s"] + float(latency.train_to_rbc(1, RSSP1_CYCLE_S)[0])
                                  if o["tta_train_s"] is not None else None)
            faults.append({"kind": f.kind, "class": fault_class(f, sc), "train": tid, "at_s": f.at_s, "until_s": f.until_s,
                           "watch_end_s": b, "detail": _fault_detail(f), "methods": outcomes})
    plot = {m: {tid: {"h": series[tid][m][1], "hpl": series[tid][m][2]} for tid in series}
            for m in (*METHODS, CROSS_TRACK)}
    return PairResult(pair.id, pair.case, pair.seed, sc.name, sc.line.id if sc.line else "", figures, faults, plot,
                      wallclock.perf_counter() - start)


def _fault_detail(f) -> dict:
    keys = {"satellite_clock_step": ("satellite", "step_ns"), "satellite_clock_ramp": ("satellite", "ramp_ns_per_s"),
            "multipath_burst": ("receiver", "satellite", "code_m", "phase_m"), "station_outage": ("station",),
            "station_coordinates": ("station", "offset_enu_m"), "odometer_slide": ("train", "slide_fraction"),
            "odometer_slip": ("train", "slip_fraction")}[f.kind]
    return {k: getattr(f, k) for k in keys}


# --- the campaign -----------------------------------------------------------------------------------------

def summarise(results: list[PairResult]) -> dict:
    """Per method over every pair and train: figures, fault outcomes, TTA distributions; the must-show checks."""
    methods = (*METHODS, CROSS_TRACK)
    per = {}
    for m in methods:
        figs = [r.figures[tid][m] for r in results for tid in r.figures]
        n = sum(f["epochs"] for f in figs)
        av = sum(f["available"] for f in figs)
        outcomes = [fl["methods"][m] | {"kind": fl["kind"], "class": fl["class"]} for r in results for fl in r.faults]
        start = [f["after_start_up"] for r in results for tid in r.figures for f in [r.figures[tid][m]]]
        n_run = sum(x["epochs"] for x in start)
        av_run = sum(x["available"] for x in start)
        tta_t = [o["tta_train_s"] for o in outcomes if o["tta_train_s"] is not None]
        tta_r = [o["tta_rbc_s"] for o in outcomes if o["tta_rbc_s"] is not None]
        counts = {k: sum(o["outcome"] == k for o in outcomes) for k in ("alarm", "missed", "protected", "unavailable")}
        tta_along = [o["tta_train_s"] for o in outcomes if o["tta_train_s"] is not None and o["class"] == "along"]
        rbc_along = [o["tta_rbc_s"] for o in outcomes if o["tta_rbc_s"] is not None and o["class"] == "along"]
        per[m] = {"epochs": n, "available": av, "availability": av / n if n else None,
                  "after_start_up": {"epochs": n_run, "available": av_run,
                                     "availability": av_run / n_run if n_run else None},
                  "tta_train_along_s": M.pct(tta_along, (50, 95)), "tta_rbc_along_s": M.pct(rbc_along, (50, 95)),
                  "hmi": sum(f["hmi"] for f in figs),
                  "hmi_beyond_alert_limit": sum(f.get("hmi_beyond_alert_limit", 0) for f in figs),
                  "alarms": sum(f["alarms"] for f in figs),
                  "fault_outcomes": counts,
                  "tta_train_s": M.pct(tta_t, (50, 95)) | {"values": sorted(tta_t)},
                  "tta_rbc_s": M.pct(tta_r, (50, 95)) | {"values": sorted(round(x, 3) for x in tta_r)},
                  "by_fault_kind": _by_kind(outcomes)}
    along = [fl["methods"]["weighted_median"] for r in results for fl in r.faults if fl["class"] == "along"]
    alarmed = [o for o in along if o["outcome"] == "alarm"]
    wm = per["weighted_median"]
    checks = [
        _check("hmi_fused_along", "fused along-track HMI (median, weighted, residual-weighted)", "0",
               sum(per[m]["hmi"] for m in FUSED_METHODS), lambda v: v == 0),
        _check("hmi_cross", "cross-track HMI", "0", per[CROSS_TRACK]["hmi"], lambda v: v == 0),
        _check("availability_wm", "weighted-median availability, every epoch (tunnels included)",
               f">= {TARGET_AVAILABILITY:.1%}", wm["availability"], lambda v: v is not None and v >= TARGET_AVAILABILITY),
        _check("availability_wm_running", "weighted-median availability after each train's start-up (its first "
               "GNSS + RAIM position; tunnels included)", f">= {TARGET_AVAILABILITY:.1%}",
               wm["after_start_up"]["availability"], lambda v: v is not None and v >= TARGET_AVAILABILITY),
        _check("missed_along_faults_wm", "along-track faults with HMI before an alarm (weighted median)", "0",
               sum(o["outcome"] == "missed" for o in along), lambda v: v == 0),
        _check("tta_train_max_s", "TTA at the train, along-track faults alarmed (weighted median), max",
               f"<= {TARGET_TTA_TRAIN_S:g} s", max((o["tta_train_s"] for o in alarmed), default=None),
               lambda v: v is not None and v <= TARGET_TTA_TRAIN_S),
        _check("tta_rbc_max_s", "TTA at the RBC, along-track faults alarmed (weighted median), max",
               f"<= {TARGET_TTA_RBC_S:g} s", max((o["tta_rbc_s"] for o in alarmed), default=None),
               lambda v: v is not None and v <= TARGET_TTA_RBC_S),
    ]
    kinds = sorted({fl["kind"] for r in results for fl in r.faults})
    lines = sorted({r.line for r in results})
    return {"methods": per, "checks": checks, "fault_kinds": kinds, "lines": lines, "pairs": len(results)}


def _by_kind(outcomes: list[dict]) -> dict:
    out = {}
    for o in outcomes:
        k = out.setdefault(o["kind"], {"n": 0, "alarm": 0, "missed": 0, "protected": 0, "unavailable": 0,
                                       "tta_train_s": []})
        k["n"] += 1
        k[o["outcome"]] += 1
        if o["tta_train_s"] is not None:
            k["tta_train_s"].append(o["tta_train_s"])
    return out


def _check(cid, what, target, measured, ok) -> dict:
    return {"id": cid, "what": what, "target": target, "measured": measured, "pass": bool(ok(measured))}


def run_campaign(campaign: str | Path | Campaign, out_dir: str | Path, *, plots: bool = True,
                 fusion: dict | None = None, on_pair: Callable[[PairResult], None] | None = None) -> dict:
    """Every pair of the campaign; writes campaign.json, campaign.md and the Stanford plots; returns the JSON."""
    cp = campaign if isinstance(campaign, Campaign) else load_campaign(campaign)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = []
    for pair in expand(cp):
        res = run_pair(pair, cp.warm_up_s, fusion)
        results.append(res)
        if on_pair is not None:
            on_pair(res)
    summary = summarise(results)
    files = [CAMPAIGN_JSON, CAMPAIGN_MD]
    if plots:
        from augnet.scenario import plots as P

        for m in (*METHODS, CROSS_TRACK):
            name = STANFORD_PNG.format(method=m)
            al = CROSS_TRACK_ALERT_LIMIT_M if m == CROSS_TRACK else ALONG_TRACK_ALERT_LIMIT_M
            series = {f"{r.pair}/{tid}": s for r in results for tid, s in r.series[m].items()}
            counts = P.stanford(series, out / name, al, f"campaign {cp.name}: {m}",
                                quantity="cross-track" if m == CROSS_TRACK else "along-track")
            summary["methods"][m]["stanford"] = counts
            files.append(name)
    doc = {"campaign": cp.model_dump(), "definitions": {
        "available": "a position with its PL under the axis's alert limit, counted over every epoch",
        "hmi": "|error| > PL while available (error against the simulator's truth)",
        "alarm": "the position withdrawn (available -> unavailable) or the fusion's lockout",
        "tta": "alarm epoch minus the fault's start, simulated time (1 s epochs); RBC: + RSSP-I cycle waits and "
               "the cellular one-way delay (LatencyModel.train_to_rbc)",
        "alert_limit_m": {"along": ALONG_TRACK_ALERT_LIMIT_M, "cross": CROSS_TRACK_ALERT_LIMIT_M},
        "fault_watch_s": FAULT_WATCH_S, "rssp1_cycle_s": RSSP1_CYCLE_S, "fusion_overrides": fusion or {}},
        "summary": summary,
        "pairs": [{"pair": r.pair, "case": r.case, "seed": r.seed, "scenario": r.scenario, "line": r.line,
                   "wall_s": r.wall_s, "figures": r.figures, "faults": r.faults} for r in results],
        "files": files}
    doc = _clean(doc)
    (out / CAMPAIGN_JSON).write_text(json.dumps(doc, indent=1))
    (out / CAMPAIGN_MD).write_text(markdown(doc))
    return doc


def _clean(x):
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not math.isfinite(float(x)) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _f(v, pct=False) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "pass" if v else "FAIL"
    if isinstance(v, float):
        return f"{v:.3%}" if pct else f"{v:.3g}"
    return str(v)


def markdown(doc: dict) -> str:
    s = doc["summary"]
    cp = doc["campaign"]
    lines = [f"# Campaign {cp['name']}", "", cp["description"] or "(no description)", "",
             f"{s['pairs']} scenario-seed pairs on lines {', '.join(s['lines'])}; fault kinds: "
             f"{', '.join(s['fault_kinds'])}. Warm-up {cp['warm_up_s']:g} s.", "", "## Must show", "",
             "| check | target | measured | result |", "| --- | --- | --- | --- |"]
    for c in s["checks"]:
        pct = c["id"].startswith("availability")
        lines.append(f"| {c['what']} | {c['target']} | {_f(c['measured'], pct)} | {_f(c['pass'])} |")
    lines += ["", "## Methods side by side (every epoch, tunnels included)", "",
              "| method | epochs | available | availability | after start-up | HMI (err > PL) | of those > AL | alarms | "
              "faults alarm/missed/protected/unavailable | TTA train p50/max s (along-track faults) | "
              "TTA RBC p50/max s (along) | TTA train max s (all) | Stanford plot |", "| --- " * 13 + "|"]
    for m, f in s["methods"].items():
        fo = f["fault_outcomes"]
        tt, tr = f["tta_train_along_s"], f["tta_rbc_along_s"]
        plot = STANFORD_PNG.format(method=m) if STANFORD_PNG.format(method=m) in doc["files"] else "-"
        lines.append(f"| {m} | {f['epochs']} | {f['available']} | {_f(f['availability'], True)} | "
                     f"{_f(f['after_start_up']['availability'], True)} | {f['hmi']} | {f['hmi_beyond_alert_limit']} | "
                     f"{f['alarms']} | {fo['alarm']}/{fo['missed']}/{fo['protected']}/{fo['unavailable']} | "
                     f"{_f(tt['p50'])}/{_f(tt['max'])} | {_f(tr['p50'])}/{_f(tr['max'])} | "
                     f"{_f(f['tta_train_s']['max'])} | {plot} |")
    lines += ["", "## Faults (weighted median / cross-track)", "",
              "| pair | fault | class | train | from-to s | WM outcome | WM TTA train / RBC s | cross outcome |",
              "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p in doc["pairs"]:
        for fl in p["faults"]:
            wm, cr = fl["methods"]["weighted_median"], fl["methods"][CROSS_TRACK]
            det = ", ".join(f"{k}={v}" for k, v in fl["detail"].items() if v is not None)
            lines.append(f"| {p['pair']} | {fl['kind']} ({det}) | {fl['class']} | {fl['train']} | {fl['at_s']:g}-{_f(fl['until_s'])} | "
                         f"{wm['outcome']} | {_f(wm['tta_train_s'])} / {_f(wm['tta_rbc_s'])} | {cr['outcome']} |")
    lines += ["", "## Pairs", "", "| pair | line | train | " + " | ".join(f"{m} avail / HMI" for m in (*METHODS, CROSS_TRACK))
              + " |", "| --- " * (3 + len(METHODS) + 1) + "|"]
    for p in doc["pairs"]:
        for tid, per in p["figures"].items():
            cells = " | ".join(f"{v['available']}/{v['epochs']} / {v['hmi']}" for v in per.values())
            lines.append(f"| {p['pair']} | {p['line']} | {tid} | {cells} |")
    lines += ["", "Definitions: " + "; ".join(f"{k}: {v}" for k, v in doc["definitions"].items()
                                               if isinstance(v, str)), ""]
    return "\n".join(lines)
