"""Carrier tracking truth: continuous arcs, integer ambiguities, cycle slips, lock time, half cycles.

Per (receiver, satellite, signal), one epoch at a time:
  * a satellite that becomes visible (risen, out of a tunnel, station back from an outage) starts a
    new arc: a new integer ambiguity, lock time 0, loss-of-lock flag (RINEX LLI bit 0);
  * while tracked, a cycle slip happens with the scenario's rate (Poisson per receiver and
    satellite): an integer jump on one or more signals, flagged and with the lock time reset;
  * with `half_cycle`, a new arc starts with a half-cycle ambiguity on about half of its signals,
    flagged (LLI bit 1) until the receiver resolves it after `HALF_CYCLE_RESOLVE_S`;
  * unflagged events (`Unflagged`, default none; real receivers, docs/simulator-calibration.md): phase
    resets (the phase re-aligned to the code on every signal, as Trimble NetRS at 30 s do 2-25 times a
    day, decision 0150: every signal jumps by the same distance rounded to its cycles, so code minus phase
    jumps by metres to kilometres and the geometry-free phase by under 0.25 m), cycle slips without a flag,
    and data gaps of a few epochs with the phase carried through; no LLI, the lock time runs on (unless the
    receiver announces them: then its resets and slips are flagged and restart the lock time). They draw
    from their own random stream, so a scenario without them gives the same bytes as before; the rates may
    differ per receiver (scenario errors.by_receiver) without moving any other receiver's draws.
Random numbers are drawn in fixed shapes every epoch, so results do not depend on how epochs are
grouped into blocks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

AMBIGUITY_SPAN_CYCLES = 500  # new-arc ambiguities drawn in +-this: phase stays within ~100 m of code
SLIP_MAX_CYCLES = 20
SLIP_SIGNAL_SHARE = 0.6  # chance each signal of a slipping satellite jumps (at least one does)
HALF_CYCLE_RESOLVE_S = 6.0  # half-cycle ambiguity flagged until the receiver finds the preamble

# Phase resets: the distance the phase jumps to meet the code, log-uniform between these [m] (catnet's NetRS
# code minus phase jumps of > 20 m to kilometres, decision 0150).
RESET_MIN_M = 20.0
RESET_MAX_M = 5000.0
GAP_MAX_EPOCHS = 3  # a data gap lasts 1 to this many epochs (catnet 30 s: mostly one epoch)

LLI_LOSS_OF_LOCK = 1  # RINEX 3.04 5.7: bit 0
LLI_HALF_CYCLE = 2  # bit 1


@dataclass
class TrackingEpoch:
    ambiguity_cyc: np.ndarray  # (R, N, K) integer-valued
    half_cycle: np.ndarray  # (R, N, K) 0 or 0.5 cycles
    lock_time_s: np.ndarray  # (R, N, K)
    lli: np.ndarray  # (R, N, K) int8 flags
    dropped: np.ndarray | None = None  # (R, N) bool: tracked but no data this epoch (a gap)


@dataclass(frozen=True)
class Unflagged:
    """Rates per receiver-satellite and hour of the events a real receiver does not flag: one for every receiver,
    or one per receiver (R,). `announced` (R,) bool: receivers that flag these resets and slips after all (LLI,
    lock time restarted; decision 0273), drawn at the same moments as if they did not."""

    phase_resets_per_hour: float | np.ndarray = 0.0
    slips_per_hour: float | np.ndarray = 0.0
    gaps_per_hour: float | np.ndarray = 0.0
    wavelength_m: np.ndarray | None = field(default=None, compare=False)  # (N, K), for the resets
    announced: np.ndarray | None = field(default=None, compare=False)

    @property
    def any(self) -> bool:
        return bool(np.any(np.asarray(self.phase_resets_per_hour) > 0) or np.any(np.asarray(self.slips_per_hour) > 0)
                    or np.any(np.asarray(self.gaps_per_hour) > 0))


def _per_receiver(rate_per_hour, dt_s: float):
    """An event probability per epoch: a scalar, or (R, 1) from per-receiver rates (broadcast over satellites)."""
    p = np.asarray(rate_per_hour, float) / 3600.0 * dt_s
    return p[:, None] if p.ndim == 1 else p


class Tracking:
    def __init__(self, shape: tuple[int, int, int], dt_s: float, slips_per_hour: float, half_cycle: bool,
                 rng: np.random.Generator, unflagged: Unflagged | None = None,
                 rng_unflagged: np.random.Generator | None = None):
        self.shape = shape
        self.dt = dt_s
        self.p_slip = _per_receiver(slips_per_hour, dt_s)  # scalar or per receiver (R,)
        self.half_cycle_on = half_cycle
        self.rng = rng
        self.tracking = np.zeros(shape[:2], bool)
        self.lock_s = np.zeros(shape)
        self.amb = np.zeros(shape)
        self.half = np.zeros(shape)
        self.unflagged = unflagged if unflagged is not None and unflagged.any else None
        if self.unflagged is not None:
            u = self.unflagged
            self.rng_u = rng_unflagged
            self.p_reset = _per_receiver(u.phase_resets_per_hour, dt_s)
            self.p_uslip = _per_receiver(u.slips_per_hour, dt_s)
            self.p_gap = _per_receiver(u.gaps_per_hour, dt_s)
            self.announced = (np.zeros(shape[0], bool) if u.announced is None
                              else np.asarray(u.announced, bool))[:, None, None]
            lam = u.wavelength_m if u.wavelength_m is not None else np.ones(shape[1:])
            self.lam = np.where(np.isfinite(lam), lam, np.inf)[None]  # (1, N, K)
            self.gap_left = np.zeros(shape[:2], int)
            self.pending = np.zeros(shape, bool)  # loss-of-lock flags waiting for the end of a gap

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
        dropped = None
        if self.unflagged is not None:
            dropped, moved = self._unflagged(visible, new_arc, slip, draw_jump, draw_jump_on)
            told = moved & self.announced  # a receiver that announces them: flagged, lock time restarted
            self.lock_s = np.where(told, 0.0, self.lock_s)
            reset = reset | told | self.pending
            # a flag raised while the satellite's data are dropped (a gap) goes out with its next data
            self.pending = reset & dropped[..., None]
        if self.half_cycle_on:
            self.half = np.where(new_arc[..., None], np.where(draw_half, 0.5, 0.0), self.half)
            self.half = np.where(self.lock_s >= HALF_CYCLE_RESOLVE_S, 0.0, self.half)
        self.tracking = visible
        lli = (reset * LLI_LOSS_OF_LOCK | (self.half != 0) * LLI_HALF_CYCLE).astype(np.int8)
        return TrackingEpoch(self.amb, self.half, self.lock_s, lli, dropped)

    def _unflagged(self, visible, new_arc, slip, draw_jump, draw_jump_on):
        """Phase resets, unflagged slips and gaps on the arcs that carry on this epoch; the dropped mask (R, N) and
        the signals whose phase moved (R, N, K)."""
        R, N, K = self.shape
        rng = self.rng_u
        u = rng.random((3, R, N))
        dist = np.exp(rng.uniform(np.log(RESET_MIN_M), np.log(RESET_MAX_M), (R, N))) * rng.choice([-1, 1], (R, N))
        gap_len = rng.integers(1, GAP_MAX_EPOCHS + 1, (R, N))
        going = visible & ~new_arc & ~slip
        resets = going & (u[0] < self.p_reset)
        # every signal moves by the same distance, in whole cycles of its own wavelength
        d_reset = np.where(resets[..., None] & np.isfinite(self.lam), np.round(dist[..., None] / self.lam), 0.0)
        uslip = going & ~resets & (u[1] < self.p_uslip)
        jump = np.where(uslip[..., None] & draw_jump_on, draw_jump, 0)
        jump[..., 0] = np.where(uslip & ~(jump != 0).any(-1), draw_jump[..., 0], jump[..., 0])
        self.amb = self.amb + d_reset + jump
        self.gap_left = np.where(visible, np.maximum(self.gap_left - 1, 0), 0)
        start = going & (self.gap_left == 0) & (u[2] < self.p_gap)
        self.gap_left = np.where(start, gap_len, self.gap_left)
        return self.gap_left > 0, (d_reset != 0) | (jump != 0)
