"""Simulated-world benchmark: epochs per second of the `demo` scenario, against real time.

`demo` is 6 reference stations + 2 trains, GPS + Galileo + BeiDou, dual frequency, 1 Hz.  Cases:
  simulate   truth + observables only (World.run): what a live station runner needs per epoch
  record     everything `augnet sim record` does: simulate, RINEX 3.04 obs and nav, RTCM 3 streams
             (MSM7 through the batch encoder), truth and atmosphere CSV files
The goal is >= 50x real time on one core.  Figures are CPU time of this process
(time.process_time), best of the repeats, so other jobs on a shared machine cost little.
Run: ``augnet bench sim`` or ``python -m augnet.bench.sim [--json]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time

GOAL_X_REAL_TIME = 50.0
DURATION_S = 300.0
REPEATS = 2


def _best(fn, repeats: int = REPEATS) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def measure(duration_s: float = DURATION_S, repeats: int = REPEATS) -> dict:
    from stations.record import record
    from stations.scenario import load_scenario
    from stations.world import World

    sc = load_scenario("demo").model_copy(update=dict(duration_s=duration_s))
    n = sc.n_epochs
    probe = World(sc)
    setup = _best(lambda: World(sc), repeats)

    def simulate():
        World(sc).run()

    def rec():
        with tempfile.TemporaryDirectory() as d:
            record(sc, d)

    t_sim = _best(simulate, repeats)
    t_rec = _best(rec, repeats)
    return {
        "scenario": sc.name,
        "receivers": len(probe.receivers),
        "satellites": len(probe.sats),
        "signals_per_system": probe.K,
        "epochs": n,
        "setup_s": setup,
        "simulate_epochs_per_s": n / t_sim,
        "simulate_x_real_time": sc.duration_s / t_sim,
        "record_epochs_per_s": n / t_rec,
        "record_x_real_time": sc.duration_s / t_rec,
        "goal_x_real_time": GOAL_X_REAL_TIME,
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--duration", type=float, default=DURATION_S)
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    r = measure(args.duration)
    if args.json:
        print(json.dumps(r, indent=2))
        return
    print(f"sim: scenario {r['scenario']}: {r['receivers']} receivers, {r['satellites']} satellites, "
          f"{r['signals_per_system']} signals/system, {r['epochs']} epochs at 1 Hz")
    print(f"  simulate  {r['simulate_epochs_per_s']:8.0f} epochs/s = {r['simulate_x_real_time']:6.0f}x real time "
          f"(goal >= {GOAL_X_REAL_TIME:.0f}x: {'met' if r['simulate_x_real_time'] >= GOAL_X_REAL_TIME else 'NOT met'})")
    print(f"  record    {r['record_epochs_per_s']:8.0f} epochs/s = {r['record_x_real_time']:6.0f}x real time "
          f"(RINEX + RTCM + truth files)")


if __name__ == "__main__":
    from augnet.blas_threads import limit_blas_threads

    limit_blas_threads()  # one BLAS thread, as under `augnet bench sim`
    main()
