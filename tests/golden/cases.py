"""The golden cases: each runs a fixed input through the code and returns its outputs epoch by epoch.

A case returns {"epochs": [record, ...], "meta": {...}}; a record is a flat dict of JSON values (the epoch's
time under "t"). Bytes are pinned as sha256 (first 16 hex digits) and length; integers and strings exactly;
metre values as integers of 0.1 mm (`tenth_mm`), compared within `compare.TOLERANCE_TENTH_MM`.
No input depends on a clock: each is a seeded simulation or a recorded file, fed epoch by epoch.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from tests.golden import probes

# Simulated centre run: seconds of network-70km from a cold start (first fixes come within the first
# minute, test_network_sim.py), and VRS sessions at these offsets from the check receiver [m, ECEF].
CENTRE_SIM_S = 150
VRS_OFFSETS_M = {"at-check1": (15.0, -20.0, 5.0), "east-9km": (5000.0, 7000.0, -3000.0),
                 "west-23km": (-20000.0, 9000.0, -8000.0)}
ONBOARD_VRS_SESSION = "at-check1"
# epoch -> session changes on the way: (what, session, new offset from check1 [m, ECEF])
SESSION_EVENTS = {60: (("move", "east-9km", (7000.0, 4000.0, -2000.0)),),
                  90: (("open", "north-15km", (-3000.0, -6000.0, 13000.0)),),
                  120: (("close", "west-23km", None),)}
# epochs of it also run through the centre process (spawn, protocol, the caster side's sinks)
CENTRE_PROCESS_EPOCHS = 20
# RTCM encoder case: the station streams of the first seconds of the same run
RTCM_EPOCHS = 30
# seeded float ambiguity problems for the integer search and partial fixing
AMBIGUITY_PROBLEMS = 200
# Real networks through `augnet vrs`: catnet's first two hours at 30 s, nl-network's 19 epochs
CATNET_EPOCHS = 240
CATNET_STATIONS = ("CREU", "EBRE", "GARR")
CATNET_VRS_AT = "41.39,2.11,100"  # Barcelona, by UPC1 (inside the network's reach, 20 km from GARR)
NL_VRS_AT = "52.0,4.5,50"  # as test_postprocess.py
# GARR -> UPC1 (20 km): UPC1 at 1 Hz against GARR's 30 s epochs, so corrections up to 30 s old are used
UPC1_EPOCHS = 300
UPC1_MAX_AGE_S = 31.0


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def tenth_mm(x) -> int | None:
    """A metre value as an integer of 0.1 mm; None for NaN."""
    v = float(x)
    return None if not np.isfinite(v) else int(round(v * 1e4))


def tenth_mm_rows(a) -> list:
    return [[tenth_mm(v) for v in row] for row in np.atleast_2d(np.asarray(a, float))]


def _bytes_item(data: bytes) -> list:
    return [digest(data), len(data)]


# --- shared simulated run ----------------------------------------------------------------------------


_SIM_CACHE: dict = {}


def _sim(duration_s: int = CENTRE_SIM_S):
    """network-70km's station streams (seeded): computed once per process."""
    if duration_s not in _SIM_CACHE:
        _SIM_CACHE[duration_s] = probes.simulated_streams(duration_s)
    return _SIM_CACHE[duration_s]


