"""Simulated station epochs for the centre's tests: the simulator's arrays as `StationEpoch`s, and the truth
beside them (kept apart: the engine under test never sees the truth)."""

from __future__ import annotations

import numpy as np

from augnet.centre.observations import StationEpoch


def station_epochs(world, block, r: int) -> list[StationEpoch]:
    """Receiver r's epochs of a simulator block, first two signals per system."""
    sats = np.array(world.sats)
    out = []
    for e in range(len(block.t_gpst)):
        obs = block.observed[e, r].any(axis=1)
        out.append(StationEpoch(world.receivers[r].id, float(block.t_gpst[e]), sats[obs],
                                block.pseudorange_m[e, r][obs][:, :2], block.phase_cyc[e, r][obs][:, :2],
                                block.lli[e, r][obs][:, :2], block.cnr_dbhz[e, r][obs][:, :2],
                                world.freq_hz[obs][:, :2], world.codes[obs][:, :2]))
    return out


def recorded_streams(duration_s: float, scenario: str = "network-70km"):
    """A scenario's stations as the RTCM bytes they would stream, every epoch kept: (world, streams, reference
    station coordinates by id; check receivers left out)."""
    from stations.rtcm_stream import RtcmStreams
    from stations.scenario import load_scenario
    from stations.world import World

    world = World(load_scenario(scenario).model_copy(update={"duration_s": duration_s}))
    streams = RtcmStreams(world)
    streams.keep_epochs = True
    for blk in world.epochs():
        streams.add(blk)
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    return world, streams, stations


def truth_dd_ambiguity(world, block, e: int, ra: int, rb: int, sat: str, ref: str) -> np.ndarray:
    """Truth DD integer ambiguities (b - a, sat - ref) on the first two signals."""
    idx = {s: j for j, s in enumerate(world.sats)}
    amb = block.ambiguity_cyc[e]
    j, jr = idx[sat], idx[ref]
    return (amb[rb, j, :2] - amb[ra, j, :2]) - (amb[rb, jr, :2] - amb[ra, jr, :2])
