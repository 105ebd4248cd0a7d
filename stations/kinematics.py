"""Train kinematics along a line: speed profile with traction and braking limits.

The driver model is the usual one of running-time calculators: run at the permitted speed, accelerate
at `accel_m_s2` when below it, and brake at `decel_m_s2` early enough to meet every lower limit ahead
(braking curve v^2 = v_limit^2 + 2 d x), including a stop at the end of the line.  Integration is
explicit in time at `STEP_S`; positions are sampled at the simulation epochs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stations.scenario import Train

STEP_S = 0.05  # integration step: at 350 km/h the train moves 4.9 m per step
GRID_M = 5.0  # spacing of the speed-limit grid along the route


@dataclass(frozen=True)
class TrainMotion:
    """Truth motion of one train, sampled at the epochs (and at the mid-points between them)."""

    t_s: np.ndarray  # seconds since scenario start
    s_m: np.ndarray  # chainage along the line [m]
    speed_m_s: np.ndarray  # >= 0
    accel_m_s2: np.ndarray  # along the direction of travel
    direction: int  # +1 towards increasing km


def train_motion(train: Train, line_length_m: float, t_s: np.ndarray) -> TrainMotion:
    """Chainage, speed and acceleration of a train at times t_s (seconds since start, increasing)."""
    d = train.direction
    start = train.start_km * 1e3
    if not 0.0 <= start <= line_length_m:
        raise ValueError(f"train {train.id}: start_km {train.start_km} outside the line "
                         f"(0..{line_length_m / 1e3:.3f} km)")
    route_len = (line_length_m - start) if d > 0 else start
    u = np.arange(0.0, route_len + GRID_M, GRID_M)
    s_grid = start + d * u
    limit = np.full(u.shape, train.speed_kmh / 3.6)
    # Restrictions: entries sorted by km; each applies from its km up to the next entry's km.
    prof = sorted(train.speed_profile, key=lambda p: p.from_km)
    for k, p in enumerate(prof):
        lo = p.from_km * 1e3
        hi = prof[k + 1].from_km * 1e3 if k + 1 < len(prof) else np.inf
        inside = (s_grid >= lo) & (s_grid < hi)
        limit[inside] = np.minimum(limit[inside], p.speed_kmh / 3.6)
    limit[-1] = 0.0  # stop at the end of the line
    allowed = braking_curve(u, limit, train.decel_m_s2)  # the braking curve to every lower limit ahead
    ut, vt, at = drive(u, allowed, route_len, min(train.start_speed_kmh / 3.6, allowed[0]), train.accel_m_s2,
                       train.decel_m_s2, t_s)
    return TrainMotion(np.asarray(t_s, float), start + d * ut, vt, at, d)


def braking_curve(u: np.ndarray, limit: np.ndarray, decel_m_s2: float) -> np.ndarray:
    """The highest speed at each grid point (spacing `GRID_M`) from which every lower limit ahead is met."""
    allowed = limit.copy()
    two_d_dx = 2.0 * decel_m_s2 * GRID_M
    for i in range(len(u) - 2, -1, -1):
        allowed[i] = min(allowed[i], np.sqrt(allowed[i + 1] ** 2 + two_d_dx))
    return allowed


def drive(u: np.ndarray, allowed: np.ndarray, route_len: float, v0: float, accel_m_s2: float, decel_m_s2: float,
          t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance along the route (stopping at `route_len`), speed and acceleration at times t_s of the driver
    model: accelerate up to the allowed speed (`allowed` on the grid `u`, braking curves included)."""
    t_end = float(np.max(t_s)) if len(t_s) else 0.0
    n = int(np.ceil(t_end / STEP_S)) + 2
    tt = np.arange(n) * STEP_S
    uu = np.zeros(n)
    vv = np.zeros(n)
    aa = np.zeros(n)
    v = v0
    pos = 0.0
    for k in range(n):
        uu[k], vv[k] = pos, v
        cap = float(np.interp(pos, u, allowed))
        v_next = min(v + accel_m_s2 * STEP_S, cap)
        v_next = max(v_next, v - decel_m_s2 * STEP_S * 1.5, 0.0)
        aa[k] = (v_next - v) / STEP_S
        pos = min(pos + 0.5 * (v + v_next) * STEP_S, route_len)
        v = v_next if pos < route_len else 0.0
    return np.interp(t_s, tt, uu), np.interp(t_s, tt, vv), np.interp(t_s, tt, aa)
