"""RTK processing time per epoch: augnet's onboard RTK against RTKLIB's rnx2rtkp on the same files.

Data: ../shared/data/rinex/static-1m-2024 (real Septentrio base and rover, 1 Hz, 301 epochs), two
configurations bracketing the issue's "20 satellites, dual frequency": GPS + Galileo + QZSS (15
satellites, ~26 DD ambiguities) and GPS + Galileo + BeiDou + QZSS (33 satellites, ~60), L1+L2
(E5a, B3I), kinematic mode, 15 degree mask, continuous AR, ratio 3 -- the same settings for both
engines.  Figures:
  ours/epoch       CPU time of `RtkFilter.step` per epoch (files already read; time.process_time)
  ours end-to-end  CPU time of reading the RINEX files and processing them, per epoch
  startup          one-time CPU cost before the first epoch, not in the figures above: loading the
                   compiled (numba, cached on disk) LAMBDA and filter kernels, like the imports; a
                   rover process pays it once at switch-on
  RTKLIB/epoch     CPU time of the rnx2rtkp child process (reading + processing) per epoch
  ratio            ours end-to-end / RTKLIB (how many times slower we are), and ours/epoch / RTKLIB
Both fix every epoch of this file; the fix count is printed as a check that the work is the same.
The machine's other load moves every figure by tens of per cent: compare figures from one run.

Run: ``augnet bench rtk`` (once wired) or ``python -m augnet.bench.rtk [--json]``.  Needs
../shared/data and rnx2rtkp (RTKLIB 2.4.3, installed by `make test`); says so and exits 0 if absent.
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "rinex" / "static-1m-2024"
# (our system letters, RTKLIB's pos1-navsys bits: GPS 1, Galileo 8, QZSS 16, BeiDou 32)
CONFIGS = ((("G", "E", "J"), 1 + 8 + 16), (("G", "E", "C", "J"), 1 + 8 + 16 + 32))
ELEVATION_MASK_DEG = 15.0

RTKLIB_CONF = """\
pos1-posmode       =kinematic
pos1-frequency     =2
pos1-soltype       =forward
pos1-elmask        ={mask:g}
pos1-dynamics      =off
pos1-ionoopt       =brdc
pos1-tropopt       =saas
pos1-sateph        =brdc
pos1-navsys        ={navsys}
pos2-armode        =continuous
pos2-arthres       =3
out-solformat      =xyz
ant2-postype       =llh
"""


def _base_llh() -> tuple[float, float, float]:
    lat, lon, h = (float(v) for v in (DATA / "base_position.txt").read_text().split())
    return lat, lon, h


def run_ours(systems) -> dict:
    import math

    from augnet.gnss.geometry import geodetic_deg_to_ecef
    from augnet.onboard.inputs import load_nav, load_obs
    from augnet.onboard.observations import choose_signals, epochs
    from augnet.onboard.rtk import RtkFilter, RtkOptions, Status
    from augnet.onboard.spp import SppOptions

    s0 = time.process_time()
    warm_up()
    startup = time.process_time() - s0
    c0 = time.process_time()
    nav, alpha, beta = load_nav([DATA / "base.nav"])
    rov = load_obs(DATA / "rover.obs")
    bas = load_obs(DATA / "base.obs")
    opt = RtkOptions(systems=systems, elevation_mask_rad=math.radians(ELEVATION_MASK_DEG),
                     spp=SppOptions(klobuchar_alpha=alpha, klobuchar_beta=beta, systems=systems))
    r_ep = epochs(rov, opt.n_slots, systems, choose_signals(rov, opt.n_slots, systems))
    b_ep = epochs(bas, opt.n_slots, systems, choose_signals(bas, opt.n_slots, systems))
    base_by_time = {round(e.time, 2): e for e in b_ep}
    flt = RtkFilter(nav, geodetic_deg_to_ecef(*_base_llh()), opt)
    c1 = time.process_time()
    n_fix = 0
    n_sats = []
    for e in r_ep:
        s = flt.step(e, base_by_time.get(round(e.time, 2)))
        n_fix += s.status == Status.FIX
        n_sats.append(s.n_sats)
    c2 = time.process_time()
    n = len(r_ep)
    return {"epochs": n, "fixed": int(n_fix), "mean_sats": sum(n_sats) / max(n, 1),
            "per_epoch_s": (c2 - c1) / n, "end_to_end_per_epoch_s": (c2 - c0) / n, "startup_s": startup}


def warm_up() -> None:
    """Load the compiled kernels the filter uses (numba caches them on disk; the first call of each
    in a process still costs a fraction of a second), on a small made-up problem."""
    import numpy as np

    from augnet.onboard.atmosphere import klobuchar_l1_m
    from augnet.gnss.ambiguity import BIASED_FLOAT_FALSE_ALARM, FixPolicy, partial_fix

    rng = np.random.default_rng(0)
    A = rng.standard_normal((6, 6))
    Q = A @ A.T * 1e-3 + np.eye(6) * 1e-3
    partial_fix(rng.standard_normal(6) * 3.0, Q, FixPolicy(biased_float_false_alarm=BIASED_FLOAT_FALSE_ALARM))
    klobuchar_l1_m(1.4e9, 0.6, 2.0, np.zeros(3), np.ones(3), (0.0,) * 4, (7.2e4,) * 4)


def run_rtklib(exe: str, navsys: int) -> dict:
    lat, lon, h = _base_llh()
    with tempfile.TemporaryDirectory() as tmp:
        conf = Path(tmp) / "bench.conf"
        conf.write_text(RTKLIB_CONF.format(mask=ELEVATION_MASK_DEG, navsys=navsys)
                        + f"ant2-pos1={lat}\nant2-pos2={lon}\nant2-pos3={h}\n")
        out = Path(tmp) / "out.pos"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([exe, "-k", str(conf), "-o", str(out), str(DATA / "rover.obs"), str(DATA / "base.obs"),
                        str(DATA / "base.nav")], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        rows = [ln.split() for ln in out.read_text().splitlines() if ln.strip() and not ln.startswith("%")]
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    n = len(rows)
    return {"epochs": n, "fixed": sum(r[5] == "1" for r in rows), "per_epoch_s": cpu / max(n, 1)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"rtk benchmark skipped: {DATA} is absent")
        return 0
    exe = shutil.which("rnx2rtkp")
    results = []
    for systems, navsys in CONFIGS:
        ours = run_ours(systems)
        theirs = run_rtklib(exe, navsys) if exe else None
        r = {"systems": "".join(systems), "ours": ours, "rtklib": theirs}
        if theirs:
            r["ratio_end_to_end"] = ours["end_to_end_per_epoch_s"] / theirs["per_epoch_s"]
            r["ratio_filter_only"] = ours["per_epoch_s"] / theirs["per_epoch_s"]
        results.append(r)
    if args.json:
        print(json.dumps({"data": "static-1m-2024 L1+L2", "results": results}))
        return 0
    for r in results:
        ours, theirs = r["ours"], r["rtklib"]
        print(f"RTK per epoch, static-1m-2024 {r['systems']} L1+L2, {ours['epochs']} epochs, "
              f"{ours['mean_sats']:.1f} satellites on average")
        print(f"  augnet   filter {ours['per_epoch_s'] * 1e3:8.2f} ms   end-to-end {ours['end_to_end_per_epoch_s'] * 1e3:8.2f} ms"
              f"   fixed {ours['fixed']}/{ours['epochs']}   (startup {ours['startup_s']:.2f} s once)")
        if theirs:
            print(f"  RTKLIB 2.4.3 rnx2rtkp       end-to-end {theirs['per_epoch_s'] * 1e3:8.2f} ms"
                  f"   fixed {theirs['fixed']}/{theirs['epochs']}")
            print(f"  ratio (augnet / RTKLIB): end-to-end {r['ratio_end_to_end']:.1f}x, "
                  f"filter alone {r['ratio_filter_only']:.1f}x")
        else:
            print("  rnx2rtkp not installed: no RTKLIB figure (make test installs it)")
    return 0


if __name__ == "__main__":
    from augnet.blas_threads import limit_blas_threads

    limit_blas_threads()  # one BLAS thread, as under `augnet bench rtk`
    sys.exit(main())
