"""The reference satellite of each system on a baseline, and the double-difference pairing it gives.

A system's reference is kept while it is healthy (no slip, no new arc) and above `ref_min_elevation_deg`; else the
best healthy satellite takes over: a fixed one (its DD integers carry the others' over, `BaselineIntegers.rereference`)
and then the highest. It is chosen before slipped satellites are reset, so the others keep their integers.
"""

from __future__ import annotations

import math

import numpy as np

from augnet.centre.baseline_integers import BaselineIntegers


class ReferenceSatellites:
    def __init__(self, min_elevation_deg: float):
        self.min_elevation_deg = min_elevation_deg
        self.refs: dict[str, str] = {}  # system -> reference satellite

    def update(self, sats: np.ndarray, el_min_rad: np.ndarray, unhealthy: set[str],
               fixed: BaselineIntegers) -> list[tuple[str, str, str]]:
        """Choose this epoch's references; returns the (system, old, new) changes of a system that had one."""
        systems = np.array([s[0] for s in sats])
        changes = []
        for system in np.unique(systems):
            in_sys = np.flatnonzero(systems == system)
            healthy = [k for k in in_sys if sats[k] not in unhealthy]
            cur = self.refs.get(system)
            cur_k = next((k for k in healthy if sats[k] == cur), None)
            if cur_k is not None and el_min_rad[cur_k] >= math.radians(self.min_elevation_deg):
                continue
            pool = healthy if healthy else list(in_sys)
            best = str(sats[max(pool, key=lambda k: (fixed.both(sats[k]), el_min_rad[k]))])
            self.refs[system] = best
            if cur is not None and cur != best:
                changes.append((str(system), cur, best))
        for system in list(self.refs):
            if system not in systems:
                del self.refs[system]
        return changes


def pair_with_references(sats: np.ndarray, refs: dict[str, str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per satellite its system's reference and that one's position in `sats`, and the positions of the
    satellites that are not references (the DD rows)."""
    ref_of = np.array([refs[s[0]] for s in sats])
    pos = {s: k for k, s in enumerate(sats)}
    ref_k = np.array([pos[r] for r in ref_of])
    rows = np.array([k for k in range(len(sats)) if sats[k] != ref_of[k]], dtype=int)
    return ref_of, ref_k, rows
