"""The simulator's presets beside the real network: record each preset briefly, measure it with the same code as
the real RINEX (`stations.observation_statistics`), and say on which statistic a preset is milder than real.

`augnet sim calibrate --real DIR` prints the tables of docs/simulator-calibration.md.
"""

from __future__ import annotations

import csv
import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.rinex.nav import read_nav
from stations import observation_statistics as ostat
from stations.record import record
from stations.scenario import load_scenario

# catnet-2010-077 (../shared/data/rinex): three Trimble NetRS at 30 s a day, two Septentrio PolaRx2 at 1 Hz an hour.
REAL_STATIONS = ("CREU", "EBRE", "GARR", "UPC1", "UPC2")
REAL_NETWORK = ("CREU", "EBRE", "GARR")  # the 30 s reference stations the per-station comparison takes
REAL_PAIRS = (("GARR", "EBRE"), ("GARR", "CREU"), ("CREU", "EBRE"), ("GARR", "UPC1"), ("UPC1", "UPC2"))
REAL_NAV = "brdc0770.10n.gz"
RATE_30S_HZ = 1.0 / 30.0
DAY_S = 86400.0
HOUR_S = 3600.0


@dataclass(frozen=True)
class PresetRun:
    label: str
    scenario: str
    level: str | None  # ionosphere level instead of the scenario's
    stations: tuple[str, ...]
    pairs: tuple[tuple[str, str], ...]


PRESET_RUNS = (
    PresetRun("baseline-10km", "baseline-10km", None, ("A", "B"), (("A", "B"),)),
    PresetRun("demo", "demo", None, ("STA1", "STA2", "STA3", "OFF1"), (("STA1", "STA2"), ("STA2", "STA3"))),
    PresetRun("network-70km quiet", "network-70km", "quiet", ("NORTH", "SOUTH", "check1"),
              (("NORTH", "SOUTH"), ("NORTH", "check1"))),
    PresetRun("network-70km moderate", "network-70km", "moderate", ("NORTH", "SOUTH", "check1"),
              (("NORTH", "SOUTH"), ("NORTH", "check1"))),
    PresetRun("iono-storm", "iono-storm", None, ("ST1", "ST2", "check1"), (("ST1", "ST2"), ("ST1", "check1"))),
    PresetRun("catnet-like", "catnet-like", None, ("CREU", "EBRE", "GARR", "UPC1"),
              (("GARR", "EBRE"), ("GARR", "CREU"), ("CREU", "EBRE"), ("GARR", "UPC1"))),
)


# The presets that ship as the product's scenarios (catnet-like is the calibration's own): each must be at least as
# harsh as the real network on every statistic (decision 0272).
SHIPPED_PRESETS = ("baseline-10km", "demo", "iono-storm", "network-70km")


def shipped_runs() -> list[PresetRun]:
    """The calibration runs of the shipped presets, each at its own ionosphere level."""
    return [r for r in PRESET_RUNS if r.scenario in SHIPPED_PRESETS and r.level in (None, _own_level(r.scenario))]


def _own_level(scenario: str) -> str:
    return load_scenario(scenario).errors.ionosphere.level


def record_run(run: PresetRun, rate_hz: float, duration_s: float, out_dir: Path) -> Path:
    """Record the preset's stations (all of them: the region and so the ionosphere field stay the preset's; no
    trains) at `rate_hz` for `duration_s`, without RTCM."""
    sc = load_scenario(run.scenario)
    update = dict(duration_s=duration_s, rate_hz=rate_hz, trains=[])
    if run.level is not None:
        iono = sc.errors.ionosphere.model_copy(update={"level": run.level})
        update["errors"] = sc.errors.model_copy(update={"ionosphere": iono})
    record(sc.model_copy(update=update), out_dir, rtcm=False)
    return Path(out_dir)


def load_nav(path) -> NavigationData:
    return NavigationData(read_nav(path).ephemerides)


def measure(series: dict[str, ostat.StationSeries], pairs) -> tuple[dict, dict]:
    """Per-station and per-pair statistics of loaded series (slips detected once per series)."""
    slips = {n: ostat.detect_slips(s) for n, s in series.items()}
    st = {n: ostat.station_statistics(s, slips[n]) for n, s in series.items()}
    pr = {(a, b): ostat.pair_statistics(series[a], series[b], slips[a], slips[b]) for a, b in pairs}
    return st, pr


