"""Truth ionosphere: a vertical TEC field over the region, mapped to slant with a thin shell.

VTEC(lat, lon, t) [TECU] = diurnal mean (peak at 14 h local time)
                         + a large-scale planar gradient (mostly poleward decrease)
                         + medium-scale irregularities (a sum of drifting random plane waves with
                           the given spatial scale; a Gaussian field with the given standard deviation)
                         + a travelling ionospheric disturbance (one plane wave moving equatorward).
All terms are smooth in space and time, so the ionosphere decorrelates with distance the way a real
one does: the double difference grows with baseline length.

Slant delay: the ionospheric pierce point (IPP) on a shell at `shell_height_km`, the single-layer
mapping function M(z) = 1 / sqrt(1 - (R cos(el) / (R + H))^2), and the first-order group delay
I_f = 40.3e16 * STEC[TECU] / f^2 [m] (code delayed by I_f, phase advanced by I_f).
"""

from __future__ import annotations

import numpy as np

EARTH_RADIUS_M = 6_371_000.0  # mean radius, the single-layer model's sphere
IONO_K_M3_S2 = 40.3e16  # 40.3 m^3/s^2 per el/m^2, times 1e16 el/m^2 per TECU: I = K * TEC / f^2
N_IRREGULARITY_WAVES = 24
IRREGULARITY_DRIFT_M_S = 60.0  # typical mid-latitude drift of medium-scale structure
DIURNAL_AMPLITUDE = 0.35  # fraction of the mean: day/night contrast at mid latitudes
PEAK_LOCAL_HOUR = 14.0


class IonosphereField:
    """Deterministic VTEC field for a region centred on (lat0, lon0) [deg]."""

    def __init__(self, params: dict, lat0_deg: float, lon0_deg: float, seed: int):
        self.p = dict(params)
        self.lat0 = np.radians(lat0_deg)
        self.lon0 = np.radians(lon0_deg)
        self.shell_m = params["shell_height_km"] * 1e3
        rng = np.random.default_rng([seed, 0x10A0])
        # gradient direction: poleward decrease (towards the equator increase), +- 40 deg
        az = np.pi + rng.uniform(-0.7, 0.7)  # direction of increasing TEC (south-ish)
        self.grad = params["gradient_tecu_per_1000km"] / 1e6 * np.array([np.sin(az), np.cos(az)])
        scale = params["irregularity_scale_km"] * 1e3
        k = 2 * np.pi / (scale * rng.uniform(0.6, 1.6, N_IRREGULARITY_WAVES))
        ang = rng.uniform(0, 2 * np.pi, N_IRREGULARITY_WAVES)
        self.kvec = np.column_stack([k * np.cos(ang), k * np.sin(ang)])  # [rad/m]
        drift_ang = rng.uniform(0, 2 * np.pi)
        drift = IRREGULARITY_DRIFT_M_S * np.array([np.cos(drift_ang), np.sin(drift_ang)])
        self.omega = self.kvec @ drift  # frozen-flow advection [rad/s]
        self.phase = rng.uniform(0, 2 * np.pi, N_IRREGULARITY_WAVES)
        # sum of N cosines with equal amplitude a has std a * sqrt(N / 2)
        self.amp = params["irregularity_tecu"] / np.sqrt(N_IRREGULARITY_WAVES / 2.0)
        tid_az = np.pi + rng.uniform(-0.5, 0.5)  # equatorward propagation
        self.tid_k = 2 * np.pi / (params["tid_wavelength_km"] * 1e3) * np.array([np.sin(tid_az), np.cos(tid_az)])
        self.tid_w = 2 * np.pi / (params["tid_period_min"] * 60.0)
        self.tid_phase = rng.uniform(0, 2 * np.pi)

    def local_xy(self, lat, lon) -> np.ndarray:
        """East/north metres from the region centre on the sphere (equirectangular; region-sized)."""
        x = EARTH_RADIUS_M * (lon - self.lon0) * np.cos(self.lat0)
        y = EARTH_RADIUS_M * (lat - self.lat0)
        return np.stack([x, y], axis=-1)

    def vtec_tecu(self, lat, lon, t_gpst) -> np.ndarray:
        """Vertical TEC at geodetic lat, lon [rad] and GPST seconds (arrays broadcast)."""
        p = self.p
        if p["vtec_tecu"] == 0.0 and p["irregularity_tecu"] == 0.0 and p["tid_amplitude_tecu"] == 0.0:
            return np.zeros(np.broadcast(lat, lon, t_gpst).shape)
        t = np.asarray(t_gpst, float)
        xy = self.local_xy(lat, lon)
        local_h = np.mod(t / 3600.0 + np.degrees(lon) / 15.0, 24.0)
        mean = p["vtec_tecu"] * (1 + DIURNAL_AMPLITUDE * np.cos(2 * np.pi * (local_h - PEAK_LOCAL_HOUR) / 24.0))
        v = mean + xy @ self.grad
        # phases up to ~1e7 rad at GPST ~1.4e9 s: float64 still resolves them to ~1e-9 rad
        arg = xy @ self.kvec.T - self.omega * t[..., None] + self.phase  # (..., waves)
        v = v + self.amp * np.cos(arg).sum(axis=-1)
        v = v + p["tid_amplitude_tecu"] * np.cos(xy @ self.tid_k - self.tid_w * t + self.tid_phase)
        return np.maximum(v, 0.0)

    def pierce_point(self, lat, lon, az, el):
        """IPP latitude, longitude [rad] and the mapping function, for receivers at lat/lon [rad]."""
        r = EARTH_RADIUS_M / (EARTH_RADIUS_M + self.shell_m)
        psi = np.pi / 2 - el - np.arcsin(r * np.cos(el))  # Earth-central angle receiver-IPP
        lat_i = np.arcsin(np.sin(lat) * np.cos(psi) + np.cos(lat) * np.sin(psi) * np.cos(az))
        lon_i = lon + np.arcsin(np.clip(np.sin(psi) * np.sin(az) / np.cos(lat_i), -1, 1))
        mapping = 1.0 / np.sqrt(1.0 - (r * np.cos(el)) ** 2)
        return lat_i, lon_i, mapping

    def slant_tec_tecu(self, lat, lon, az, el, t_gpst) -> np.ndarray:
        lat_i, lon_i, m = self.pierce_point(lat, lon, az, el)
        return self.vtec_tecu(lat_i, lon_i, t_gpst) * m


def delay_m(stec_tecu, freq_hz):
    """First-order ionospheric group delay [m] (the phase advance has the same size)."""
    return IONO_K_M3_S2 * np.asarray(stec_tecu) / np.asarray(freq_hz) ** 2
