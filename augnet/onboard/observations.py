"""Observations as the positioning core uses them: per epoch, satellites x frequency slots.

A receiver file or stream gives observables per RINEX type ("C1C", "L2W", ...).  The filter wants,
for each satellite, a small number of *frequency slots* (slot 0 = L1/E1/B1I, slot 1 = the second
frequency ...), each with one code, phase, Doppler, SNR and loss-of-lock flag, plus the carrier
wavelength.  This module makes that choice once per satellite (the best tracked signal of each band,
by a priority list), so a satellite's arc never switches signal in the middle.

The input is deliberately plain: `ObsArrays` holds epoch times, satellite ids and one
(epochs x satellites) array per observation type, which is what `augnet.gnss.rinex.read_obs`
returns and what an RTCM MSM decoder can produce.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from augnet.gnss.signals import (
    FREQ_B1I_HZ,
    FREQ_B3I_HZ,
    FREQ_E5B_HZ,
    FREQ_L1_HZ,
    FREQ_L2_HZ,
    FREQ_L5_HZ,
)
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S

# Bands per system for each frequency slot (RINEX band digits).  Default dual frequency follows the
# railway design: GPS/QZSS L1+L2, Galileo E1+E5a, BeiDou B1I+B3I; a third slot where tracked.
SYSTEM_BANDS: dict[str, tuple[str, ...]] = {
    "G": ("1", "2", "5"),
    "J": ("1", "2", "5"),
    "E": ("1", "5", "7"),
    "C": ("2", "6", "7"),
}
BAND_FREQ_HZ: dict[tuple[str, str], float] = {
    ("G", "1"): FREQ_L1_HZ, ("G", "2"): FREQ_L2_HZ, ("G", "5"): FREQ_L5_HZ,
    ("J", "1"): FREQ_L1_HZ, ("J", "2"): FREQ_L2_HZ, ("J", "5"): FREQ_L5_HZ,
    ("E", "1"): FREQ_L1_HZ, ("E", "5"): FREQ_L5_HZ, ("E", "7"): FREQ_E5B_HZ,
    ("C", "2"): FREQ_B1I_HZ, ("C", "6"): FREQ_B3I_HZ, ("C", "7"): FREQ_E5B_HZ,
}
# Tracking-mode priority within a band (RINEX attribute letters, best first).  Semi-codeless P(Y)
# (W) comes first on GPS L2 because every geodetic receiver has it; the RINEX 3 rule that phases
# are aligned to a common reference (quarter-cycle shifts removed) lets base and rover differ.
ATTRIBUTE_PRIORITY: dict[tuple[str, str], str] = {
    ("G", "1"): "CWPSLX", ("G", "2"): "WPCLXSD", ("G", "5"): "QXI",
    ("J", "1"): "CXSLZ", ("J", "2"): "LXS", ("J", "5"): "QXI",
    ("E", "1"): "CXBAZ", ("E", "5"): "QXI", ("E", "7"): "QXI",
    ("C", "2"): "IXQ", ("C", "6"): "IXQ", ("C", "7"): "IXQ",
}
SUPPORTED_SYSTEMS = tuple(SYSTEM_BANDS)

# RINEX LLI bit 0: loss of lock since the previous observation (possible cycle slip); bit 1: half
# cycle ambiguity (RINEX 3.04 5.3).
LLI_SLIP = 1
LLI_HALF_CYCLE = 2

# Plausibility limits for raw observables; anything outside is treated as missing, not used.
# Ranges from the ground to GNSS satellites: 19,100 km (GPS at zenith) to ~42,000 km (BDS GEO at the
# horizon), plus receiver clock offsets of up to a millisecond (300 km) either way.
MIN_PSEUDORANGE_M = 1.0e7
MAX_PSEUDORANGE_M = 6.0e7
# RINEX F14.3 cannot hold more than 1e10; a phase of exactly 0 is how several receivers say "none".
MAX_ABS_PHASE_CYC = 1.0e10
# Doppler of a satellite seen from a train: < 6 kHz; 1e5 Hz leaves room and rejects garbage.
MAX_ABS_DOPPLER_HZ = 1.0e5


@dataclass
class ObsArrays:
    """Observations of one receiver over many epochs, per RINEX observation type.

    `obs[type]` and `lli[type]` are (epochs x satellites); NaN / 0 where missing.
    """

    times: np.ndarray  # (T,) GPST seconds
    sats: Sequence[str]  # (N,) RINEX ids 'G05'
    obs: Mapping[str, np.ndarray]
    lli: Mapping[str, np.ndarray] = field(default_factory=dict)
    approx_position_m: np.ndarray | None = None
    # RINEX MARKER TYPE; "NON_PHYSICAL" marks a computed station such as a network VRS, whose data
    # carry the network's residual atmosphere errors (the RTK filter weights its ionosphere for that)
    marker_type: str = ""
    antenna_type: str = ""  # RINEX ANT # / TYPE (type and radome): the ANTEX calibration to look up
    antenna_delta_hen_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # RINEX ANTENNA: DELTA H/E/N

    @property
    def non_physical(self) -> bool:
        return self.marker_type.strip().upper() == "NON_PHYSICAL"


@dataclass
class EpochObs:
    """One receiver's observations at one epoch: satellites x frequency slots.

    Missing values are NaN (LLI 0).  `wavelength_m` is NaN where the slot has no signal.
    """

    time: float  # GPST seconds (receiver time tag)
    sats: np.ndarray  # (N,) '<U3'
    code_m: np.ndarray  # (N, F)
    phase_cyc: np.ndarray  # (N, F)
    doppler_hz: np.ndarray  # (N, F)
    snr_dbhz: np.ndarray  # (N, F)
    lli: np.ndarray  # (N, F) int
    wavelength_m: np.ndarray  # (N, F)
    signal: np.ndarray  # (N, F) '<U3' RINEX signal ('1C', '2W', '' when none)
    # an epoch made from others (base_interpolation.py): how old its information is [s]; NaN for a measured one
    info_age_s: float = math.nan
    # ... and the newest measured epoch whose information went into it [GPST s]; NaN: its own time
    newest_epoch_s: float = math.nan

    @property
    def newest_time(self) -> float:
        """The time of the newest measured epoch behind these observations (its own for a measured one)."""
        return self.time if math.isnan(self.newest_epoch_s) else float(self.newest_epoch_s)

    @property
    def n_slots(self) -> int:
        return self.code_m.shape[1]

    def sanitised(self) -> "EpochObs":
        """A copy with implausible values (non-finite, out of range, phase exactly 0) set missing."""
        code = np.where((self.code_m > MIN_PSEUDORANGE_M) & (self.code_m < MAX_PSEUDORANGE_M), self.code_m, np.nan)
        ph = self.phase_cyc
        phase = np.where(np.isfinite(ph) & (np.abs(ph) < MAX_ABS_PHASE_CYC) & (ph != 0.0), ph, np.nan)
        dop = np.where(np.abs(self.doppler_hz) < MAX_ABS_DOPPLER_HZ, self.doppler_hz, np.nan)
        snr = np.where(np.isfinite(self.snr_dbhz), self.snr_dbhz, np.nan)
        return EpochObs(float(self.time), self.sats, code, phase, dop, snr, self.lli, self.wavelength_m, self.signal,
                        self.info_age_s, self.newest_epoch_s)

    def take(self, index) -> "EpochObs":
        idx = np.asarray(index)
        return EpochObs(self.time, self.sats[idx], self.code_m[idx], self.phase_cyc[idx], self.doppler_hz[idx],
                        self.snr_dbhz[idx], self.lli[idx], self.wavelength_m[idx], self.signal[idx], self.info_age_s,
                        self.newest_epoch_s)


def choose_signals(data: ObsArrays, n_slots: int = 2, systems: Sequence[str] = SUPPORTED_SYSTEMS) -> dict[str, list[str]]:
    """Per satellite, the RINEX signal code ('1C', '2W' ...) used in each slot ('' when none).

    The choice is the best-priority attribute with both code and phase present in most epochs.
    """
    out: dict[str, list[str]] = {}
    for j, sat in enumerate(data.sats):
        sys_ = sat[0]
        if sys_ not in systems or sys_ not in SYSTEM_BANDS:
            continue
        codes = []
        for band in SYSTEM_BANDS[sys_][:n_slots]:
            best, best_n = "", 0
            for attr in ATTRIBUTE_PRIORITY[(sys_, band)]:
                c = data.obs.get(f"C{band}{attr}")
                lph = data.obs.get(f"L{band}{attr}")
                if c is None or lph is None:
                    continue
                n = int(np.count_nonzero(np.isfinite(c[:, j]) & np.isfinite(lph[:, j])))
                # priority order wins unless a lower-priority signal is tracked far more often
                if n > 2 * best_n:
                    best, best_n = band + attr, n
            codes.append(best)
        out[str(sat)] = codes
    return out


def epochs(data: ObsArrays, n_slots: int = 2, systems: Sequence[str] = SUPPORTED_SYSTEMS,
           signals: dict[str, list[str]] | None = None) -> list[EpochObs]:
    """Split an `ObsArrays` into `EpochObs`, one per epoch, with the slot signals chosen once."""
    if signals is None:
        signals = choose_signals(data, n_slots, systems)
    sats = [s for s in data.sats if str(s) in signals]
    col = np.array([list(data.sats).index(s) for s in sats], dtype=int)
    T, N = len(data.times), len(sats)
    shape = (T, N, n_slots)
    code = np.full(shape, np.nan)
    phase = np.full(shape, np.nan)
    dop = np.full(shape, np.nan)
    snr = np.full(shape, np.nan)
    lli = np.zeros(shape, dtype=np.int16)
    wl = np.full((N, n_slots), np.nan)
    sig = np.full((N, n_slots), "", dtype="<U3")
    for k, (sat, j) in enumerate(zip(sats, col)):
        for f, s in enumerate(signals[str(sat)][:n_slots]):
            if not s:
                continue
            sig[k, f] = s
            wl[k, f] = SPEED_OF_LIGHT_M_S / BAND_FREQ_HZ[(sat[0], s[0])]
            for arr, prefix in ((code, "C"), (phase, "L"), (dop, "D"), (snr, "S")):
                a = data.obs.get(prefix + s)
                if a is not None:
                    arr[:, k, f] = a[:, j]
            li = data.lli.get("L" + s)
            if li is not None:
                lli[:, k, f] = li[:, j]
    sats_a = np.array([str(s) for s in sats], dtype="<U3")
    # phase without code (or the reverse) is of no use to the filter; keep them consistent
    return [
        EpochObs(float(data.times[t]), sats_a, code[t], phase[t], dop[t], snr[t], lli[t], wl, sig)
        for t in range(T)
    ]