def _centre_run():
    """The centre engine fed the simulated stations epoch by epoch with VRS sessions open (one moved, one
    opened and one closed on the way, SESSION_EVENTS): per epoch, each session's VRS bytes (MSM7, as served,
    and MSM4 from a second encoder given the same VRS epochs), the bus messages and the network's state.
    Computed once per process (three cases read it)."""
    if "centre" in _SIM_CACHE:
        return _SIM_CACHE["centre"]
    world, streams, stations = _sim()
    engine = probes.centre_engine(stations, world.t0)
    msm4 = probes.vrs_encoder(4)
    check = world.receivers[world.receiver_ids.index("check1")].ecef[0]
    got: dict[str, bytearray] = {}

    def open_session(name: str, offset_m) -> None:
        got[name] = bytearray()
        lat, lon, h = probes.geodetic_deg(check + np.array(offset_m))
        engine.open_session(name, lat, lon, h, got[name].extend)
        msm4.add(name, engine.sessions[name].station_id, engine.sessions[name].point_ecef)

    for name, off in VRS_OFFSETS_M.items():
        open_session(name, off)
    epochs, vrs_bytes, outbox = [], [], []
    now = 0.0
    for e in range(CENTRE_SIM_S):
        for kind, name, off in SESSION_EVENTS.get(e, ()):
            if kind == "open":
                open_session(name, off)
            elif kind == "move":
                engine.move_session(name, *probes.geodetic_deg(check + np.array(off)))
                msm4.move(name, engine.sessions[name].point_ecef)
            else:
                engine.close_session(name)
                msm4.remove(name)
                del got[name]
        for name in stations:
            engine.feed(name, streams.epoch_bytes[name][e][1], now)
        now += 1.0
        reports = engine.tick(now)
        if len(reports) != 1:
            raise AssertionError(f"epoch {e}: {len(reports)} epochs solved in one tick (the driver feeds one)")
        vrs = {name: bytes(buf) for name, buf in got.items()}
        for buf in got.values():
            buf.clear()
        if reports[0].vrs is not None:
            for name, data in msm4.encode(list(engine.sessions), reports[0].vrs, engine.nav).items():
                vrs[f"{name}.msm4"] = data
        vrs_bytes.append(vrs)
        outbox.append(_outbox_item(engine.drain_outbox()))
        epochs.append(_network_record(reports[0].network, engine.network))
    out = {"world": world, "streams": streams, "stations": stations, "network": epochs, "vrs": vrs_bytes,
           "outbox": outbox}
    _SIM_CACHE["centre"] = out
    return out


def _centre_run_meta() -> dict:
    return {"scenario": "network-70km", "seconds": CENTRE_SIM_S, "sessions_offset_from_check1_m": VRS_OFFSETS_M,
            "session_events": SESSION_EVENTS}


def _outbox_item(messages) -> list:
    """What the centre publishes on the bus for an epoch (correction model, alarms): subject and payload."""
    return [[subject, *_bytes_item(payload)] for subject, payload in messages]


def _network_record(ne, network) -> dict:
    """One network epoch: per baseline its references and fixed DD integer tables (after the epoch), and the
    DD corrections of every station against the master."""
    rec = {"t": float(ne.t_gpst), "master": ne.master, "stations": list(ne.stations),
           "refs": dict(sorted(ne.refs.items())), "sats": [str(s) for s in ne.sats],
           "dd_iono": tenth_mm_rows(ne.dd_iono_m), "dd_trop": tenth_mm_rows(ne.dd_trop_m),
           "misclosures": int(ne.misclosures), "excluded": sorted(map(str, ne.excluded))}
    for name, solver in probes.baseline_solvers(network).items():
        res = ne.baselines.get(name)
        rec[f"{name}.solved"] = res is not None
        rec[f"{name}.refs"] = dict(sorted(probes.baseline_refs(solver).items()))
        for table, values in probes.fixed_tables(solver).items():
            rec[f"{name}.{table}"] = dict(sorted(values.items()))
    return rec


# --- cases ---------------------------------------------------------------------------------------------


def rtcm_encoder(shared: Path | None) -> dict:
    """The simulated stations' RTCM streams (1005/1033, ephemerides, batch-encoded MSM7) per epoch and
    receiver; each epoch's MSM decoded and encoded again one message at a time (MSM7 and MSM4) and by the
    batch encoder across the stations; every broadcast ephemeris of the world as a frame."""
    world, streams, _ = _sim()
    receivers = list(streams.epoch_bytes)
    epochs = []
    for e in range(RTCM_EPOCHS):
        rec = {"t": streams.epoch_bytes[receivers[0]][e][0]}
        by_layout: dict = {}
        for rx in receivers:
            t, data = streams.epoch_bytes[rx][e]
            rec[f"{rx}.stream"] = _bytes_item(data)
            msgs = probes.rtcm_messages(data)
            rec[f"{rx}.types"] = [int(getattr(m, "msg_type", 0)) for m in msgs]
            msm = [m for m in msgs if probes.is_msm(m)]
            for level in (7, 4):
                rec[f"{rx}.msm{level}"] = _bytes_item(b"".join(probes.msm_round_trip(m, level) for m in msm))
            for m in msm:
                by_layout.setdefault((m.msg_type, m.multiple), []).append(m)
        for (msg_type, multiple), msgs in sorted(by_layout.items()):
            for level in (7, 4):
                frames = probes.msm_batch(msgs, level) if _same_layout(msgs) else []
                rec[f"batch{msg_type}.{multiple}.msm{level}"] = [digest(f) for f in frames]
        epochs.append(rec)
    eph = [digest(f) for f in probes.ephemeris_frames(world.nav)]
    return {"epochs": epochs, "meta": {"scenario": "network-70km", "receivers": receivers,
                                       "ephemeris_frames": eph}}


