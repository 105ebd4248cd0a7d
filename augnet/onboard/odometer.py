"""The train's odometer as the onboard unit sees it: pulse counts, their distance, and the variance of a
distance increment (the error model the along-track fusion weights by).

The stream is what a wheel tachometer delivers: a cumulative pulse count (forward positive, since
switch-on) at a time. The onboard converts counts to metres with the calibrated wheel and its pulses per
revolution; the true wheel differs (radius error), the wheel slips under traction and slides under
braking, and the speed derived from it has white noise. Variance of the distance travelled between two
readings (railway.md, the weighted-median literature: white-noise velocity error ~0.5 km/h, slip and slide
a Wiener process), over D metres in T seconds sampled every dt seconds:

    var = (sigma_v dt)^2 T / dt      white speed error, integrated per reading (a random walk)
        + (scale_sigma D)^2          the radius calibration error, proportional to distance
        + q_slip T                   slip / slide, a Wiener process in distance
        + 2 q^2 / 12                 quantisation of both end counts (q = metres per pulse)

Sans-IO: readings in, numbers out; no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# railway.md (weighted-median fusion, after the field trial it cites): white-noise velocity error ~0.5 km/h.
SPEED_WHITE_SIGMA_M_S = 0.5 / 3.6
# Nominal high-speed wheel: 920 mm new tread diameter (EN 13262 / UIC 510-2 sizes for 25 m coaches and EMUs).
NOMINAL_WHEEL_DIAMETER_M = 0.92
DEFAULT_PULSES_PER_REV = 200  # a common tachometer resolution (100-256 per revolution); 14.5 mm per pulse
# Onboard belief of the radius calibration error (1 sigma, relative): a wheel calibrated against balises or
# GNSS keeps ~0.1 %; the simulator's radius error is a scenario field (stations/odometer.py).
SCALE_SIGMA = 1e-3
# Onboard belief of the slip/slide Wiener intensity [m^2/s], bounding the simulator's wet-rail value
# (stations/odometer.SLIP_WIENER_M2_PER_S) while under traction or braking: the unit does not know the rail.
SLIP_WIENER_BOUND_M2_PER_S = 0.05


class OdometerError(ValueError):
    """An odometer reading that cannot be used (time going back, non-integer count)."""


@dataclass(frozen=True)
class OdometerSample:
    """One tachometer reading: the cumulative pulse count (forward positive) at `time` [s, the unit's GPST]."""

    time: float
    pulses: int


@dataclass(frozen=True)
class OdometerModel:
    """How the onboard turns pulses into metres and how uncertain an increment is."""

    wheel_diameter_m: float = NOMINAL_WHEEL_DIAMETER_M
    pulses_per_rev: int = DEFAULT_PULSES_PER_REV
    speed_sigma_m_s: float = SPEED_WHITE_SIGMA_M_S
    scale_sigma: float = SCALE_SIGMA
    slip_wiener_m2_per_s: float = SLIP_WIENER_BOUND_M2_PER_S
    sample_interval_s: float = 1.0  # dt of the readings the white speed error is integrated over

    def __post_init__(self):
        for name in ("wheel_diameter_m", "sample_interval_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise OdometerError(f"odometer {name} must be positive, got {v}")
        if not (isinstance(self.pulses_per_rev, int) and self.pulses_per_rev > 0):
            raise OdometerError(f"odometer pulses_per_rev must be a positive integer, got {self.pulses_per_rev}")
        for name in ("speed_sigma_m_s", "scale_sigma", "slip_wiener_m2_per_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise OdometerError(f"odometer {name} must be zero or positive, got {v}")

    @property
    def metres_per_pulse(self) -> float:
        return math.pi * self.wheel_diameter_m / self.pulses_per_rev

    def distance_m(self, pulses: int) -> float:
        return pulses * self.metres_per_pulse

    def increment_variance_m2(self, distance_m: float, elapsed_s: float) -> float:
        """Variance [m^2] of a distance increment of `distance_m` travelled over `elapsed_s` (module docstring)."""
        d, t = abs(distance_m), max(elapsed_s, 0.0)
        q = self.metres_per_pulse
        white = self.speed_sigma_m_s ** 2 * self.sample_interval_s * t
        return white + (self.scale_sigma * d) ** 2 + self.slip_wiener_m2_per_s * t + q * q / 6.0


def check_sample(sample: OdometerSample, previous: OdometerSample | None) -> None:
    """Refuse a reading that is not a count or goes back in time (clear error, never a crash later)."""
    if not isinstance(sample.pulses, int) or isinstance(sample.pulses, bool):
        raise OdometerError(f"odometer pulses must be an integer count, got {sample.pulses!r}")
    if not math.isfinite(sample.time):
        raise OdometerError(f"odometer time must be finite, got {sample.time}")
    if previous is not None and sample.time < previous.time:
        raise OdometerError(f"odometer time went back: {sample.time} after {previous.time}")
