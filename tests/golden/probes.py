"""Every call the golden test makes into the code under test, in one place.

The golden data pin what the code computes, not how it is organised: a restructure that moves or renames
one of the functions or attributes below (for example `BaselineSolver.fixed` becoming a `BaselineIntegers`
value, or CRC-24Q moving to a shared wire package) updates the matching probe here and leaves the golden
files alone. A probe changes only how a value is reached, never which value is recorded.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

# --- simulated stations (the stations package is the test fixture, not code under restructure) ---------


# The receiver model the golden files were recorded with: the presets' unannounced receiver events and L2 code
# factor (decision 0272) left out, so that a preset made harsher leaves the recorded golden inputs byte-identical.
GOLDEN_RECEIVER = {"phase_resets_per_hour": 0.0, "unflagged_slips_per_hour": 0.0, "data_gaps_per_hour": 0.0,
                   "noise": {"second_signal_code_factor": 1.0}}


def simulated_streams(duration_s: int, scenario: str = "network-70km"):
    """(world, RtcmStreams with every epoch's bytes kept, reference stations by id) of a seeded scenario, with
    the golden receiver model."""
    from tests.centre.simdata import recorded_streams

    return recorded_streams(duration_s, scenario, errors=GOLDEN_RECEIVER)


# --- RTCM encoder and wire primitives ------------------------------------------------------------------


def rtcm_messages(data: bytes):
    """Decoded messages of a byte stream (frames split, CRC checked, payloads decoded)."""
    from augnet.gnss.rtcm.codec import MessageReader

    return MessageReader().feed(data)


def msm_round_trip(msg, level: int) -> bytes:
    """An MSM message decoded to observables and encoded again, one message at a time, at `level`."""
    from augnet.gnss.rtcm.codec import encode_frame
    from augnet.gnss.rtcm.observables import msm_to_observables, observables_to_msm_list

    obs = msm_to_observables(msg)
    msgs = observables_to_msm_list(obs, level, msg.station_id, msg.epoch, multiple=msg.multiple)
    return b"".join(encode_frame(m) for m in msgs)


def msm_batch(msgs, level: int) -> list[bytes]:
    """The batch encoder over several receivers' MSM of one system and signal layout (receivers = msgs)."""
    from augnet.gnss.rtcm.batch import encode_msm_batch
    from augnet.gnss.rtcm.observables import msm_to_observables

    obs = [msm_to_observables(m) for m in msgs]
    o0 = obs[0]
    batch = encode_msm_batch(o0.system, level, o0.sat_ids, o0.sig_ids,
                             np.array([m.station_id for m in msgs]), np.array([m.epoch for m in msgs]),
                             np.stack([o.pseudorange_m for o in obs]), np.stack([o.phase_cycles for o in obs]),
                             np.stack([o.doppler_hz for o in obs]), np.stack([o.cnr_dbhz for o in obs]),
                             np.stack([o.lock_ms for o in obs]), np.stack([o.half_cycle for o in obs]))
    return [batch[i] for i in range(len(batch))]


def msm_layout_key(msg) -> tuple:
    from augnet.gnss.rtcm.observables import msm_to_observables

    o = msm_to_observables(msg)
    return (msg.msg_type, tuple(int(s) for s in o.sat_ids), tuple(int(s) for s in o.sig_ids))


def is_msm(msg) -> bool:
    from augnet.gnss.rtcm.msm import MsmMessage

    return isinstance(msg, MsmMessage)


def ephemeris_frames(nav) -> list[bytes]:
    """Every broadcast ephemeris of a simulated world's navigation table as an RTCM frame."""
    from augnet.gnss.rtcm.codec import encode_frame
    from augnet.gnss.rtcm.ephemeris import ephemeris_message

    return [encode_frame(ephemeris_message(rec)) for rec in nav.table.records]


def crc24q_all(data: bytes) -> dict[str, int]:
    """CRC-24Q of `data` by every implementation the code base has."""
    from augwire.crc24q import crc24q, crc24q_bytewise, crc24q_rows

    out = {"augnet": crc24q(data), "augnet_bytewise": crc24q_bytewise(data)}
    if len(data) <= 1029:  # the row-wise CRC covers one frame at most (3 + 1023 + 3 bytes)
        out["augnet_rows"] = int(crc24q_rows(np.frombuffer(data, np.uint8)[None])[0])
    # the caster's copies were recorded too; both sides now import augwire's
    out["caster_crc24q"], out["caster_crc24q_bytewise"] = out["augnet"], out["augnet_bytewise"]
    return out


def rtcm_frame_split(data: bytes, chunk: int) -> list[tuple[int, int]]:
    """(message type, frame length) of every frame of a stream fed `chunk` bytes at a time."""
    from augwire.rtcm_framing import RtcmStreamReader

    reader = RtcmStreamReader()
    out = []
    for i in range(0, len(data), chunk):
        out.extend((fr.msg_type, len(fr.raw)) for fr in reader.feed(data[i:i + chunk]))
    return out


def chunk_encode(data: bytes) -> bytes:
    from augwire.chunked import encode_chunk

    return encode_chunk(data)


def chunk_decode(body: bytes, split: int) -> bytes:
    from augwire.chunked import ChunkedDecoder

    dec = ChunkedDecoder()
    out = bytearray()
    for i in range(0, len(body), split):
        out += b"".join(dec.feed(body[i:i + split]))
    assert dec.finished
    return bytes(out)


# --- the centre --------------------------------------------------------------------------------------


def centre_engine(stations: dict, t0: float, name: str = "golden"):
    """The engine with admission moments off: the recorded VRS bytes are those of the stream before them
    (decision 0190: off reproduces them; tests/centre/test_vrs_live_admission.py tests on)."""
    from augnet.centre.engine import CentreEngine
    from augnet.centre.vrs_admission import AdmissionConfig

    return CentreEngine(stations, t0, network_name=name, admission=AdmissionConfig(admission=False))


def vrs_encoder(msm_level: int):
    from augnet.centre.vrs_stream import VrsStreamEncoder

    return VrsStreamEncoder(msm_level)


def network_solver(stations: dict, master: str | None = None):
    from augnet.centre.network import NetworkSolver

    return NetworkSolver(stations, master=master)


def baseline_solvers(network) -> dict:
    """name -> baseline solver of a network solver, in the network's baseline order."""
    return {s.name: s for s in network.solvers.values()}


def fixed_tables(solver) -> dict[str, dict[str, int]]:
    """A baseline's fixed DD integers against its references: N1, N2 and the wide lane N1 - N2 held on its
    own (satellite -> cycles)."""
    f = solver.fixed
    return {"N1": dict(f.n1), "N2": dict(f.n2), "WL": dict(f.wide_lane)}


def baseline_refs(solver) -> dict[str, str]:
    return dict(solver.refs)


def augnet_vrs(folder: Path, at: str, on_network, epochs: int | None = None):
    """`augnet vrs`'s post-processing of a folder of station RINEX (`load_network`, then `process`) for the
    VRS at `at`, its first `epochs` common epochs only (None: all). `on_network(network_epoch, solver)` sees
    the network solver after every epoch. Returns (VrsResult, the RINEX 3 header it writes)."""
    import dataclasses

    from augnet.centre import postprocess as pp
    from augnet.gnss.rinex.obs import write_obs

    inp = pp.load_network(folder)
    if epochs is not None:
        times, _ = pp.align_epochs(inp.stations)
        end = times[min(epochs, len(times)) - 1] + pp.EPOCH_MATCH_S
        inp.stations = [dataclasses.replace(st, obs=_obs_until(st.obs, end)) for st in inp.stations]
    solver_class = pp.NetworkSolver
    seen = []

    class Recording(solver_class):  # process() builds its own solver: this one shows each epoch's state
        def update(self, *args, **kwargs):
            ne = super().update(*args, **kwargs)
            seen.append(ne.t_gpst)
            on_network(ne, self)
            return ne

    pp.NetworkSolver = Recording
    try:
        result = pp.process(inp, pp.parse_point(at))
    finally:
        pp.NetworkSolver = solver_class
    if not seen:
        raise AssertionError("augnet vrs's process() no longer builds postprocess.NetworkSolver: update this probe")
    data = pp.to_obsdata(result)
    data.header.date = "20261201 000000 UTC"  # the writer's default is the wall clock
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "vrs.obs"
        write_obs(out, data)
        text = out.read_text()
    return result, text[:text.index("END OF HEADER")]


def _obs_until(obs, end_s: float):
    import dataclasses

    keep = obs.times < end_s
    return dataclasses.replace(obs, times=obs.times[keep], flags=obs.flags[keep],
                               clock_offset_s=obs.clock_offset_s[keep],
                               obs={k: v[keep] for k, v in obs.obs.items()},
                               lli={k: v[keep] for k, v in obs.lli.items()},
                               ssi={k: v[keep] for k, v in obs.ssi.items()})


def geodetic_deg(ecef) -> tuple[float, float, float]:
    from augnet.gnss.geometry import ecef_to_geodetic

    lat, lon, h = ecef_to_geodetic(np.asarray(ecef, float))
    return float(np.degrees(lat)), float(np.degrees(lon)), float(h)


# --- onboard ------------------------------------------------------------------------------------------


def rtk_options(systems: tuple[str, ...], alpha=None, beta=None, elevation_mask_deg: float = 15.0,
                max_age_s: float | None = None):
    """`augnet rtk`'s options for these systems (dual frequency, kinematic, continuous with hold)."""
    from augnet.onboard.rtk import RtkOptions
    from augnet.onboard.spp import SppOptions

    kw = {} if max_age_s is None else {"max_age_s": max_age_s}
    return RtkOptions(elevation_mask_rad=math.radians(elevation_mask_deg), systems=systems,
                      spp=SppOptions(elevation_mask_rad=math.radians(min(elevation_mask_deg, 10.0)),
                                     klobuchar_alpha=alpha, klobuchar_beta=beta, systems=systems), **kw)


def load_rinex_pair(rover: Path, base: Path, navs: list[Path]):
    """(rover, base, navigation, Klobuchar alpha, beta) as `augnet rtk` reads them."""
    from augnet.onboard.inputs import load_nav, load_obs

    nav, alpha, beta = load_nav(navs)
    return load_obs(rover), load_obs(base), nav, alpha, beta


def parse_position(text: str) -> np.ndarray:
    from augnet.onboard.inputs import parse_position as parse

    return np.asarray(parse(text), float)


def obs_window(obs, keep: np.ndarray):
    from augnet.onboard.observations import ObsArrays

    return ObsArrays(obs.times[keep], obs.sats, {k: v[keep] for k, v in obs.obs.items()},
                     {k: v[keep] for k, v in obs.lli.items()}, obs.approx_position_m, obs.marker_type)


def rtk_postprocess(rover, base, nav, base_position, options):
    """`augnet rtk`'s processing: one solution per rover epoch."""
    from augnet.onboard.postprocess import process

    return process(rover, base, nav, base_position, options)


def correction_decoder():
    from augnet.onboard.corrections import CorrectionDecoder

    return CorrectionDecoder()


def rtk_filter(nav, base_position, options=None, base_is_vrs: bool = False):
    from augnet.onboard.rtk import RtkFilter, RtkOptions

    return RtkFilter(nav, base_position, options or RtkOptions(), base_is_vrs=base_is_vrs)


def solution_record(sol) -> dict:
    """What is pinned of an RTK solution: status, position, fixed DD integers."""
    return {"status": sol.status_name, "position": [float(v) for v in sol.position_m],
            "fixed_dd": sorted([sat, ref, int(f), int(n)] for (sat, ref, f), n in sol.fixed_dd.items())}


def caster_frame_align(data: bytes, split: int) -> tuple[list[int], int, int]:
    """The caster's frame aligner fed `split` bytes at a time: (lengths forwarded per feed, frames, junk)."""
    from augwire.rtcm_framing import RtcmFrameAligner

    al = RtcmFrameAligner()
    sizes = [len(al.feed(data[i:i + split])) for i in range(0, len(data), split)]
    sizes.append(len(al.flush()))
    return sizes, al.frames, al.junk_bytes


def caster_frame_split(data: bytes) -> list[bytes]:
    from augwire.rtcm_framing import split_frames

    return split_frames(data)


def ntrip_client_requests() -> list[bytes]:
    from augnet.onboard.ntrip_client import NtripClientConnection

    gga = "$GPGGA,120000.00,3930.000,N,11642.000,E,1,12,0.8,35.0,M,0.0,M,,*4B"
    return [NtripClientConnection("caster", 2101, "VRS", "user", "pw", version=v, gga=g).request()
            for v in (1, 2) for g in (None, gga)]


def ntrip_client_body(response: bytes, split: int) -> bytes:
    """The data the onboard NTRIP client takes from a caster's response fed `split` bytes at a time."""
    from augnet.onboard.ntrip_client import Data, NtripClientConnection

    conn = NtripClientConnection("caster", 2101, "VRS", version=2)
    out = bytearray()
    for i in range(0, len(response), split):
        out += b"".join(ev.data for ev in conn.receive(response[i:i + split]) if isinstance(ev, Data))
    return bytes(out)


# --- the centre process (augnet up's centre service) ---------------------------------------------------

# The longest wait for the centre process to answer [s]: a guard against a hang, never a measurement.
CENTRE_PROCESS_ANSWER_S = 120.0


async def centre_service_run(stations: dict, t0: float, fixes: dict, feed: list) -> list:
    """The centre service (a child process speaking the parent <-> centre protocol) with a VRS session per
    `fixes` entry (name -> lat, lon, h), fed `feed[e]` = [(station, bytes), ...] epoch after epoch, each
    once the previous epoch is solved: per epoch (t, {session: VRS bytes}, bus messages)."""
    import asyncio

    from augnet.centre.vrs_admission import AdmissionConfig
    from augnet.system.centre_service import CentreService, CentreSpec
    from ntrip_caster.gga import GgaFix

    reports, bus = [], []
    spec = CentreSpec({k: tuple(map(float, v)) for k, v in stations.items()}, t0, "golden",
                      admission=AdmissionConfig(admission=False))  # as centre_engine: the recorded bytes
    svc = CentreService(spec, asyncio.get_running_loop(), on_epoch=lambda r, at: reports.append(r),
                        on_outbox=bus.extend)
    got = {name: bytearray() for name in fixes}
    out = []
    await svc.start()
    try:
        for name, (lat, lon, h) in fixes.items():
            svc.open(name, "VRS", GgaFix(lat, lon, h, 1, 12, "GN", b""), got[name].extend)
        for e, data in enumerate(feed):
            for station, chunk in data:
                svc.feed(station, chunk)
            waited = 0.0
            while len(reports) <= e:
                if waited > CENTRE_PROCESS_ANSWER_S:
                    raise AssertionError(f"the centre process solved no epoch {e} within {CENTRE_PROCESS_ANSWER_S} s")
                await asyncio.sleep(0.01)
                waited += 0.01
            await asyncio.sleep(0)
            out.append((float(reports[e].t_gpst), {k: bytes(v) for k, v in got.items()}, list(bus)))
            for v in got.values():
                v.clear()
            bus.clear()
    finally:
        await svc.stop()
    return out


# --- integer ambiguity resolution --------------------------------------------------------------------


def lambda_best_two(a_hat, Q):
    """(best two integer vectors, ratio, bootstrapped success rate) of integer least squares."""
    from augnet.gnss.ambiguity import lambda_search

    res = lambda_search(a_hat, Q, 2)
    return res.candidates, res.ratio, res.success_rate


def partial_fixes(a_hat, Q) -> dict:
    """The partial fix as the centre's baseline filter and the onboard RTK each call it with their default
    settings: name -> PartialFix or None (Zs, z_fixed, ratio, success_rate). When one policy serves both,
    call it here with each estimator's settings."""
    from augnet.centre.baseline_config import BaselineConfig, fix_policy as centre_fix_policy
    from augnet.gnss.ambiguity import partial_fix
    from augnet.onboard.rtk import RtkOptions, fix_policy

    c = BaselineConfig()
    return {"centre": partial_fix(a_hat, Q, centre_fix_policy(c, c.fix_min_count)),
            "onboard": partial_fix(a_hat, Q, fix_policy(RtkOptions()))}