def _same_layout(msgs) -> bool:
    return len({probes.msm_layout_key(m)[0] for m in msgs}) == 1


def wire(shared: Path | None) -> dict:
    """Wire primitives on fixed inputs: CRC-24Q (every implementation), RTCM framing of a station stream (with
    junk between frames) in odd splits by augnet's reader and the caster's aligner and splitter, HTTP chunked
    transfer coding by the caster's encoder and decoder and the onboard NTRIP client, the client's requests."""
    world, streams, _ = _sim()
    stream = b"".join(d for _, d in streams.epoch_bytes["NORTH"][:RTCM_EPOCHS])
    rng = np.random.default_rng(24)
    junky = stream[:3000] + b"\x00\xd3\x00\x05junk" + stream[3000:6000] + rng.bytes(50) + stream[6000:]
    epochs = []

    def add(item: str, **values) -> None:
        epochs.append({"t": len(epochs), "item": item, **values})

    for data in (b"", b"\xd3", b"123456789", bytes(range(256)), stream[:1000], rng.bytes(4097)):
        add("crc24q", input=_bytes_item(data), crc=probes.crc24q_all(data))
    for split in (1, 7, 1024, len(junky)):
        frames = probes.rtcm_frame_split(junky, split)
        add(f"augnet framing, split {split}", frames=len(frames), digest=digest(repr(frames).encode()))
        sizes, n, junk = probes.caster_frame_align(junky, split)
        add(f"caster aligner, split {split}", frames=n, junk=junk, forwarded=digest(repr(sizes).encode()))
    add("caster splitter", frames=[digest(f) for f in probes.caster_frame_split(junky)])
    payloads = [b"x", stream[:17], stream[:4096], rng.bytes(60000)]
    body = b"".join(probes.chunk_encode(p) for p in payloads) + b"0\r\n\r\n"
    add("chunked encode", body=_bytes_item(body))
    for split in (1, 3, 4096, len(body)):
        add(f"chunked decode, split {split}", data=_bytes_item(probes.chunk_decode(body, split)))
    response = b"HTTP/1.1 200 OK\r\nContent-Type: gnss/data\r\nTransfer-Encoding: chunked\r\n\r\n" + body
    for split in (1, 5, 4096, len(response)):
        add(f"ntrip client body, split {split}", data=_bytes_item(probes.ntrip_client_body(response, split)))
    add("ntrip client requests", requests=[r.decode("ascii") for r in probes.ntrip_client_requests()])
    return {"epochs": epochs, "meta": {}}


def _ambiguity_problem(rng, n: int, sigma_cyc: float, bias_cyc: float):
    """Float DD ambiguities over two frequencies' worth of correlated geometry: (a_hat, Q, true integers)."""
    G = rng.normal(size=(n, 3))
    Q = sigma_cyc**2 * (np.eye(n) + np.ones((n, n))) + 50.0 * sigma_cyc**2 * G @ G.T / n
    a = rng.integers(-50, 51, n).astype(float)
    a_hat = a + np.linalg.cholesky(Q) @ rng.normal(size=n) + bias_cyc * rng.normal(size=n)
    return a_hat, Q, a


def _sig6(x: float) -> str:
    return f"{float(x):.6g}"


def _conditioned_mcyc(a_hat, Q, fix) -> list[int] | None:
    """The float ambiguities conditioned on a partial fix's constraints Zs^T a = z [milli-cycles]: the same for
    any integer basis of the fixed combinations."""
    if fix is None:
        return None
    Zs = np.asarray(fix.Zs, float)
    K = Q @ Zs @ np.linalg.inv(Zs.T @ Q @ Zs)
    a = a_hat - K @ (Zs.T @ a_hat - np.asarray(fix.z_fixed, float))
    return [int(round(v * 1e3)) for v in a]


