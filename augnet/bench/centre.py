"""Benchmark of the control centre: network solution per epoch (6 and 60 stations) and VRS synthesis +
RTCM encoding for 1, 100 and 2,000 trains per epoch, on simulated data; goal <= 100 ms per epoch for
2,000 trains on one core (issue 5). CPU time of this process (the machine may be shared)."""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from augnet.centre.network import NetworkSolver
from augnet.centre.observations import StationEpoch
from augnet.centre.vrs import synthesize
from augnet.centre.vrs_stream import VrsStreamEncoder
from augnet.gnss.geometry import geodetic_deg_to_ecef

GOAL_MS_2000_TRAINS = 100.0


def _world(n_stations: int, epochs: int):
    from stations.scenario import Station, load_scenario
    from stations.world import World

    base = load_scenario("network-70km")
    # stations every 30 km along a gently curving line (a national line's reference network)
    sts = []
    for i in range(n_stations):
        lat = 39.0 + 0.27 * i * np.cos(0.3)
        lon = 116.0 + 0.35 * i * np.sin(0.3) + 0.05 * np.sin(i)
        sts.append(Station(id=f"S{i:02d}", station_id=10 + i, lat_deg=float(lat), lon_deg=float(lon),
                           h_m=50.0))
    sc = base.model_copy(update={"stations": sts, "duration_s": float(epochs), "name": f"bench-{n_stations}"})
    return World(sc)


def _epochs(world):
    sats = np.array(world.sats)
    for blk in world.epochs():
        for e in range(len(blk.t_gpst)):
            out = {}
            for r, rx in enumerate(world.receivers):
                obs = blk.observed[e, r].any(axis=1)
                out[rx.id] = StationEpoch(rx.id, float(blk.t_gpst[e]), sats[obs], blk.pseudorange_m[e, r][obs][:, :2],
                                          blk.phase_cyc[e, r][obs][:, :2], blk.lli[e, r][obs][:, :2],
                                          blk.cnr_dbhz[e, r][obs][:, :2], world.freq_hz[obs][:, :2],
                                          world.codes[obs][:, :2])
            yield out


def network_ms_per_epoch(n_stations: int, epochs: int) -> tuple[float, int]:
    world = _world(n_stations, epochs)
    net = NetworkSolver({r.id: r.ecef[0] for r in world.receivers})
    times = []
    for eps in _epochs(world):
        t0 = time.process_time()
        net.update(eps, world.nav)
        times.append(time.process_time() - t0)
    return 1e3 * float(np.median(times[len(times) // 3:])), len(net.edges)


def vrs_sessions(trains: int, prefix: str = "T") -> tuple[list[str], np.ndarray, VrsStreamEncoder]:
    """`trains` VRS sessions at random points along the first six stations' line (seeded): their client
    ids, points (ECEF) and an encoder holding them."""
    rng = np.random.default_rng(1)
    lat = rng.uniform(39.0, 39.0 + 0.27 * 5 * np.cos(0.3), trains)
    lon = 116.0 + (lat - 39.0) / np.cos(0.3) * 0.35 * np.sin(0.3) / 0.27 + rng.normal(0, 0.01, trains)
    points = geodetic_deg_to_ecef(lat, lon, np.full(trains, 50.0))
    enc = VrsStreamEncoder()
    ids = [f"{prefix}{i}" for i in range(trains)]
    for i, cid in enumerate(ids):
        enc.add(cid, 2000 + i % 2000, points[i])
    return ids, points, enc


def vrs_ms_per_epoch(trains: int, epochs: int = 8) -> tuple[float, float, int]:
    world = _world(6, epochs)
    stations = {r.id: r.ecef[0] for r in world.receivers}
    net = NetworkSolver(stations)
    ids, points, enc = vrs_sessions(trains)
    synth, encode, nbytes = [], [], 0
    for eps in _epochs(world):
        ne = net.update(eps, world.nav)
        t0 = time.process_time()
        vrs = synthesize(ne, eps, points, world.nav)
        t1 = time.process_time()
        out = enc.encode(ids, vrs, world.nav)
        t2 = time.process_time()
        synth.append(t1 - t0)
        encode.append(t2 - t1)
        nbytes = sum(len(v) for v in out.values())
    k = len(synth) // 2
    return 1e3 * float(np.median(synth[k:])), 1e3 * float(np.median(encode[k:])), nbytes


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="augnet bench centre", description=__doc__)
    ap.add_argument("--epochs", type=int, default=30, help="epochs per network run")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--quick", action="store_true", help="6 stations and 100 trains only")
    args = ap.parse_args(argv)  # None: the command line (python -m augnet.bench.centre --quick)
    results: dict[str, object] = {}
    sizes = (6,) if args.quick else (6, 60)
    for n in sizes:
        ms, edges = network_ms_per_epoch(n, args.epochs)
        results[f"network_{n}_stations_ms_per_epoch"] = round(ms, 1)
        results[f"network_{n}_stations_baselines"] = edges
    for trains in ((1, 100) if args.quick else (1, 100, 2000)):
        s, e, nbytes = vrs_ms_per_epoch(trains)
        results[f"vrs_{trains}_trains_synthesis_ms"] = round(s, 1)
        results[f"vrs_{trains}_trains_encoding_ms"] = round(e, 1)
        results[f"vrs_{trains}_trains_bytes_per_epoch"] = nbytes
    if "vrs_2000_trains_synthesis_ms" in results:
        total = results["vrs_2000_trains_synthesis_ms"] + results["vrs_2000_trains_encoding_ms"]
        results["vrs_2000_trains_total_ms"] = round(total, 1)
        results["vrs_2000_trains_vs_goal"] = round(total / GOAL_MS_2000_TRAINS, 2)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print("augnet centre, CPU time per epoch (median after warm-up), one core")
    for k, v in results.items():
        print(f"  {k:42s} {v}")
    if "vrs_2000_trains_total_ms" in results:
        print(f"  2,000 trains: {results['vrs_2000_trains_total_ms']} ms per epoch against the "
              f"{GOAL_MS_2000_TRAINS:.0f} ms goal ({results['vrs_2000_trains_vs_goal']}x)")


if __name__ == "__main__":
    from augnet.blas_threads import limit_blas_threads

    limit_blas_threads()  # one BLAS thread, as under `augnet bench centre`
    main()
