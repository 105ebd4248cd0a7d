"""Which stations a VRS point's interpolated corrections come from, on a railway: the nearest six (two more
along the line than the four around the point), so that the field's curvature along the line is known."""

from __future__ import annotations

import numpy as np

from augnet.centre import vrs
from augnet.centre.interpolation import MODEL_CODES, Model, kriging_weights
from augnet.centre.network import NetworkEpoch
from augnet.gnss.geometry import ecef_to_enu, geodetic_deg_to_ecef

# The demo line's layout, rounded (stations/scenarios/demo.yaml): the master (km 72), the stations at km 2, 142
# and 209 of the 210 km line, and the two off it.
STATIONS_LAT_LON_DEG = np.array([[39.47, 116.97], [39.85, 116.32], [39.10, 117.63], [38.82, 118.31],
                                 [39.80, 117.15], [38.70, 117.30]])
# Medium-scale travelling ionospheric disturbances: wavelengths 100-500 km (Hernandez-Pajares et al., J. Geophys.
# Res. 111, 2006); a quiet day's DD ionosphere of 1-4 ppm (network-rtk.md): a few cm over the line.
WAVELENGTH_M = (200e3, 500e3)
AMPLITUDE_M = 0.03
SATELLITES = 40


def _network(field) -> NetworkEpoch:
    lat, lon = STATIONS_LAT_LON_DEG.T
    xyz = geodetic_deg_to_ecef(lat, lon, np.zeros(len(lat)))
    en = ecef_to_enu(xyz - xyz[0], xyz[0])[:, :2]
    names = [f"S{i}" for i in range(len(en))]
    iono = field(en) - field(en[:1])  # residuals against the master (row 0)
    sats = np.array([f"G{k + 1:02d}" for k in range(iono.shape[1])])
    return NetworkEpoch(t_gpst=0.0, master=names[0], stations=names, station_en_m=en, station_xyz_m=xyz, refs={},
                        sats=sats, dd_iono_m=iono, dd_trop_m=np.zeros_like(iono), baselines={}, present=names)


def _waves(seed: int):
    """A smooth field per satellite: a plane and a wave of 200-500 km in a random direction."""
    rng = np.random.default_rng(seed)
    k = 2 * np.pi / rng.uniform(*WAVELENGTH_M, SATELLITES)
    ang = rng.uniform(0, 2 * np.pi, SATELLITES)
    kvec = np.column_stack([k * np.cos(ang), k * np.sin(ang)])
    phase = rng.uniform(0, 2 * np.pi, SATELLITES)
    grad = rng.normal(scale=2e-7, size=(2, SATELLITES))  # 0.2 ppm
    return lambda en: en @ grad + AMPLITUDE_M * np.cos(en @ kvec.T + phase)


def test_a_point_between_two_line_stations_gets_the_curvature_along_the_line():
    """Points along the line between the stations at km 72 and km 142 (rows 0 and 2), 7-63 km from them: the VRS
    plan's interpolated ionosphere against the field, beside the same kriging over the four nearest stations."""
    frac = np.linspace(0.1, 0.9, 9)
    lat_lon = STATIONS_LAT_LON_DEG[0] + frac[:, None] * (STATIONS_LAT_LON_DEG[2] - STATIONS_LAT_LON_DEG[0])
    pts = geodetic_deg_to_ecef(lat_lon[:, 0], lat_lon[:, 1], np.zeros(len(frac)))
    err, err_four = [], []
    for seed in range(5):
        field = _waves(seed)
        net = _network(field)
        en = net.station_en_m
        p_en = ecef_to_enu(pts - net.station_xyz_m[0], net.station_xyz_m[0])[:, :2]
        truth = field(p_en) - field(en[:1])
        plan = vrs.VrsPlan(net, None, 0.0, net.stations)  # no satellite geometry asked for: no ephemeris needed
        rows = plan.rows_for(pts)
        assert np.all(plan.model[rows] == MODEL_CODES[Model.KRIGING])
        err.append(plan.dI[rows] - truth)
        near = np.argsort(np.linalg.norm(en[None] - p_en[:, None], axis=2), axis=1)[:, :4]
        err_four.append([kriging_weights(en[n], p)[0] @ net.dd_iono_m[n] for n, p in zip(near, p_en)] - truth)
    rms, rms_four = (float(np.sqrt(np.mean(np.square(e)))) for e in (err, err_four))
    print(f"\nthe VRS plan {rms * 100:.2f} cm, kriging over the four nearest {rms_four * 100:.2f} cm RMS")
    assert rms < 0.5 * rms_four