def measure_recording(folder: Path, stations, pairs, interval_s: float | None = None):
    nav = load_nav(Path(folder) / "nav.rnx")
    series = {n: ostat.load_station(Path(folder) / f"{n}.obs", nav, n) for n in stations}
    if interval_s:
        series = {n: s.decimated(interval_s) for n, s in series.items()}
    return measure(series, pairs)


def measure_real(data_dir: Path):
    """catnet-2010-077 at the files' own rates (the 1 Hz pair UPC1-UPC2 at 1 Hz, GARR-UPC1 at 30 s)."""
    data_dir = Path(data_dir)
    nav = load_nav(data_dir / REAL_NAV)
    series = {n: ostat.load_station(data_dir / f"{n}0770.10o.gz", nav, n) for n in REAL_STATIONS}
    return measure(series, REAL_PAIRS)


def truth_dd_iono_mm(folder: Path, a: str, b: str) -> float:
    """RMS of the true DD L1 ionosphere of a recorded pair (atmosphere.csv), the same satellites and reference
    rule as `pair_statistics` (reference the highest at `a`, the others above DD_MIN_ELEVATION_DEG): what the
    levelled measurement tries to reach."""
    rows: dict[tuple[float, str], dict[str, tuple[float, float]]] = {}
    with open(Path(folder) / "atmosphere.csv") as f:
        for r in csv.DictReader(f):
            if r["receiver"] in (a, b) and r["sat"].startswith("G"):
                rows.setdefault((float(r["gpst_s"]), r["sat"]), {})[r["receiver"]] = (
                    float(r["iono_l1_m"]), float(r["elevation_deg"]))
    by_t: dict[float, list[tuple[str, float, float]]] = {}
    for (t, sat), d in rows.items():
        if a in d and b in d:
            by_t.setdefault(t, []).append((sat, d[a][0] - d[b][0], d[a][1]))
    vals = []
    for t, sats in by_t.items():
        if len(sats) < 2:
            continue
        ref = max(sats, key=lambda x: x[2])
        vals += [sd - ref[1] for s, sd, el in sats if s != ref[0] and el >= ostat.DD_MIN_ELEVATION_DEG]
    return float(np.sqrt(np.mean(np.square(vals)))) * 1e3 if vals else math.nan


# -- harshness ----------------------------------------------------------------------------------------------

@dataclass
class Comparison:
    statistic: str
    preset: float
    real: float

    @property
    def milder(self) -> bool:
        return bool(np.isfinite(self.preset) and np.isfinite(self.real) and self.preset < self.real)


def _max(values):
    v = [x for x in values if x is not None and np.isfinite(x)]
    return max(v) if v else math.nan


def compare_stations(sim: dict, real: dict) -> list[Comparison]:
    """Per statistic: the preset's mildest station against the real network's harshest 30 s station."""
    out = []
    bins = [ostat.bin_label(lo, hi) for lo, hi in ostat.ELEVATION_BINS_DEG]
    real_net = [real[n] for n in REAL_NETWORK if n in real]
    sims = list(sim.values())
    for key, name in (("mp1_m", "MP1 m"), ("mp2_m", "MP2 m"), ("gf_d2_mm", "GF phase d2 mm")):
        for b in bins:
            out.append(Comparison(f"{name} {b} deg", min(getattr(s, key)[b] for s in sims),
                                  _max(getattr(r, key)[b] for r in real_net)))
    out.append(Comparison("unflagged slips /sat-h", min(s.unflagged_per_sat_h for s in sims),
                          _max(r.unflagged_per_sat_h for r in real_net)))
    out.append(Comparison("phase resets /sat-h", min(s.extra["resets_per_sat_h"] for s in sims),
                          _max(r.extra["resets_per_sat_h"] for r in real_net)))
    out.append(Comparison("gaps /sat-h", min(s.gaps_per_sat_h for s in sims), _max(r.gaps_per_sat_h for r in real_net)))
    return out


