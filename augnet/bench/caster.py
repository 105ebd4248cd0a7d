"""`augnet bench caster [--clients 1000,5000,10000] [--epochs N] [--peer HOST:PORT --peer-pid PID]`

Our NTRIP caster under `augnet loadtest` (1 Hz epochs of ~1 KB, NTRIP 1/2 half and half, one
mountpoint). With `--peer`, a running Millipede (or any caster with a LOAD mountpoint taking
`SOURCE loadtest /LOAD`) faces the same load in the same run, one after the other at each size,
and the p99 ratio is ours / peer's. Without it, ours is printed beside Millipede's figures as
issue 4 reports them for this kind of machine. Millipede is built outside the repository (fetch
CentipedeRTK/millipede-caster, `make` in caster/), never vendored.
"""

from __future__ import annotations

import argparse
import json

from ntrip_caster.loadtest import LoadSettings, run_load

# Millipede (C + libevent) p99 delivery latency in ms, every epoch to every client, measured with
# a Python load generator on a 2-core machine (issue 4).
MILLIPEDE_P99_MS = {100: 4.0, 1000: 26.0, 5000: 132.0, 10000: 255.0}


def _row(r: dict, peer_p99: float | None, peer_label: str) -> str:
    lat = r["latency_ms"]
    ratio = f"{lat['p99'] / peer_p99:.2f}" if peer_p99 and lat["p99"] is not None else "-"
    return (f"{r['label']:>10} {r['requested']:7d} {r['connected']:9d} {r['complete']:8d} "
            f"{r['lost_epochs']:5d} {lat['p50'] or 0:7.1f} {lat['p99'] or 0:7.1f} {lat['max'] or 0:7.1f} "
            f"{r['caster_cpu_percent'] or 0:6.1f} {r['caster_rss_mb'] or 0:7.1f}   "
            f"{peer_label} p99 {peer_p99 if peer_p99 else '-'} ms, ratio {ratio}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="augnet bench caster")
    ap.add_argument("--clients", default="1000,5000,10000")
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--peer", default="", help="host:port of a running peer caster")
    ap.add_argument("--peer-pid", type=int, default=0)
    ap.add_argument("--peer-label", default="millipede")
    args = ap.parse_args(argv or [])
    print(f"{'caster':>10} {'clients':>7} {'connected':>9} {'complete':>8} {'lost':>5} "
          f"{'p50_ms':>7} {'p99_ms':>7} {'max_ms':>7} {'cpu_%':>6} {'rss_MB':>7}")
    results = []
    for n in [int(x) for x in args.clients.split(",") if x.strip()]:
        ours = run_load(LoadSettings(clients=n, epochs=args.epochs, label="augnet"))
        results.append(ours)
        if args.peer:
            peer = run_load(LoadSettings(clients=n, epochs=args.epochs, target=args.peer,
                                         caster_pid=args.peer_pid, label=args.peer_label))
            results.append(peer)
            print(_row(ours, peer["latency_ms"]["p99"], f"{args.peer_label} (same run)"), flush=True)
            print(_row(peer, None, ""), flush=True)
        else:
            print(_row(ours, MILLIPEDE_P99_MS.get(n), "millipede (issue 4)"), flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    from augnet.blas_threads import limit_blas_threads

    limit_blas_threads()  # one BLAS thread, as under `augnet bench caster`
    main()
