"""Read a `sim record` folder back: truth per receiver and atmosphere truth per receiver/satellite.

For the estimate-minus-truth side of every test and report (the centre, the onboard core); the
estimators themselves never read these files.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class ReceiverTruth:
    receiver: str
    kind: str  # "station" or "train"
    t_gpst: np.ndarray  # (E,) epoch tags, GPST seconds
    ecef_m: np.ndarray  # (E, 3) antenna
    clock_s: np.ndarray  # (E,) receiver clock offset
    track: np.ndarray  # (E,) track id ("" for stations)
    km: np.ndarray  # (E,) chainage, NaN for stations
    speed_m_s: np.ndarray  # (E,) NaN for stations

    def at(self, t_gpst) -> np.ndarray:
        """ECEF truth at epoch tags t (exact epochs; KeyError for a time not recorded)."""
        t = np.atleast_1d(np.asarray(t_gpst, float))
        idx = np.searchsorted(self.t_gpst, t)
        ok = (idx < len(self.t_gpst)) & np.isclose(self.t_gpst[np.minimum(idx, len(self.t_gpst) - 1)], t,
                                                    atol=1e-6, rtol=0)
        if not ok.all():
            raise KeyError(f"{self.receiver}: no truth at {t[~ok][:3]}")
        return self.ecef_m[idx]


def _f(v: str) -> float:
    return float(v) if v else float("nan")


def load_truth(folder: str | Path) -> dict[str, ReceiverTruth]:
    rows: dict[str, list[dict]] = {}
    with open(Path(folder) / "truth.csv", newline="") as f:
        for r in csv.DictReader(f):
            rows.setdefault(r["receiver"], []).append(r)
    out = {}
    for rid, rs in rows.items():
        out[rid] = ReceiverTruth(
            rid, rs[0]["kind"], np.array([float(r["gpst_s"]) for r in rs]),
            np.array([[float(r["x_m"]), float(r["y_m"]), float(r["z_m"])] for r in rs]),
            np.array([float(r["clock_s"]) for r in rs]), np.array([r["track"] for r in rs]),
            np.array([_f(r["km"]) for r in rs]), np.array([_f(r["speed_m_s"]) for r in rs]))
    return out


def load_atmosphere(folder: str | Path) -> dict[str, np.ndarray]:
    """atmosphere.csv as columns: `gpst_s`, `receiver`, `sat`, `iono_l1_m`, `tropo_m`, ... (N_k as float)."""
    with open(Path(folder) / "atmosphere.csv", newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        cols = list(zip(*reader)) or [() for _ in header]
    out = {}
    for name, values in zip(header, cols):
        if name in ("receiver", "sat"):
            out[name] = np.array(values)
        else:
            out[name] = np.array([_f(v) for v in values])
    return out


def load_scenario_json(folder: str | Path) -> dict:
    return json.loads((Path(folder) / "scenario.json").read_text())
