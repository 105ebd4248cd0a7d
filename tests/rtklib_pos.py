"""Reading rnx2rtkp solution files (`out-solformat=xyz`), shared by the tests that run RTKLIB."""

from __future__ import annotations

import numpy as np


def read_pos(path):
    """rnx2rtkp xyz output, times as week/TOW or date and time of day: (seconds (E,), xyz (E, 3), Q (E,))."""
    t, xyz, q = [], [], []
    for line in open(path):
        if line.startswith("%") or not line.strip():
            continue
        f = line.split()
        if ":" in f[1]:
            h, m, sec = f[1].split(":")
            t.append(int(h) * 3600 + int(m) * 60 + float(sec))
        else:
            t.append(float(f[1]))
        xyz.append([float(v) for v in f[2:5]])
        q.append(int(f[5]))
    return np.array(t), np.array(xyz).reshape(-1, 3), np.array(q, dtype=int)