def ambiguity(shared: Path | None) -> dict:
    """Integer least squares and each partial-fixing policy on seeded float ambiguity problems (well and badly
    determined, biased and not): best two integer vectors, ratio, success rate, and what each partial fix
    fixes (count, and the float solution conditioned on it, in milli-cycles)."""
    rng = np.random.default_rng(18)
    epochs = []
    for k in range(AMBIGUITY_PROBLEMS):
        n = int(rng.integers(4, 25))
        sigma = float(rng.choice([0.01, 0.05, 0.15, 0.4]))
        bias = float(rng.choice([0.0, 0.0, 0.1, 0.3]))
        a_hat, Q, truth = _ambiguity_problem(rng, n, sigma, bias)
        cands, ratio, rate = probes.lambda_best_two(a_hat, Q)
        rec = {"t": k, "n": n, "best": np.asarray(cands).astype(int).tolist(), "ratio": _sig6(ratio),
               "success_rate": _sig6(rate)}
        for name, fix in probes.partial_fixes(a_hat, Q).items():
            rec[f"{name}.count"] = None if fix is None else int(fix.count)
            rec[f"{name}.ratio"] = None if fix is None else _sig6(fix.ratio)
            rec[f"{name}.success_rate"] = None if fix is None else _sig6(fix.success_rate)
            rec[f"{name}.a_fixed_mcyc"] = _conditioned_mcyc(a_hat, Q, fix)
        epochs.append(rec)
    return {"epochs": epochs, "meta": {"problems": AMBIGUITY_PROBLEMS, "seed": 18}}


def vrs_streams(shared: Path | None) -> dict:
    """The centre engine's VRS bytes per epoch and session over the simulated run (the engine's own decoding
    of the station bytes, network solve, synthesis and encoding)."""
    run = _centre_run()
    epochs = [{"t": ne["t"], "bus": bus, **{name: _bytes_item(data) for name, data in vrs.items()}}
              for ne, vrs, bus in zip(run["network"], run["vrs"], run["outbox"])]
    return {"epochs": epochs, "meta": _centre_run_meta()}


def centre_network_sim(shared: Path | None) -> dict:
    """The same run's network: per epoch and baseline the fixed DD integer tables, and the DD corrections."""
    run = _centre_run()
    return {"epochs": run["network"], "meta": {"scenario": "network-70km", "seconds": CENTRE_SIM_S}}


def _augnet_vrs_case(folder: Path, at: str, epochs: int | None) -> tuple[list[dict], dict]:
    """`augnet vrs` on a folder: per processed epoch the network record, and the VRS epoch it wrote (none
    when the epoch was skipped); meta: the RINEX header it writes."""
    network = []
    result, header = probes.augnet_vrs(folder, at, lambda ne, solver: network.append(_network_record(ne, solver)),
                                       epochs)
    by_t = {}
    for ep, mode, n in zip(result.epochs, result.epoch_mode, result.corrected_sats):
        by_t[round(float(ep.t_gpst), 3)] = _vrs_epoch_record(ep, mode, n)
    for rec in network:
        rec["vrs"] = by_t.pop(round(rec["t"], 3), None)
    if by_t:
        raise AssertionError(f"VRS epochs at times the network did not solve: {sorted(by_t)[:3]}")
    return network, {"rinex_header": header, "vrs_masters": dict(sorted(result.vrs_masters.items())),
                     "skipped_epochs": int(result.skipped_epochs)}


def _vrs_epoch_record(ep, mode: str, corrected: int) -> dict:
    lam = SPEED_OF_LIGHT_M_S / np.asarray(ep.freq_hz, float)
    return {"mode": mode, "corrected": int(corrected), "sats": [str(s) for s in ep.sats],
            "codes": [[str(c) for c in row] for row in ep.codes], "lli": np.asarray(ep.lli).astype(int).tolist(),
            "vrs_code": tenth_mm_rows(ep.code_m), "vrs_phase": tenth_mm_rows(np.asarray(ep.phase_cyc) * lam)}


