"""Train integrity in the full chain: every train's head and rear antenna through the simulated GNSS chain
(`augnet.scenario.runner`, Train.rear_antenna), the onboard `IntegrityMonitor` per epoch, judged against the
truth: a "lost" state on a fault-free run is a false alarm; on a run with a `train_split` the detection time is
the first "lost" epoch minus the split time (requirement: time to alarm 10-30 s, railway.md, GSA 2019).

    res = run(sc, seeds, split=True)        # one split per train and run (time and deceleration per seed)

The truth (the rear's route distance, the fault) is read here only, to judge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from stations.scenario import Fault

# Split campaign: each train's rear separates at a time and decelerates at a rate drawn per seed from these
# (seeded): from coasting on a level line (~0.05 m/s^2, running resistance) to an emergency brake (1 m/s^2).
SPLIT_AT_S = (20.0, 30.0)  # after the first fixes (~12 s), before R3 brakes to its route end (~41 s)
SPLIT_DECEL_M_S2 = (0.05, 0.2, 1.0)
TIME_TO_ALARM_S = 10.0  # the lower (strict) end of the requirement's 10-30 s (railway.md, train integrity)


@dataclass
class TrainIntegrityRun:
    seed: int
    train: str
    epochs: int = 0
    confirmed: int = 0
    unknown: int = 0
    lost: int = 0
    split_at_s: float = math.nan
    split_decel_m_s2: float = math.nan
    lost_at_s: float = math.nan
    # the truth's spacing error when "lost" was declared [m] (head minus rear route distance minus the length)
    gap_at_alarm_m: float = math.nan
    max_error_fault_free_m: float = 0.0  # largest |measured - spacing| while the train was truly complete
    max_ratio_fault_free: float = 0.0  # largest |measured - spacing| / bound while truly complete

    @property
    def false_alarm(self) -> bool:
        return math.isnan(self.split_at_s) and self.lost > 0 or (
            math.isfinite(self.split_at_s) and math.isfinite(self.lost_at_s) and self.lost_at_s < self.split_at_s)

    @property
    def detection_s(self) -> float:
        return self.lost_at_s - self.split_at_s if math.isfinite(self.split_at_s) else math.nan


def split_faults(sc, seed: int, window_s: tuple[float, float] = SPLIT_AT_S,
                 decels_m_s2: tuple[float, ...] = SPLIT_DECEL_M_S2, trains: list[str] | None = None) -> list[Fault]:
    """One split per train with a rear antenna (or per train of `trains`): its time drawn in `window_s`
    (seeded by `seed`), its rear's deceleration taken in turn from `decels_m_s2`."""
    rng = np.random.default_rng([seed, 293])
    out = []
    for i, t in enumerate(sc.trains):
        at = round(float(rng.uniform(*window_s)), 1)  # drawn for every train: the others keep their times
        if t.rear_antenna and (trains is None or t.id in trains):
            out.append(Fault(kind="train_split", train=t.id, at_s=at,
                             rear_decel_m_s2=float(decels_m_s2[(seed + i) % len(decels_m_s2)])))
    return out


def judge(log, seed: int) -> list[TrainIntegrityRun]:
    splits = {f.train: f for f in log.scenario.faults if f.kind == "train_split"}
    out = []
    for tid, tl in log.trains.items():
        if not tl.integrity:
            continue
        r = TrainIntegrityRun(seed, tid)
        f = splits.get(tid)
        if f is not None:
            r.split_at_s, r.split_decel_m_s2 = f.at_s, f.rear_decel_m_s2
        for k, st in enumerate(tl.integrity):
            r.epochs += 1
            setattr(r, st.status, getattr(r, st.status) + 1)
            truth_gap = tl.truth_route_m[k] - tl.truth_rear_route_m[k] - tl.length_m
            if st.status == "lost" and math.isnan(r.lost_at_s):
                r.lost_at_s = st.time_s
                r.gap_at_alarm_m = truth_gap
            complete = abs(truth_gap) < 1e-6
            if complete and math.isfinite(st.error_m):
                r.max_error_fault_free_m = max(r.max_error_fault_free_m, abs(st.error_m))
                r.max_ratio_fault_free = max(r.max_ratio_fault_free, abs(st.error_m) / st.bound_m)
        out.append(r)
    return out


def run(sc, seeds, *, split: bool, warm_up_s: float = 60.0, progress=None, **split_args) -> list[TrainIntegrityRun]:
    """Each seed's full chain once: fault-free (`split` False) or with `split_faults(sc, seed, **split_args)`."""
    from augnet.scenario.runner import simulate

    out: list[TrainIntegrityRun] = []
    for seed in seeds:
        run_sc = sc.model_copy(update={"seed": int(seed),
                                       "faults": split_faults(sc, seed, **split_args) if split else []})
        res = judge(simulate(run_sc, warm_up_s=warm_up_s), seed)
        out.extend(res)
        if progress is not None:
            progress(seed, res)
    return out


def totals(runs: list[TrainIntegrityRun]) -> dict:
    det = np.array([r.detection_s for r in runs if math.isfinite(r.detection_s)])
    splits = [r for r in runs if math.isfinite(r.split_at_s)]
    n = sum(r.epochs for r in runs)
    return {"train_runs": len(runs), "epochs": n, "confirmed": sum(r.confirmed for r in runs),
            "unknown": sum(r.unknown for r in runs), "lost": sum(r.lost for r in runs),
            "confirmed_pct": 100.0 * sum(r.confirmed for r in runs) / max(n, 1),
            "false_alarms": sum(1 for r in runs if r.false_alarm),
            "splits": len(splits), "detected": int(len(det)),
            "missed": sum(1 for r in splits if not math.isfinite(r.lost_at_s)),
            "detection_s": sorted(round(float(x), 1) for x in det),
            "detection_max_s": float(det.max()) if len(det) else math.nan,
            "within_tta": int(np.sum(det <= TIME_TO_ALARM_S)),
            "gap_at_alarm_m": sorted(round(r.gap_at_alarm_m, 2) for r in splits if math.isfinite(r.gap_at_alarm_m)),
            "max_error_fault_free_m": max((r.max_error_fault_free_m for r in runs), default=0.0),
            "max_ratio_fault_free": max((r.max_ratio_fault_free for r in runs), default=0.0)}
