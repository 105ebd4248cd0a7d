"""`augnet loadtest trains`: thousands of simulated trains on the VRS mountpoint of a running `augnet up`.

Each train is an NTRIP client (half NTRIP 1, half NTRIP 2, Basic authentication with the run's train
credentials from its state file) that uploads a GGA sentence moving along the scenario's line at its own
speed, and receives its own VRS stream. Per train and epoch the client notes when the first MSM of the
epoch arrived: the correction age is that arrival time (host clock when the bytes were read, as GPST)
minus the epoch's GPS time (the MSM epoch time, DF004). Every train must receive every epoch of the
measured window, each from its own virtual station (the RTCM station id of its 1005/1006 is unique to it).

Clients live in several worker processes (one asyncio loop each); the CPU of `augnet up` with its child
processes (the centre runs in one: % of one core, user + system, over the window) and their peak RSS
summed are read with psutil.
"""

from __future__ import annotations

import asyncio
import json
import math
import multiprocessing as mp
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np
import typer

from augnet.gnss import time as gtime
from ntrip_caster.gga import format_gga
from ntrip_caster.loadtest import ClientSpec, LoadClient, _percentiles

CONNECT_CONCURRENCY = 128
GGA_INTERVAL_S = 5.0  # trains report their position every few seconds (ntrip.md: VRS casters expect 1-10 s)
SPEEDS_KMH = (120.0, 160.0, 200.0, 250.0, 300.0, 350.0)
MSM_GPS = range(1071, 1078)
ARP_TYPES = (1005, 1006)
DRAIN_S = 3.0


@dataclass
class TrainSpec:
    spec: ClientSpec
    start_m: float  # chainage at t = 0
    speed_m_s: float
    direction: int
    gga_phase_s: float = 0.0  # when in each GGA interval this train reports


class TrainClient(LoadClient):
    """A LoadClient whose frames are a real VRS stream: MSM epochs and the station id are what count."""

    def __init__(self, spec: ClientSpec, connected: asyncio.Future, line: "LinePoints", train: TrainSpec):
        super().__init__(spec, None, connected)  # type: ignore[arg-type]
        self.line = line
        self.train = train
        self.ages_ms: dict[int, float] = {}  # GPS epoch time [ms of week] -> correction age [ms]
        self.station_ids: set[int] = set()
        self.t0 = time.monotonic()
        # `now` of a frame is the monotonic clock when its bytes arrived (data_received): as GPST
        self.gps_minus_monotonic_s = gtime.now_gpst() - time.monotonic()

    def _frame(self, frame: bytes, now: int) -> None:
        if len(frame) < 12:
            self.bad += 1
            return
        mtype = (frame[3] << 4) | (frame[4] >> 4)
        if mtype in MSM_GPS:
            # payload bits 0-11 type, 12-23 station id, 24-53 GPS epoch time [ms] (DF004)
            tow_ms = ((frame[6] << 22) | (frame[7] << 14) | (frame[8] << 6) | (frame[9] >> 2)) & 0x3FFFFFFF
            if tow_ms not in self.ages_ms:
                now_gpst = now * 1e-9 + self.gps_minus_monotonic_s
                _, tow_now = gtime.week_tow(now_gpst)
                age = (float(tow_now) * 1000.0 - tow_ms) % (7 * 86400 * 1000)
                self.ages_ms[tow_ms] = age
        elif mtype in ARP_TYPES:
            self.station_ids.add(((frame[4] & 0x0F) << 8) | frame[5])

    def gga(self) -> bytes:
        t = time.monotonic() - self.t0
        s = self.train.start_m + self.train.direction * self.train.speed_m_s * t
        lat, lon = self.line.at(s)
        return format_gga(lat, lon, 30.0)

    async def report_positions(self) -> None:
        # each train at its own moment of the interval, as independent trains would: all reporting in the
        # same millisecond made the caster move hundreds of VRS points at once and stalled this process's
        # loop (formatting a thousand GGA) while it stamped arrivals
        await asyncio.sleep(self.train.gga_phase_s)
        while not self.closed:
            await asyncio.sleep(GGA_INTERVAL_S)
            if self.transport is not None and not self.closed and self.head_done:
                self.transport.write(self.gga())