def centre_network_catnet(shared: Path | None) -> dict:
    """`augnet vrs` on catnet-2010-077's CREU, EBRE, GARR (130-290 km, GPS L1/L2, 30 s) from the day's start,
    the VRS at CATNET_VRS_AT: the network (fixed tables, DD corrections) and the VRS epoch by epoch."""
    src = shared / "rinex" / "catnet-2010-077"
    with tempfile.TemporaryDirectory() as tmp:
        for name in [f"{s}0770.10o.gz" for s in CATNET_STATIONS] + ["brdc0770.10n.gz"]:
            os.symlink(src / name, Path(tmp) / name)
        epochs, meta = _augnet_vrs_case(Path(tmp), CATNET_VRS_AT, CATNET_EPOCHS)
    return {"epochs": epochs, "meta": {"folder": "rinex/catnet-2010-077", "stations": list(CATNET_STATIONS),
                                       "epochs": CATNET_EPOCHS, "at": CATNET_VRS_AT, **meta}}


def centre_network_nl(shared: Path | None) -> dict:
    """`augnet vrs` on nl-network-2021's four Dutch stations (35-150 km), the VRS at NL_VRS_AT."""
    epochs, meta = _augnet_vrs_case(shared / "rinex" / "nl-network-2021", NL_VRS_AT, None)
    return {"epochs": epochs, "meta": {"folder": "rinex/nl-network-2021", "at": NL_VRS_AT, **meta}}


def _solution_records(sols) -> list[dict]:
    out = []
    for s in sols:
        r = probes.solution_record(s)
        out.append({"t": float(s.time), "status": r["status"], "position": [tenth_mm(v) for v in r["position"]],
                    "fixed_dd": r["fixed_dd"]})
    return out


def onboard_static(shared: Path | None) -> dict:
    """static-1m-2024 as `augnet rtk` runs it (GPS, Galileo, BeiDou, QZSS; 15 deg; base from its file)."""
    d = shared / "rinex" / "static-1m-2024"
    rov, bas, nav, alpha, beta = probes.load_rinex_pair(d / "rover.obs", d / "base.obs", [d / "base.nav"])
    base = probes.parse_position(",".join(d.joinpath("base_position.txt").read_text().split()))
    opt = probes.rtk_options(("G", "E", "C", "J"), alpha, beta)
    return {"epochs": _solution_records(probes.rtk_postprocess(rov, bas, nav, base, opt)),
            "meta": {"folder": "rinex/static-1m-2024", "systems": "GECJ"}}


def onboard_yokohama(shared: Path | None) -> dict:
    """The moving Yokohama rover as test_real_data runs it (GPS, Galileo, QZSS; 15 deg; base from header)."""
    d = shared / "rinex" / "rtk-base-rover-yokohama-2021"
    rov, bas, nav, alpha, beta = probes.load_rinex_pair(d / "rover-SEPT265G.21O", d / "base-3034265G.21O",
                                                        [d / "nav-SEPT2650.21P"])
    opt = probes.rtk_options(("G", "E", "J"), alpha, beta)
    return {"epochs": _solution_records(probes.rtk_postprocess(rov, bas, nav, bas.approx_position_m, opt)),
            "meta": {"folder": "rinex/rtk-base-rover-yokohama-2021", "systems": "GEJ"}}


def onboard_garr_upc1(shared: Path | None) -> dict:
    """UPC1 (1 Hz) against GARR (30 s, 20 km away), GPS only, the first UPC1_EPOCHS of UPC1's hour."""
    d = shared / "rinex" / "catnet-2010-077"
    rov, bas, nav, alpha, beta = probes.load_rinex_pair(d / "UPC10770.10o.gz", d / "GARR0770.10o.gz",
                                                        [d / "brdc0770.10n.gz"])
    rov = probes.obs_window(rov, np.arange(len(rov.times)) < UPC1_EPOCHS)
    opt = probes.rtk_options(("G",), alpha, beta, max_age_s=UPC1_MAX_AGE_S)
    return {"epochs": _solution_records(probes.rtk_postprocess(rov, bas, nav, bas.approx_position_m, opt)),
            "meta": {"folder": "rinex/catnet-2010-077", "rover": "UPC1", "base": "GARR", "epochs": UPC1_EPOCHS,
                     "max_age_s": UPC1_MAX_AGE_S}}


