"""Correction latency model: when a VRS epoch reaches the train.

Nothing travels over a socket in a scenario run, so the delays a live system has are drawn here
instead (seeded: the same scenario gives the same delays). A VRS epoch tagged t reaches the train at

    t + STATION_UPLINK_S + CENTRE_PROCESSING_S + downlink,   downlink ~ lognormal(median, sigma)

and the train solves epoch t at t with the newest VRS epoch that has arrived by then (low-latency RTK,
what a train needs: it cannot wait for the base), so the correction age is normally 1 s at 1 Hz and
2 s or more when the cellular downlink is slow. The filter refuses corrections older than
`augnet.onboard.rtk.RtkOptions.max_age_s` (5 s). Source of the scale: ../shared/design/network-rtk.md,
"corrections normally arrive under 2 s old and must stay under 5 s"; the split between the links
and the shape of the downlink distribution are this model's assumptions (a station's NTRIP upload
over fibre or a leased line, a caster in the same centre, a cellular downlink with a long tail).
"""

from __future__ import annotations

import numpy as np

STATION_UPLINK_S = 0.20  # station -> centre: MSM epoch framing plus a wired NTRIP upload
CENTRE_PROCESSING_S = 0.10  # network solution + VRS synthesis + encoding per epoch
DOWNLINK_MEDIAN_S = 0.25  # caster -> train over a cellular bearer, one way
DOWNLINK_SIGMA_LN = 0.5  # lognormal shape: ~2 % of epochs slower than 0.7 s, arriving after the next epoch
SEED_TAG = 0x1A7E  # keeps this stream of draws apart from the simulator's own
RBC_SEED_TAG = 0x2BC  # the train -> RBC draws, apart from the downlink's (adding them changes no VRS arrival)


class LatencyModel:
    def __init__(self, seed: int, uplink_s: float = STATION_UPLINK_S, processing_s: float = CENTRE_PROCESSING_S,
                 downlink_median_s: float = DOWNLINK_MEDIAN_S, downlink_sigma_ln: float = DOWNLINK_SIGMA_LN):
        self.uplink_s = uplink_s
        self.processing_s = processing_s
        self.downlink_median_s = downlink_median_s
        self.downlink_sigma_ln = downlink_sigma_ln
        self._rng = np.random.default_rng([seed, SEED_TAG])
        self._rbc_rng = np.random.default_rng([seed, RBC_SEED_TAG])

    def station_arrival(self, t_gpst: float) -> float:
        """When a station epoch tagged t reaches the centre."""
        return t_gpst + self.uplink_s

    def downlink(self, n: int) -> np.ndarray:
        """n independent one-way downlink delays [s] (one per train session and epoch)."""
        return self.downlink_median_s * np.exp(self.downlink_sigma_ln * self._rng.standard_normal(n))

    def train_to_rbc(self, n: int, cycle_s: float) -> np.ndarray:
        """n delays [s] from an alarm raised at the train to the RBC acting on it: the train's RSSP-I main cycle
        sends it at the next cycle (uniform wait up to `cycle_s`), the cellular bearer carries it one way (the
        downlink's distribution, the same bearer), the RBC reads it at its next cycle (uniform wait again)."""
        rng = self._rbc_rng
        bearer = self.downlink_median_s * np.exp(self.downlink_sigma_ln * rng.standard_normal(n))
        return rng.uniform(0.0, cycle_s, n) + bearer + rng.uniform(0.0, cycle_s, n)

    def describe(self) -> dict:
        return {"station_uplink_s": self.uplink_s, "centre_processing_s": self.processing_s,
                "downlink_median_s": self.downlink_median_s, "downlink_sigma_ln": self.downlink_sigma_ln,
                "rover_mode": "low latency: epoch t is solved at t with the newest VRS epoch received"}
