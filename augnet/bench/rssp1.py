"""RSSP-I: frames encoded + verified per second (goal: 100,000 on one core, issue 7).

Every path encodes each frame (check words + CRC16) and verifies it (size, CRC16, both check words
against the timestamps the receiver predicts), on the same payloads, side by side in one run:
- codec: the per-frame API every frame takes (rssp1.frames + rssp1.checkword), with the selected CRC
  backend (compiled with numba when it imports; rssp1.crc);
- codec, pure Python: the same with the standard-library reference CRCs (rssp1.crc.use_backend),
  the first named peer: what rssp1 costs without the optional compiled path;
- endpoint: the sans-IO state machine, one sender cycle + one receiver receive per frame;
- sealed: the endpoint path inside the AES-GCM open-bearer envelope;
- batch: rssp1.batch, BATCH frames per call (timestamps, encode, verify), for callers that hold
  many frames at once (a centre serving many links, a capture replay);
- C CRCs: the second named peer, the C CRCs of the standard library (zlib.crc32 twice +
  binascii.crc_hqx, sender and receiver, over the same byte counts; different polynomials, same
  work): the cost of the CRCs alone, done in C, and nothing else of a frame.
Trials are interleaved (every path once per round) so that other work on a shared machine lands on
all of them alike; the figures are medians over the rounds, in CPU time of this process (what one
core delivers when it is ours) and wall-clock time. The goal is judged on the per-frame codec.
"""

from __future__ import annotations

import binascii
import os
import statistics
import time
import zlib

from rssp1 import batch, checkword, crc
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.endpoint import DataReceived, Endpoint
from rssp1.envelope import Keyring, SealedEndpoint
from rssp1.frames import RSD_PREFIX, decode_frame, encode_rsd
from rssp1.timestamp import TIMESTAMP_CH1, TIMESTAMP_CH2

GOAL_FRAMES_PER_S = 100_000
GOAL_PATH = "codec"
SENDER = DeviceConfig(0x0101, (0x1A2B3C4D, 0x5E6F7081), dataver=(1, 2))
RECEIVER = DeviceConfig(0x0029, (0x311616DC, 0x07643EDE), dataver=(10, 11))
PAYLOAD_SIZES = (16, 96)  # a short command; a 10-section integrity report with correction age
FRAMES = 30_000  # per path and trial (the sealed path runs a quarter of it)
TRIALS = 5  # interleaved rounds; medians reported
BATCH = 1_000  # frames per batch call
PATHS = ("codec", "codec (pure Python)", "endpoint", "sealed", "batch", "C CRCs (peer)")
LABELS = {
    "codec": "per-frame codec ({backend} CRCs)",
    "codec (pure Python)": "peer: per-frame codec, pure Python",
    "endpoint": "endpoint (sans-IO state machine)",
    "sealed": "sealed endpoint (AES-256-GCM)",
    "batch": "batch codec ({batch_backend}, {batch_n:,} frames/call)",
    "C CRCs (peer)": "peer: stdlib C CRCs only (zlib, binascii)",
}


def _measure(fn, n: int) -> tuple[float, float]:
    """(frames per wall-clock second, frames per CPU second of this process) for one run."""
    w0, c0 = time.perf_counter(), time.process_time()
    fn(n)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return n / max(wall, 1e-9), n / max(cpu, 1e-9)


def codec_run(size: int, backend: str | None = None):
    data = bytes(range(size))
    sid, seed = SENDER.sid, SENDER.timestamp_seed

    def run(n: int) -> None:
        previous = crc.use_backend(backend) if backend else None
        try:
            t1, t2 = seed
            rt1, rt2 = seed
            step1, step2 = TIMESTAMP_CH1.step, TIMESTAMP_CH2.step
            for tc in range(n):
                frame = encode_rsd(SENDER.address, RECEIVER.address, tc, checkword.svc(data, sid, (t1, t2)), data)
                rsd = decode_frame(frame)  # CRC16 + layout
                if checkword.timestamp_from_svc(rsd.svc, rsd.data, sid) != (rt1, rt2):
                    raise AssertionError("check words did not verify")
                t1, t2 = step1(t1), step2(t2)
                rt1, rt2 = step1(rt1), step2(rt2)
        finally:
            if previous:
                crc.use_backend(previous)

    return run