def onboard_sim_vrs(shared: Path | None) -> dict:
    """check1's own RTCM stream as the rover against the centre's VRS 26 m from it (both decoded as the
    onboard unit decodes the caster's bytes), the RTK filter stepped epoch by epoch."""
    run = _centre_run()
    world, streams = run["world"], run["streams"]
    rover_dec, base_dec = probes.correction_decoder(), probes.correction_decoder()
    flt = None
    sols = []
    for e, vrs in enumerate(run["vrs"]):
        t_ref = streams.epoch_bytes["check1"][e][0]
        rov = rover_dec.feed(streams.epoch_bytes["check1"][e][1], t_ref)
        base = base_dec.feed(vrs[ONBOARD_VRS_SESSION], t_ref)
        if flt is None and base_dec.base_position_m is not None:
            flt = probes.rtk_filter(world.nav, base_dec.base_position_m, base_is_vrs=base_dec.base_non_physical)
        if flt is None:
            continue
        b = base[-1] if base else None
        for ep in rov:
            sols.append(flt.step(ep, b if b is not None and abs(b.time - ep.time) < 0.5 else None))
    return {"epochs": _solution_records(sols), "meta": {"scenario": "network-70km", "session": ONBOARD_VRS_SESSION}}


def centre_process(shared: Path | None) -> dict:
    """The first CENTRE_PROCESS_EPOCHS epochs of the simulated run through `augnet up`'s centre service (the
    engine in its own process behind the parent <-> centre protocol): each session's VRS bytes and the bus
    messages must be those of the engine in-process (its golden file, `vrs_streams`)."""
    import asyncio

    world, streams, stations = _sim()
    check = world.receivers[world.receiver_ids.index("check1")].ecef[0]
    fixes = {name: probes.geodetic_deg(check + np.array(off)) for name, off in VRS_OFFSETS_M.items()}
    feed = [[(name, streams.epoch_bytes[name][e][1]) for name in stations] for e in range(CENTRE_PROCESS_EPOCHS)]
    got = asyncio.run(probes.centre_service_run(stations, world.t0, fixes, feed))
    epochs = [{"t": t, "bus": _outbox_item(bus), **{name: _bytes_item(vrs[name]) for name in VRS_OFFSETS_M}}
              for t, vrs, bus in got]
    if any(e < CENTRE_PROCESS_EPOCHS for e in SESSION_EVENTS):
        raise AssertionError("the centre process case covers the epochs before the first session event only")
    return {"epochs": epochs, "meta": _centre_run_meta()}


def run(case: str, shared: Path | None) -> dict:
    """A case's outputs as its golden file holds them (through JSON: tuples become lists, keys strings),
    computed with one BLAS thread (what `make test` and the services use: the float sums in one order)."""
    import json

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        result = CASES[case][0](shared)
    return json.loads(json.dumps({"meta": result["meta"], "epochs": result["epochs"]}, sort_keys=True,
                                 allow_nan=False))


# Cases without a golden file of their own: compared with the first epochs of another case's.
# (golden case, its first epochs, the items compared)
GOLDEN_SOURCE = {"centre_process": ("vrs_streams", CENTRE_PROCESS_EPOCHS, ("t", "bus", *VRS_OFFSETS_M))}

# name -> (function, needs ../shared/data, slow: over ~3 s, outside `make test-fast`)
CASES: dict[str, tuple[Callable[[Path | None], dict], bool, bool]] = {
    "rtcm_encoder": (rtcm_encoder, False, False),
    "wire": (wire, False, False),
    "ambiguity": (ambiguity, False, False),
    "vrs_streams": (vrs_streams, False, True),
    "centre_network_sim": (centre_network_sim, False, True),
    "onboard_sim_vrs": (onboard_sim_vrs, False, True),
    "centre_process": (centre_process, False, True),
    "centre_network_catnet": (centre_network_catnet, True, True),
    "centre_network_nl": (centre_network_nl, True, False),
    "onboard_static": (onboard_static, True, True),
    "onboard_yokohama": (onboard_yokohama, True, False),
    "onboard_garr_upc1": (onboard_garr_upc1, True, False),
}