def compare_pairs(sim: dict, real: dict) -> list[Comparison]:
    """The DD ionosphere's change per km of baseline: the preset's mildest pair against the real network's harshest
    long pair (the three 130-290 km baselines; GARR-UPC1 has an hour only)."""
    long_real = [real[p] for p in REAL_PAIRS[:3] if p in real]
    sims = [p for p in sim.values() if p.baseline_km >= ostat.PER_KM_MIN_KM]
    out = []
    for lag, name in ((30.0, "DD iono 30 s change mm"), (300.0, "DD iono 5 min change mm/km")):
        f = (lambda p: p.dd_change_rms_mm[lag]) if lag == 30.0 else (lambda p: p.per_km(p.dd_change_rms_mm[lag]))
        out.append(Comparison(name, min(f(p) for p in sims), _max(f(p) for p in long_real)))
    # the level, levelling error taken out: the real one is below what code levelling resolves (0 on each pair)
    out.append(Comparison("DD iono level mm/km (floor out)", min(p.per_km(p.dd_level_mm) for p in sims),
                          _max(p.per_km(p.dd_level_mm) for p in long_real)))
    return out


def comparison_table(rows: list[tuple[str, list[Comparison]]]) -> str:
    stats = [c.statistic for c in rows[0][1]]
    head = ["statistic", "real (harshest)"] + [label for label, _ in rows]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i, s in enumerate(stats):
        real = rows[0][1][i].real
        cells = [s, ostat._f(real, "{:.3g}")]
        for _, comps in rows:
            c = comps[i]
            cells.append(ostat._f(c.preset, "{:.3g}") + (" **milder**" if c.milder else ""))
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def calibration_report(real_dir: Path, work_dir: Path, runs=PRESET_RUNS, day_s: float = DAY_S,
                       hour_s: float = HOUR_S, log=print) -> str:
    """Every table of docs/simulator-calibration.md: real catnet, each preset at 30 s for a day and at 1 Hz for
    an hour, and the harshness comparison."""
    work_dir = Path(work_dir)
    real_st, real_pr = measure_real(real_dir)
    st_rows = [("real catnet", real_st[n]) for n in REAL_STATIONS]
    pr_rows = [("real catnet", real_pr[p]) for p in REAL_PAIRS]
    comps = []
    truth_lines = []
    for run in runs:
        slug = run.label.replace(" ", "-")
        log(f"recording {run.label}")
        d30 = record_run(run, RATE_30S_HZ, day_s, work_dir / f"{slug}-30s")
        st, pr = measure_recording(d30, run.stations, run.pairs)
        st_rows += [(f"{run.label} 30 s", s) for s in st.values()]
        pr_rows += [(f"{run.label} 30 s", p) for p in pr.values()]
        comps.append((run.label, compare_stations(st, real_st) + compare_pairs(pr, real_pr)))
        for (a, b), p in pr.items():
            truth = truth_dd_iono_mm(d30, a, b)
            truth_lines.append(f"| {run.label} | {a}-{b} | {p.baseline_km:.1f} | {p.per_km(truth):.3f} | "
                               f"{p.per_km(p.dd_level_rms_mm):.3f} | {p.per_km(p.dd_level_mm):.3f} |")
        d1 = record_run(run, 1.0, hour_s, work_dir / f"{slug}-1hz")
        st1, pr1 = measure_recording(d1, run.stations, run.pairs)
        st_rows += [(f"{run.label} 1 Hz", s) for s in st1.values()]
        pr_rows += [(f"{run.label} 1 Hz", p) for p in pr1.values()]
    truth_head = ("| preset | pair | km | true DD iono RMS mm/km | measured raw | measured, floor out |\n"
                  "|---|---|---|---|---|---|")
    return "\n\n".join([
        "### Per station\n\n" + ostat.station_table(st_rows),
        "### Per pair\n\n" + ostat.pair_table(pr_rows),
        "### Preset against the real network (30 s)\n\n" + comparison_table(comps),
        "### The DD level estimator against the simulator's truth (30 s, a day)\n\n" + truth_head + "\n"
        + "\n".join(truth_lines),
    ])


def all_pairs(names):
    return list(itertools.combinations(names, 2))
