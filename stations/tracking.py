"""Carrier tracking truth: continuous arcs, integer ambiguities, cycle slips, lock time, half cycles.

Per (receiver, satellite, signal), one epoch at a time:
  * a satellite that becomes visible (risen, out of a tunnel, station back from an outage) starts a
    new arc: a new integer ambiguity, lock time 0, loss-of-lock flag (RINEX LLI bit 0);
  * while tracked, a cycle slip happens with the scenario's rate (Poisson per receiver and
    satellite): an integer jump on one or more signals, flagged and with the lock time reset;
  * with `half_cycle`, a new arc starts with a half-cycle ambiguity on about half of its signals,
    flagged (LLI bit 1) until the receiver resolves it after `HALF_CYCLE_RESOLVE_S`.
Random numbers are drawn in fixed shapes every epoch, so results do not depend on how epochs are
grouped into blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

AMBIGUITY_SPAN_CYCLES = 500  # new-arc ambiguities drawn in +-this: phase stays within ~100 m of code
SLIP_MAX_CYCLES = 20
SLIP_SIGNAL_SHARE = 0.6  # chance each signal of a slipping satellite jumps (at least one does)
HALF_CYCLE_RESOLVE_S = 6.0  # half-cycle ambiguity flagged until the receiver finds the preamble

LLI_LOSS_OF_LOCK = 1  # RINEX 3.04 5.7: bit 0
LLI_HALF_CYCLE = 2  # bit 1


@dataclass
class TrackingEpoch:
    ambiguity_cyc: np.ndarray  # (R, N, K) integer-valued
    half_cycle: np.ndarray  # (R, N, K) 0 or 0.5 cycles
    lock_time_s: np.ndarray  # (R, N, K)
    lli: np.ndarray  # (R, N, K) int8 flags


class Tracking:
    def __init__(self, shape: tuple[int, int, int], dt_s: float, slips_per_hour: float, half_cycle: bool,
                 rng: np.random.Generator):
        self.shape = shape
        self.dt = dt_s
        self.p_slip = slips_per_hour / 3600.0 * dt_s
        self.half_cycle_on = half_cycle
        self.rng = rng
        self.tracking = np.zeros(shape[:2], bool)
        self.lock_s = np.zeros(shape)
        self.amb = np.zeros(shape)
        self.half = np.zeros(shape)

    def step(self, visible: np.ndarray) -> TrackingEpoch:
        """Advance one epoch given which (receiver, satellite) pairs can be tracked now."""
        R, N, K = self.shape
        rng = self.rng
        draw_slip = rng.random((R, N))
        draw_amb = rng.integers(-AMBIGUITY_SPAN_CYCLES, AMBIGUITY_SPAN_CYCLES + 1, (R, N, K))
        draw_jump = rng.integers(1, SLIP_MAX_CYCLES + 1, (R, N, K)) * rng.choice([-1, 1], (R, N, K))
        draw_jump_on = rng.random((R, N, K)) < SLIP_SIGNAL_SHARE
        draw_half = rng.random((R, N, K)) < 0.5
        new_arc = visible & ~self.tracking
        slip = visible & ~new_arc & (draw_slip < self.p_slip)
        jump = np.where(slip[..., None] & draw_jump_on, draw_jump, 0)
        none = slip & ~(jump != 0).any(-1)  # a slip changes at least one signal's ambiguity
        jump[..., 0] = np.where(none, draw_jump[..., 0], jump[..., 0])
        self.amb = np.where(new_arc[..., None], draw_amb, self.amb + jump)
        reset = new_arc[..., None] | (jump != 0)
        self.lock_s = np.where(reset, 0.0, self.lock_s + self.dt)
        if self.half_cycle_on:
            self.half = np.where(new_arc[..., None], np.where(draw_half, 0.5, 0.0), self.half)
            self.half = np.where(self.lock_s >= HALF_CYCLE_RESOLVE_S, 0.0, self.half)
        self.tracking = visible
        lli = (reset * LLI_LOSS_OF_LOCK | (self.half != 0) * LLI_HALF_CYCLE).astype(np.int8)
        return TrackingEpoch(self.amb, self.half, self.lock_s, lli)