def endpoint_run(size: int, sealed: bool = False):
    """Both ends send `size` bytes every cycle (as a live link does) and verify what they receive;
    a frame counts once it has been built by one end and accepted by the other."""
    data = bytes(range(size))
    timing = LinkTiming()

    def run(n: int) -> None:
        tx, rx = Endpoint(SENDER, RECEIVER, timing), Endpoint(RECEIVER, SENDER, timing)
        if sealed:
            keys = Keyring({1: bytes(32)})
            tx, rx = SealedEndpoint(tx, keys), SealedEndpoint(rx, keys)
        for _ in range(4):  # synchronise both directions
            for f in tx.cycle(data)[0]:
                rx.receive(f)
            for f in rx.cycle(data)[0]:
                tx.receive(f)
        if not (tx.is_up and rx.is_up):
            raise AssertionError("link did not come up")
        got = 0
        for _ in range(n // 2):
            frames_tx, _ = tx.cycle(data)
            frames_rx, _ = rx.cycle(data)
            for f in frames_tx:
                for e in rx.receive(f):
                    got += isinstance(e, DataReceived)
            for f in frames_rx:
                for e in tx.receive(f):
                    got += isinstance(e, DataReceived)
        if got != n // 2 * 2:
            raise AssertionError(f"{got} of {n} frames verified")

    return run


def batch_run(size: int):
    """The codec path BATCH frames at a time: the sender's timestamps for its next TCs, the frames,
    the receiver's own predicted timestamps, verification of every frame against them."""
    datas = [bytes(range(size))] * BATCH
    sid, seed = SENDER.sid, SENDER.timestamp_seed

    def run(n: int) -> None:
        t, rt = seed, seed
        for tc0 in range(0, n, BATCH):
            k = min(BATCH, n - tc0)
            ts = batch.timestamp_run(t, k + 1)
            frames = batch.encode_rsds(datas[:k], source=SENDER.address, destination=RECEIVER.address,
                                       tc=range(tc0, tc0 + k), sid=sid, t=ts[:k])
            predicted = batch.timestamp_run(rt, k + 1)
            if not batch.verify_rsds(frames, sid=sid, t=predicted[:k]).ok.all():
                raise AssertionError("check words did not verify")
            t, rt = tuple(ts[k].tolist()), tuple(predicted[k].tolist())

    return run


def stdlib_c_crc_run(size: int):
    frame = bytes(RSD_PREFIX.size + size)
    data = frame[RSD_PREFIX.size :]

    def run(n: int) -> None:
        for _ in range(n):  # sender and receiver each: CRC16 over the frame, two CRC32s over the data
            for _side in range(2):
                binascii.crc_hqx(frame, 0)
                zlib.crc32(data)
                zlib.crc32(data, 1)

    return run


def _runs(size: int) -> dict[str, tuple]:
    return {
        "codec": (codec_run(size), FRAMES),
        "codec (pure Python)": (codec_run(size, "python"), FRAMES),
        "endpoint": (endpoint_run(size), FRAMES),
        "sealed": (endpoint_run(size, True), FRAMES // 4),
        "batch": (batch_run(size), FRAMES),
        "C CRCs (peer)": (stdlib_c_crc_run(size), FRAMES),
    }


def measure() -> dict:
    """Every path for every payload size, TRIALS interleaved rounds, medians:
    {"results": {size: {path: {"wall": fps, "cpu": fps}}}, "goal_holds": bool, ...}."""
    runs = {str(size): _runs(size) for size in PAYLOAD_SIZES}
    for size_runs in runs.values():  # warm-up: first calls, caches, compiled kernels loaded
        for fn, n in size_runs.values():
            fn(min(n, 2 * BATCH))
    samples: dict[str, dict[str, list[tuple[float, float]]]] = {s: {p: [] for p in PATHS} for s in runs}
    load_before = os.getloadavg()[0]
    for _ in range(TRIALS):
        for size, size_runs in runs.items():
            for path, (fn, n) in size_runs.items():
                samples[size][path].append(_measure(fn, n))
    load_after = os.getloadavg()[0]
    results = {
        size: {
            path: {"wall": statistics.median(w for w, _ in s), "cpu": statistics.median(c for _, c in s)}
            for path, s in rows.items()
        }
        for size, rows in samples.items()
    }
    return {
        "goal_frames_per_s": GOAL_FRAMES_PER_S,
        "goal_path": GOAL_PATH,
        "goal_holds": all(rows[GOAL_PATH]["cpu"] >= GOAL_FRAMES_PER_S for rows in results.values()),
        "trials": TRIALS,
        "crc_backend": crc.backend,
        "batch_backend": batch.BACKEND,
        "batch_frames_per_call": BATCH,
        "load_average_1min": [round(load_before, 2), round(load_after, 2)],
        "cores": os.cpu_count(),
        "results": results,
    }


def print_table(result: dict) -> None:
    goal = result["goal_frames_per_s"]
    sizes = list(result["results"])
    print(f"RSSP-I frames encoded + verified per second, one core; goal {goal:,}; median of "
          f"{result['trials']} interleaved trials; load average {result['load_average_1min'][0]:.1f} -> "
          f"{result['load_average_1min'][1]:.1f} on {result['cores']} cores")
    print("figures: CPU time of this process (wall clock in brackets: they differ when other work shares the core)")
    print(f"{'path':<44}" + "".join(f"{s + ' data bytes':>26}" for s in sizes))
    for path in PATHS:
        label = LABELS[path].format(backend=result["crc_backend"], batch_backend=result["batch_backend"],
                                   batch_n=result["batch_frames_per_call"])
        cells = []
        for s in sizes:
            r = result["results"][s][path]
            cells.append(f"{r['cpu']:>12,.0f} ({r['wall']:>9,.0f})")
        print(f"{label:<44}" + "".join(f"{c:>26}" for c in cells))
    for s in sizes:
        rows = result["results"][s]
        cpu = {p: rows[p]["cpu"] for p in PATHS}
        print(f"{s:>3} data bytes: codec {cpu['codec'] / goal:.2f}x goal, "
              f"{cpu['codec'] / cpu['codec (pure Python)']:.2f}x pure-Python codec, "
              f"{cpu['codec'] / cpu['C CRCs (peer)']:.3f}x C CRCs alone; "
              f"endpoint {cpu['endpoint'] / goal:.2f}x goal; batch {cpu['batch'] / goal:.1f}x goal")
    verdict = "holds" if result["goal_holds"] else "does NOT hold"
    print(f"goal >= {goal:,} frames/s on one core for the per-frame codec (CPU time, median) at every size: "
          f"{verdict} (CRC backend: {result['crc_backend']})")


def main(argv: list[str] | None = None) -> None:
    """Print the table (or, with --json, the figures as JSON)."""
    import json
    import sys

    args = sys.argv[1:] if argv is None else argv
    result = measure()
    if "--json" in args:
        print(json.dumps(result))
    else:
        print_table(result)


if __name__ == "__main__":
    from augnet.blas_threads import limit_blas_threads

    limit_blas_threads()  # one BLAS thread, as under `augnet bench rssp1`
    main()