class LinePoints:
    """The scenario's centre line, sampled, for GGA positions by chainage (bouncing at the ends)."""

    def __init__(self, polyline_llh: list[list[float]], length_m: float):
        self.ll = np.asarray(polyline_llh, float)[:, :2]
        self.s = np.linspace(0.0, length_m, len(self.ll))
        self.length_m = length_m

    def at(self, s_m: float) -> tuple[float, float]:
        period = 2 * self.length_m
        s = s_m % period
        s = period - s if s > self.length_m else s
        return float(np.interp(s, self.s, self.ll[:, 0])), float(np.interp(s, self.s, self.ll[:, 1]))


def line_of(scenario: str) -> LinePoints:
    from stations.scenario import load_scenario
    from stations.track import TrackLine

    sc = load_scenario(scenario)
    if sc.line is None:
        raise typer.BadParameter(f"scenario {scenario!r} has no line for the trains to run on")
    tl = TrackLine(sc.line)
    enu = np.column_stack([tl.centre_xy, tl.rail_h])
    return LinePoints(tl.plane_to_geodetic(enu)[:, :2].tolist(), tl.length_m)


def train_specs(host: str, port: int, mount: str, n: int, user: str, password: str, line: LinePoints,
                offset: int = 0) -> list[TrainSpec]:
    out = []
    for i in range(n):
        k = offset + i
        start = (k * 0.6180339887 % 1.0) * line.length_m  # golden-ratio spacing: evenly spread
        train = TrainSpec(ClientSpec(host, port, mount, 2 if k % 2 else 1, user, password), start,
                          SPEEDS_KMH[k % len(SPEEDS_KMH)] / 3.6, 1 if k % 4 < 2 else -1,
                          (k * 0.7548776662 % 1.0) * GGA_INTERVAL_S)  # spread evenly (another irrational)
        lat, lon = line.at(start)
        train.spec.gga = format_gga(lat, lon, 30.0)
        out.append(train)
    return out


def _worker(trains: list[TrainSpec], line: LinePoints, ctl: Any) -> None:
    async def main() -> None:
        loop = asyncio.get_running_loop()
        sem = asyncio.Semaphore(CONNECT_CONCURRENCY)
        clients: list[TrainClient] = []

        async def one(tr: TrainSpec) -> None:
            fut = loop.create_future()
            c = TrainClient(tr.spec, fut, line, tr)
            clients.append(c)
            async with sem:
                try:
                    await asyncio.wait_for(loop.create_connection(lambda: c, tr.spec.host, tr.spec.port), 30)
                    await asyncio.wait_for(fut, 30)
                except (OSError, asyncio.TimeoutError) as exc:
                    c.status = c.status or f"connect failed: {type(exc).__name__}"
                    if not fut.done():
                        fut.set_result(False)

        await asyncio.gather(*(one(t) for t in trains))
        movers = [asyncio.ensure_future(c.report_positions()) for c in clients]
        ok = sum(1 for c in clients if c.head_done and not c.closed)
        statuses: dict[str, int] = {}
        for c in clients:
            statuses[c.status] = statuses.get(c.status, 0) + 1
        ctl.send(("ready", ok, statuses))
        await loop.run_in_executor(None, ctl.recv)  # "stop"
        ctl.send(("result", [(c.ages_ms, sorted(c.station_ids), c.bad) for c in clients]))
        for m in movers:
            m.cancel()
        for c in clients:
            if c.transport is not None:
                c.transport.abort()

    try:
        import uvloop
        uvloop.run(main())
    except ImportError:
        asyncio.run(main())


def _tree(proc) -> list:
    if proc is None:
        return []
    try:
        return [proc] + proc.children(recursive=True)
    except Exception:  # noqa: BLE001 - gone
        return []


def _tree_cpu_s(proc) -> float:
    """User + system CPU of a process and its live children [s] (a child that exits in the window
    takes its share with it: the centre's process lives as long as `augnet up`)."""
    total = 0.0
    for p in _tree(proc):
        try:
            total += sum(p.cpu_times()[:2])
        except Exception:  # noqa: BLE001 - exited meanwhile
            pass
    return total


def _tree_rss(proc) -> int:
    total = 0
    for p in _tree(proc):
        try:
            total += p.memory_info().rss
        except Exception:  # noqa: BLE001
            pass
    return total


