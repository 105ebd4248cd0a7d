"""Simulated wheel odometers: pulse counts from the trains' true motion, with the errors of a real one.

Per train and epoch (vectorised over trains and epochs, one seeded stream per world):

* the wheel rolls the true distance plus slip/slide: a Wiener process in distance, active while the train
  accelerates or brakes (|a| > `TRACTION_ACCEL_M_S2`), of intensity `SLIP_WIENER_M2_PER_S[rail]`, plus an
  injected `odometer_slide` fault (the wheel turns `slide_fraction` slower than the train moves) or
  `odometer_slip` fault (it spins `slip_fraction` faster);
* the speed the wheel gives has white noise `SPEED_WHITE_SIGMA_M_S` per reading (integrated into the count);
* the wheel's true radius is `wheel_radius_error_pct` larger than the calibrated one, so the counted
  revolutions map to a distance that much short (fixed per train);
* the tachometer counts whole pulses (`odometer_pulses_per_rev` per revolution): quantisation.

The truth (the true distance travelled, the wheel error) stays in `OdometerTruth`; the onboard gets only
`augnet.onboard.odometer.OdometerSample`s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from augnet.onboard.odometer import NOMINAL_WHEEL_DIAMETER_M, SPEED_WHITE_SIGMA_M_S, OdometerSample
from stations.scenario import Scenario

# Slip/slide Wiener intensity in distance [m^2/s] while under traction or braking. The weighted-median
# literature (railway.md) models slip/slide as a Wiener process without giving its level here; assumed: dry
# rail 0.005 m^2/s (0.07 m 1-sigma per 1 s of acceleration), wet rail 4x (adhesion on wet rail is about half
# the dry one, ~0.15 vs ~0.3, so the wheel creeps and slides more; UIC 544-1 / EN 15595 adhesion figures).
SLIP_WIENER_M2_PER_S = {"dry": 0.005, "wet": 0.02}
# Above this |acceleration| the wheels transmit traction or braking force (below: coasting at line speed).
TRACTION_ACCEL_M_S2 = 0.02
_SEED_TAG = 0x0D0


@dataclass(frozen=True)
class OdometerTruth:
    """What the simulated odometer should have counted, kept apart from its output."""

    distance_m: np.ndarray  # (T, E) true distance travelled since time 0 (forward positive)
    slip_m: np.ndarray  # (T, E) cumulative slip/slide (wheel minus train distance)
    radius_error: np.ndarray  # (T,) relative true-minus-calibrated wheel radius


@dataclass(frozen=True)
class OdometerStreams:
    """Pulse counts of every train at every epoch: (T, E) cumulative counts and the (E,) epoch times."""

    train_ids: tuple[str, ...]
    t_s: np.ndarray  # (E,) since the scenario start
    pulses: np.ndarray  # (T, E) int64
    truth: OdometerTruth

    def sample(self, train: str, epoch: int, time_gpst: float) -> OdometerSample:
        """The reading the onboard unit of `train` receives at `epoch`, stamped on the unit's clock."""
        i = self.train_ids.index(train)
        return OdometerSample(float(time_gpst), int(self.pulses[i, epoch]))


def simulate_odometers(scenario: Scenario, t_s: np.ndarray, km: np.ndarray, speed_m_s: np.ndarray,
                       *, seed_offset: int = 0) -> OdometerStreams:
    """Odometer streams for the scenario's trains from their truth motion.

    t_s (E,) seconds since the scenario's start, km (T, E) true chainage, speed_m_s (T, E) true speed.
    """
    trains = scenario.trains
    t = np.asarray(t_s, float)
    km = np.atleast_2d(np.asarray(km, float))
    v = np.atleast_2d(np.asarray(speed_m_s, float))
    if km.shape != (len(trains), len(t)) or v.shape != km.shape:
        raise ValueError(f"odometer: km and speed must be (trains, epochs) = {(len(trains), len(t))}, "
                         f"got {km.shape} and {v.shape}")
    n_tr, n_ep = km.shape
    rng = np.random.default_rng([scenario.seed, _SEED_TAG, seed_offset])
    dt = np.diff(t, prepend=t[:1])  # 0 at the first epoch: the count starts there
    step = np.abs(np.diff(km, axis=1, prepend=km[:, :1])) * 1e3  # true metres per epoch
    accel = np.diff(v, axis=1, prepend=v[:, :1]) / np.where(dt > 0, dt, 1.0)
    pushing = np.abs(accel) > TRACTION_ACCEL_M_S2
    q = SLIP_WIENER_M2_PER_S[scenario.rail]
    slip = np.where(pushing, rng.standard_normal((n_tr, n_ep)) * np.sqrt(q * dt), 0.0)
    # Injected slides: the wheel turns slower than the train moves (locked at slide_fraction = 1); injected
    # slips: it spins faster (slip_fraction of the train's speed on top).
    ids = [tr.id for tr in trains]
    for f in scenario.faults:
        if f.kind not in ("odometer_slide", "odometer_slip"):
            continue
        on = (t >= f.at_s) & (t < f.until_s)
        signed = -f.slide_fraction if f.kind == "odometer_slide" else f.slip_fraction
        slip[ids.index(f.train)] += np.where(on, signed * step[ids.index(f.train)], 0.0)
    white = rng.standard_normal((n_tr, n_ep)) * SPEED_WHITE_SIGMA_M_S * dt
    wheel_m = np.cumsum(step + slip + white, axis=1)  # distance the wheel's tread has rolled
    radius_err = np.array([tr.wheel_radius_error_pct / 100.0 for tr in trains])
    ppr = np.array([tr.odometer_pulses_per_rev for tr in trains], float)
    true_circumference = np.pi * NOMINAL_WHEEL_DIAMETER_M * (1.0 + radius_err)
    # Whole pulses counted; a random phase of the first pulse edge within a pulse at switch-on.
    phase = rng.random(n_tr)
    pulses = np.floor(wheel_m / true_circumference[:, None] * ppr[:, None] + phase[:, None]).astype(np.int64)
    pulses -= pulses[:, :1]
    truth = OdometerTruth(np.cumsum(step, axis=1), np.cumsum(slip, axis=1), radius_err)
    return OdometerStreams(tuple(ids), t, pulses, truth)
