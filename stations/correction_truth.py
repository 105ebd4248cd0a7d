"""The true interpolation error of the centre's DD corrections at a train, from the simulator's truth.

For evaluation only: the centre's estimator (`augnet.centre.correction_bound`) never reads this. The
correction the VRS carries for satellite s is the DD (point minus master, s minus its system's reference r)
of the non-dispersive residual beyond the troposphere model minus the f1 ionosphere (the phase advance):
`augnet.centre.correction_bound.correction_residuals`. The truth of that quantity at any receiver of the
world is built here from the slant troposphere, the line-of-sight orbit error and the slant TEC the
simulator drew, minus the estimator's own troposphere model (which the VRS adds separately at each point).
"""

from __future__ import annotations

import numpy as np

from augnet.gnss import troposphere
from augnet.gnss.geometry import ecef_to_geodetic
from stations.ionosphere import delay_m


def _undifferenced(world, block, e: int, i: int) -> np.ndarray:
    """(N,) correction-shaped truth of receiver i at epoch e: trop - model + orbit error - f1 ionosphere [m]."""
    lat, _, h = ecef_to_geodetic(block.rx_ecef[e, i])
    el = block.elevation_rad[e, i]
    model = troposphere.slant_delay_m(el, lat, h, world.doy)
    nondispersive = block.tropo_m[e, i] - model + block.orbit_error_range_m[e, i]
    return nondispersive - delay_m(block.stec_tecu[e, i], world.freq_hz[:, 0])


def true_dd_correction(world, block, e: int, point: int, master: int, sats, refs: dict) -> np.ndarray:
    """True DD correction [m] of receiver `point` against receiver `master` at epoch e, for `sats` (each minus
    its system's reference in `refs`); NaN where the satellite or its reference is unknown to the world."""
    index = {str(s): k for k, s in enumerate(world.sats)}
    u = _undifferenced(world, block, e, point) - _undifferenced(world, block, e, master)
    s_idx = np.array([index.get(str(s), -1) for s in sats])
    r_idx = np.array([index.get(str(refs.get(str(s)[0], "")), -1) for s in sats])
    ok = (s_idx >= 0) & (r_idx >= 0)
    out = np.full(len(s_idx), np.nan)
    out[ok] = u[s_idx[ok]] - u[r_idx[ok]]
    return out


def measure(scenario, duration_s: float | None = None) -> dict:
    """Run the centre's network engine and `CorrectionBound` on a scenario's reference stations; at every
    train and epoch compare the interpolated correction with `true_dd_correction` and the bound with the
    error. An epoch of a train counts bounded when every satellite with both a bound and an error is
    within its bound."""
    from augnet.centre import interpolation
    from augnet.centre.correction_bound import CorrectionBound, correction_residuals, ionosphere_level_ppm
    from augnet.centre.network import NetworkSolver
    from augnet.gnss.geometry import ecef_to_enu
    from stations.network_truth import station_epoch
    from stations.scenario import load_scenario
    from stations.world import World

    sc = load_scenario(scenario) if isinstance(scenario, str) else scenario
    if duration_s is not None:
        sc = sc.model_copy(update={"duration_s": float(duration_s)})
    world = World(sc)
    ids = world.receiver_ids
    kinds = {r.id: r.kind for r in world.receivers}
    stations = [r for r in ids if kinds[r] == "station" and not r.startswith("check")]
    trains = [r for r in ids if kinds[r] == "train"]
    net = NetworkSolver({r.id: r.ecef[0] for r in world.receivers if r.id in stations})
    cb = CorrectionBound()
    errs, bounds, epochs, bounded, worst = [], [], 0, 0, []
    for blk in world.epochs():
        for e in range(len(blk.t_gpst)):
            ne = net.update({r: station_epoch(world, blk, e, ids.index(r)) for r in stations}, world.nav)
            if not len(ne.stations) or len(ne.stations) < 3:
                continue
            v = correction_residuals(ne.dd_iono_m, ne.dd_trop_m)
            level = ionosphere_level_ppm(ne.station_en_m, ne.dd_iono_m, 0)
            origin = ne.station_xyz_m[0]
            t_en = ecef_to_enu(blk.rx_ecef[e, [ids.index(t) for t in trains]] - origin, origin)[:, :2]
            bound = cb.bound(ne.station_en_m, t_en, ne.sats, level)  # from the window before this epoch
            cb.update(ne.station_en_m, v, ne.sats, 0, level)
            pred, _ = interpolation.interpolate(ne.station_en_m, t_en, v, master=0)
            for k, t in enumerate(trains):
                truth = true_dd_correction(world, blk, e, ids.index(t), ids.index(ne.master), ne.sats, ne.refs)
                err = pred[k] - truth
                ok = np.isfinite(err) & np.isfinite(bound[k]) & ~np.isin(ne.sats, list(ne.refs.values()))
                if not ok.any():
                    continue
                epochs += 1
                bounded += int(np.all(np.abs(err[ok]) <= bound[k][ok]))
                worst.append((float(blk.t_gpst[e]), t, float(np.max(np.abs(err[ok]) / bound[k][ok]))))
                errs.append(np.abs(err[ok]))
                bounds.append(bound[k][ok])
    if not errs:
        raise ValueError(f"{sc.name}, {sc.duration_s:g} s: no train epoch had both a bound and a fixed network "
                         "correction to judge (the network fixes nothing yet?)")
    a_err, a_bound = np.concatenate(errs), np.concatenate(bounds)
    p999 = float(np.quantile(a_err, 0.999))
    return {"scenario": sc.name, "duration_s": sc.duration_s, "train_epochs": epochs, "bounded": bounded,
            "fraction_bounded": bounded / epochs, "samples": a_err.size,
            "samples_bounded": float(np.mean(a_err <= a_bound)), "error_p999_m": p999,
            "bound_median_m": float(np.median(a_bound)), "ratio_median": float(np.median(a_bound)) / p999,
            "ratio_max": float(a_bound.max()) / p999, "worst_error_over_bound": worst}


if __name__ == "__main__":  # python -m stations.correction_truth demo [duration_s]
    import sys

    print(measure(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else None))