def run_trains(state: dict, n: int, epochs: int, processes: int, scenario: str, warmup_s: float) -> dict:
    import psutil

    caster = state["caster"]
    line = line_of(scenario)
    up = psutil.Process(int(state["pid"])) if state.get("pid") else None
    ctx = mp.get_context("spawn")
    pipes, procs = [], []
    per = [n // processes + (1 if i < n % processes else 0) for i in range(processes)]
    offset = 0
    t_connect = time.monotonic()
    for k in per:
        if k == 0:
            continue
        specs = train_specs(caster["host"], int(caster["port"]), caster.get("vrs_mount", "VRS"), k,
                            caster["user"], caster["password"], line, offset)
        offset += k
        parent, child = ctx.Pipe()
        p = ctx.Process(target=_worker, args=(specs, line, child), daemon=True)
        p.start()
        pipes.append(parent)
        procs.append(p)
    connected, statuses = 0, {}
    try:
        for pipe in pipes:
            if not pipe.poll(600):
                raise RuntimeError("a load worker did not connect its trains within 600 s")
            _, ok, st = pipe.recv()
            connected += ok
            for key, v in st.items():
                statuses[key] = statuses.get(key, 0) + v
        connect_s = time.monotonic() - t_connect
        time.sleep(warmup_s)  # sessions open, the VRS of every train settles into its epoch rhythm
        cpu0 = _tree_cpu_s(up)
        w0 = time.monotonic()
        g0 = gtime.now_gpst()
        rss = 0
        while time.monotonic() - w0 < epochs:
            time.sleep(1.0)
            rss = max(rss, _tree_rss(up))
        cpu1 = _tree_cpu_s(up)
        window_s = time.monotonic() - w0
        g1 = g0 + window_s
        time.sleep(DRAIN_S)
        for pipe in pipes:
            pipe.send("stop")
        results = []
        for pipe in pipes:
            if not pipe.poll(120):
                raise RuntimeError("a load worker did not return its results")
            results.extend(pipe.recv()[1])
    finally:
        for p in procs:
            p.join(timeout=10)
            if p.is_alive():
                p.kill()
    # the measured epochs: whole GPS seconds inside the window
    _, tow0 = gtime.week_tow(math.ceil(g0))
    want = [int(round((float(tow0) + k) * 1000)) % (7 * 86400 * 1000) for k in range(int(g1 - math.ceil(g0)))]
    ages, complete, lost, bad = [], 0, 0, 0
    ids: dict[int, int] = {}
    for got, sids, nbad in results:
        bad += nbad
        miss = sum(1 for e in want if e not in got)
        lost += miss
        complete += miss == 0
        ages.extend(got[e] for e in want if e in got)
        for sid in sids:
            ids[sid] = ids.get(sid, 0) + 1
    shared_ids = sum(1 for c in ids.values() if c > 1)
    return {
        "trains": n, "connected": connected, "complete": complete, "epochs": len(want), "lost_epochs": lost,
        "bad_frames": bad, "correction_age_ms": _percentiles([int(a * 1e6) for a in ages]),
        "samples": len(ages), "distinct_vrs_station_ids": len(ids), "station_ids_shared": shared_ids,
        "up_cpu_percent": round(100.0 * (cpu1 - cpu0) / window_s, 1) if up else None,
        "up_rss_mb": round(rss / 2**20, 1) if up else None, "connect_s": round(connect_s, 1),
        "statuses": statuses, "cpus": os.cpu_count(), "goal_p99_ms": 200.0,
    }


def trains(
    state: Path = typer.Option(Path("augnet-up.json"), help="State file of the running `augnet up`."),
    count: int = typer.Option(2000, "--trains", help="Simulated trains (NTRIP clients with moving GGA)."),
    epochs: int = typer.Option(30, help="Measured epochs (seconds)."),
    processes: int = typer.Option(2, help="Client worker processes."),
    scenario: str = typer.Option("", help="Line the trains run on (default: the run's scenario)."),
    warmup: float = typer.Option(15.0, help="Seconds between all trains connected and the measurement."),
    output: Optional[Path] = typer.Option(None, "--json", help="Also write the JSON here."),
) -> None:
    """Load a running `augnet up` with many trains on its VRS mountpoint; prints JSON."""
    try:
        st = json.loads(state.read_text())
        st["caster"]["port"], st["caster"]["user"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        typer.echo(f"error: --state {state}: not the state file of a running augnet up ({exc})", err=True)
        raise typer.Exit(2)
    if count < 1 or epochs < 1 or processes < 1:
        typer.echo("error: need --trains >= 1, --epochs >= 1, --processes >= 1", err=True)
        raise typer.Exit(2)
    result = run_trains(st, count, epochs, processes, scenario or st.get("scenario", "demo"), warmup)
    text = json.dumps(result, indent=2)
    typer.echo(text)
    if output is not None:
        output.write_text(text)
