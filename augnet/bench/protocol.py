"""Benchmark of the centre-process protocol (`augnet.system.centre_protocol`): encode and decode cost per
network epoch against pickle of the same content (the tuples the protocol replaced), on realistic
messages from the simulated world: every station's RTCM of an epoch and 200 train moves (loop -> centre),
2,000 trains' VRS in groups of 500 and the epoch's report (centre -> loop). CPU time of this process."""

from __future__ import annotations

import argparse
import json
import pickle
import struct
import time

import numpy as np

from augnet.bench.centre import _epochs, _world, vrs_sessions
from augnet.centre.engine import EpochReport, correction_model_json, vrs_model_counts
from augnet.centre.network import NetworkSolver
from augnet.centre.vrs import synthesize
from augnet.system.centre_protocol import (
    Decoder, EpochsSolved, MoveSession, StationData, VrsGroup, VrsWritten, encode)
from augnet.system.centre_service import VRS_GROUP

MOVES_PER_EPOCH = 200  # 2,000 trains' moves in a second (centre_service, PLAN_UPDATE_S)
_HEAD = struct.Struct(">I")  # the pickled frames' length prefix
LOOP_READ_BYTES = 256 << 10  # a read on the loop (asyncio's selector_events max_size)
CENTRE_READ_BYTES = 1 << 20  # a read in the centre (centre_service._RECV)


def _pickle_frame(obj) -> bytes:
    data = pickle.dumps(obj, protocol=5)
    return _HEAD.pack(len(data)) + data


class _PickleReader:
    """What both ends did with the pickled frames: a buffer, then every complete frame unpickled."""

    def __init__(self):
        self.buf = bytearray()

    def receive_data(self, data: bytes) -> list:
        buf = self.buf
        buf += data
        out, pos, n = [], 0, len(buf)
        with memoryview(buf) as view:
            while n - pos >= 4:
                size = _HEAD.unpack_from(view, pos)[0]
                if n - pos - 4 < size:
                    break
                with view[pos + 4:pos + 4 + size] as part:
                    out.append(pickle.loads(part))
                pos += 4 + size
        if pos:
            del buf[:pos]
        return out


def _network(n_stations: int, epochs: int):
    """The last epoch of a network solved from the simulated world, and its stations' RTCM bytes."""
    from stations.rtcm_stream import RtcmStreams

    streams = RtcmStreams(_world(n_stations, epochs))  # a world's epochs are generated once: one each
    streams.keep_epochs = True
    for blk in streams.world.epochs():
        streams.add(blk)
    world = _world(n_stations, epochs)
    net = NetworkSolver({r.id: r.ecef[0] for r in world.receivers})
    eps = ne = None
    for eps in _epochs(world):
        ne = net.update(eps, world.nav)
    rtcm = {name: per_epoch[-1][1] for name, per_epoch in streams.epoch_bytes.items()}
    return world, eps, ne, rtcm


def _vrs_bytes(world, eps, ne, trains: int):
    """Every train's VRS epoch (client id, RTCM bytes) and the epoch's VRS arrays."""
    ids, points, enc = vrs_sessions(trains, "VRS/")
    vrs = synthesize(ne, eps, points, world.nav)
    out = enc.encode(ids, vrs, world.nav)
    return [(cid, out[cid]) for cid in ids if out.get(cid)], vrs


def _messages(n_stations: int, trains: int, epochs: int) -> dict[str, list]:
    """One epoch's messages, by direction, in the protocol's types."""
    world, eps, ne, rtcm = _network(n_stations, epochs)
    batch, vrs = _vrs_bytes(world, eps, ne, trains)
    now = time.time()
    loop = [StationData(name, data, now) for name, data in rtcm.items()]
    loop += [MoveSession(f"VRS/{i}", 39.0 + 1e-4 * i, 116.0, 50.0) for i in range(MOVES_PER_EPOCH)]
    loop.append(VrsWritten(ne.t_gpst))
    groups = [batch[a:a + VRS_GROUP] for a in range(0, len(batch), VRS_GROUP)]
    centre: list = [VrsGroup(ne.t_gpst, [c for c, _ in g], [b for _, b in g], now, (now - 0.3, now - 0.2),
                             (0.01, 0.02, 0.03, 1.0), k == len(groups) - 1) for k, g in enumerate(groups)]
    report = EpochReport(ne.t_gpst, ne, None, trains, sorted(eps), (now - 0.3, now - 0.2), vrs_model_counts(vrs))
    centre.append(EpochsSolved([report], [("augnet.corrections.line", correction_model_json(ne))], 0.04, trains))
    return {"loop": loop, "centre": centre}


