"""Synthetic receiver observations from broadcast ephemerides, for testing the positioning core.

Truth is kept here and handed to tests separately from the observations: the estimator only ever
sees the `ObsArrays`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData, group_delay_s, transit
from augnet.gnss.geometry import azimuth_elevation, ecef_to_geodetic
from augnet.onboard.atmosphere import KLOBUCHAR_DEFAULT_ALPHA, KLOBUCHAR_DEFAULT_BETA, klobuchar_l1_m, saastamoinen_m
from augnet.onboard.observations import BAND_FREQ_HZ, ObsArrays

SIGNALS = {"G": ("1C", "2W"), "E": ("1C", "5Q")}
MASK_RAD = math.radians(10.0)


@dataclass
class Truth:
    times: np.ndarray  # (T,) true GPST of reception
    position_m: np.ndarray  # (T, 3)
    clock_s: np.ndarray  # (T,)
    ambiguities: dict  # (sat, slot) -> integer cycles


def simulate(nav: NavigationData, sats, t_true, position_m, *, clock_s=None, seed=0, code_sigma=0.3,
             phase_sigma=0.002, ambiguity_offset=0, slips=None, with_atmosphere=True):
    """Observations of one receiver: (ObsArrays, Truth).

    `slips`: list of (epoch index, sat, slot, cycles) added from that epoch on, with the LLI set.
    """
    rng = np.random.default_rng(seed)
    t = np.asarray(t_true, dtype=float)
    T = len(t)
    pos = np.broadcast_to(np.asarray(position_m, dtype=float), (T, 3)).copy()
    clk = np.zeros(T) if clock_s is None else np.asarray(clock_s, dtype=float)
    sats = list(sats)
    N = len(sats)
    tr = transit(nav, sats, pos, t)
    _, el = azimuth_elevation(pos[:, None, :], np.where(tr.valid[..., None], tr.sat_position_m, pos[:, None, :] + 1))
    az, _ = azimuth_elevation(pos[:, None, :], np.where(tr.valid[..., None], tr.sat_position_m, pos[:, None, :] + 1))
    visible = tr.valid & (el > MASK_RAD)
    llh = ecef_to_geodetic(pos)
    obs = {}
    lli = {}
    amb = {}
    for j, sat in enumerate(sats):
        s = sat[0]
        for f, code in enumerate(SIGNALS[s]):
            amb[(sat, f)] = int(rng.integers(-1000, 1000)) + ambiguity_offset
    for s, codes in SIGNALS.items():
        for f, code in enumerate(codes):
            freq = BAND_FREQ_HZ[(s, code[0])]
            wl = SPEED_OF_LIGHT_M_S / freq
            cols = np.array([sat[0] == s for sat in sats])
            # group delay per (epoch, sat) from the selected ephemeris
            gd = np.zeros((T, N))
            for ti in range(T):
                r = nav.table.take(np.where(tr.valid[ti], tr.ephemeris_index[ti], 0))
                gd[ti] = np.nan_to_num(group_delay_s(r, code), nan=0.0)
            if with_atmosphere:
                trop = saastamoinen_m(llh[:, 0:1], llh[:, 2:3], el)
                iono = klobuchar_l1_m(t[:, None], llh[:, 0:1], llh[:, 1:2], az, el, KLOBUCHAR_DEFAULT_ALPHA,
                                      KLOBUCHAR_DEFAULT_BETA) * (BAND_FREQ_HZ[("G", "1")] / freq) ** 2
            else:
                trop = iono = np.zeros((T, N))
            base = tr.range_m + SPEED_OF_LIGHT_M_S * (clk[:, None] - tr.sat_clock_bias_s) + trop
            P = base + SPEED_OF_LIGHT_M_S * gd + iono + rng.normal(0, code_sigma, (T, N))
            N_int = np.array([amb.get((sat, f), 0) for sat in sats], dtype=float)
            L = (base - iono + rng.normal(0, phase_sigma, (T, N))) / wl + N_int
            flags = np.zeros((T, N), dtype=np.int16)
            for (k, sat, slot, cyc) in slips or []:
                if slot == f and sat in sats:
                    jj = sats.index(sat)
                    L[k:, jj] += cyc
                    flags[k, jj] |= 1
            m = visible & cols[None, :]
            obs["C" + code] = np.where(m, P, np.where(cols[None, :], np.nan, obs.get("C" + code, np.nan)))
            obs["L" + code] = np.where(m, L, np.where(cols[None, :], np.nan, obs.get("L" + code, np.nan)))
            lli["L" + code] = np.where(m, flags, lli.get("L" + code, 0)).astype(np.int16)
    t_obs = t + clk
    return ObsArrays(t_obs, sats, obs, lli, pos[0].copy()), Truth(t, pos, clk, amb)


def visible_sats(nav: NavigationData, position_m, t, systems=("G", "E"), n_max=None):
    sats = [s for s in nav.satellites if s[0] in systems]
    tr = transit(nav, sats, np.asarray(position_m, float), float(t))
    _, el = azimuth_elevation(np.asarray(position_m, float), np.where(tr.valid[:, None], tr.sat_position_m, 0))
    ok = tr.valid & (el > math.radians(15.0))
    out = [s for s, o in zip(sats, ok) if o]
    return out[:n_max] if n_max else out
