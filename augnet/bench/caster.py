"""`augnet bench caster`: our NTRIP caster under `augnet loadtest`, beside the published peers.

Runs the load generator against a freshly spawned caster at each client count (1 Hz epochs of
~1 KB, NTRIP 1/2 half and half) and prints our figures next to Millipede's as issue 4 reports them
for the same load on this kind of machine. For a side-by-side run in one go against a live
Millipede, use `augnet loadtest sweep --target HOST:PORT --caster-pid PID`.

Environment: AUGNET_BENCH_CASTER_CLIENTS (default "1000,5000,10000"),
AUGNET_BENCH_CASTER_EPOCHS (default 10).
"""

from __future__ import annotations

import json
import os

from ntrip_caster.loadtest import LoadSettings, run_load

# Millipede (C + libevent) p99 delivery latency in ms, every epoch to every client, as measured
# with a Python load generator on a 2-core machine (issue 4).
MILLIPEDE_P99_MS = {100: 4.0, 1000: 26.0, 5000: 132.0, 10000: 255.0}


def main() -> None:
    counts = [int(x) for x in os.environ.get("AUGNET_BENCH_CASTER_CLIENTS", "1000,5000,10000").split(",")]
    epochs = int(os.environ.get("AUGNET_BENCH_CASTER_EPOCHS", "10"))
    print("caster: clients  connected  complete  lost  p50_ms  p99_ms  max_ms  cpu_%  rss_MB  "
          "millipede_p99_ms  ratio")
    results = []
    for n in counts:
        r = run_load(LoadSettings(clients=n, epochs=epochs))
        results.append(r)
        lat = r["latency_ms"]
        peer = MILLIPEDE_P99_MS.get(n)
        ratio = f"{lat['p99'] / peer:.2f}" if peer and lat["p99"] is not None else "-"
        print(f"caster: {n:7d}  {r['connected']:9d}  {r['complete']:8d}  {r['lost_epochs']:4d}  "
              f"{lat['p50']:6.1f}  {lat['p99']:6.1f}  {lat['max']:6.1f}  "
              f"{r['caster_cpu_percent']:5.1f}  {r['caster_rss_mb']:6.1f}  "
              f"{peer if peer else '-':>16}  {ratio}")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