def _as_tuples(msgs: list) -> list:
    """The pickled tuples the protocol replaced: the loop's commands of an iteration in one frame, each
    centre message in its own."""
    out: list = []
    cmds: list = []
    for m in msgs:
        if isinstance(m, StationData):
            cmds.append(("data", m.station, m.data, m.arrival_unix_s))
        elif isinstance(m, MoveSession):
            cmds.append(("move", m.client_id, m.lat_deg, m.lon_deg, m.h_m))
        elif isinstance(m, VrsWritten):
            cmds.append(("written", m.t_gpst))
        elif isinstance(m, VrsGroup):
            batch = list(zip(m.client_ids, m.rtcm))
            out.append(("vrs", m.t_gpst, batch, m.ready_unix_s, m.arrival, m.cost, m.last))
        elif isinstance(m, EpochsSolved):
            out.append(("epoch", m.reports, m.outbox, m.solve_s, m.sessions))
    return ([cmds] if cmds else []) + out


def _chunks(data: bytes, size: int) -> list[bytes]:
    return [data[a:a + size] for a in range(0, len(data), size)]


def _read_into(decoder: Decoder, chunks: list[bytes]) -> list:
    """Ours as the sockets read: each read lands in the decoder's buffer (the copy stands for the kernel's)."""
    out = []
    for c in chunks:
        with decoder.get_buffer(len(c)) as room:
            room[:len(c)] = c
        out += decoder.buffer_updated(len(c))
    return out


def _read_pickled(reader: _PickleReader, chunks: list[bytes]) -> list:
    """The pickled frames as the sockets read them: each read a fresh bytes (the copy stands for the
    kernel's), appended to the reader's buffer."""
    return [m for c in chunks for m in reader.receive_data(memoryview(c).tobytes())]


def measure(msgs: list, read_bytes: int, repeat: int = 200) -> dict:
    """Encode and decode CPU [us] and bytes for `msgs` with the protocol and with pickle, the best of
    `repeat` (the two alternate: the machine may be shared). Decoding as on the socket: one reader for
    the run, the bytes in reads of `read_bytes`."""
    tuples = _as_tuples(msgs)
    ours = _chunks(b"".join(map(encode, msgs)), read_bytes)
    theirs = _chunks(b"".join(map(_pickle_frame, tuples)), read_bytes)
    decoder, reader = Decoder(), _PickleReader()
    steps = {
        "encode_us": lambda: b"".join([encode(m) for m in msgs]),
        "pickle_encode_us": lambda: [_pickle_frame(t) for t in tuples],
        "decode_us": lambda: _read_into(decoder, ours),
        "pickle_decode_us": lambda: _read_pickled(reader, theirs),
    }
    assert len(steps["decode_us"]()) == len(msgs) and len(steps["pickle_decode_us"]()) == len(tuples)
    best = dict.fromkeys(steps, np.inf)
    for _ in range(repeat):
        for name, fn in steps.items():
            t0 = time.process_time()
            fn()
            best[name] = min(best[name], time.process_time() - t0)
    return {"messages": len(msgs), "bytes": sum(map(len, ours)), "pickle_bytes": sum(map(len, theirs)),
            **{k: round(v * 1e6) for k, v in best.items()}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="augnet bench protocol", description=__doc__.splitlines()[0])
    ap.add_argument("--trains", type=int, default=2000)
    ap.add_argument("--epochs", type=int, default=10, help="epochs solved before the measured one")
    ap.add_argument("--repeat", type=int, default=200)
    ap.add_argument("--quick", action="store_true", help="6 stations only")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    results: dict = {}
    for n in ((6,) if args.quick else (6, 60)):
        msgs = _messages(n, args.trains, args.epochs)
        results[f"{n}_stations_loop"] = measure(msgs["loop"], CENTRE_READ_BYTES, args.repeat)
        results[f"{n}_stations_centre"] = measure(msgs["centre"], LOOP_READ_BYTES, args.repeat)
        vrs = [m for m in msgs["centre"] if isinstance(m, VrsGroup)]
        results[f"{n}_stations_vrs_group"] = measure(vrs[:1], LOOP_READ_BYTES, args.repeat)
        results[f"{n}_stations_epoch_report"] = measure([m for m in msgs["centre"] if isinstance(m, EpochsSolved)],
                                                        LOOP_READ_BYTES, args.repeat)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"centre protocol against pickle, CPU per network epoch ({args.trains} trains, groups of {VRS_GROUP}),"
          " best of", args.repeat)
    print(f"  {'':28s} {'msgs':>5s} {'bytes':>9s} {'pickle':>9s} {'encode us':>10s} {'pickle':>8s} "
          f"{'decode us':>10s} {'pickle':>8s}")
    for name, r in results.items():
        print(f"  {name:28s} {r['messages']:5d} {r['bytes']:9d} {r['pickle_bytes']:9d} {r['encode_us']:10d} "
              f"{r['pickle_encode_us']:8d} {r['decode_us']:10d} {r['pickle_decode_us']:8d}")


if __name__ == "__main__":
    main()
