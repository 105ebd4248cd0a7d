"""Simulated station epochs for the centre's tests: the simulator's arrays as `StationEpoch`s, and the truth
beside them (kept apart: the engine under test never sees the truth)."""

from __future__ import annotations

import numpy as np

from augnet.centre.observations import StationEpoch
from stations.network_truth import station_epoch, true_dd_integers


def station_epochs(world, block, r: int) -> list[StationEpoch]:
    """Receiver r's epochs of a simulator block, first two signals per system."""
    return [station_epoch(world, block, e, r) for e in range(len(block.t_gpst))]


def recorded_streams(duration_s: float, scenario: str = "network-70km", errors: dict | None = None):
    """A scenario's stations as the RTCM bytes they would stream, every epoch kept: (world, streams, reference
    station coordinates by id; check receivers left out). `errors` overrides fields of the scenario's errors
    (a nested dict for `noise`), e.g. the golden probes' receiver model."""
    from stations.rtcm_stream import RtcmStreams
    from stations.scenario import load_scenario
    from stations.world import World

    sc = load_scenario(scenario)
    update: dict = {"duration_s": duration_s}
    if errors:
        err = dict(errors)
        if "noise" in err:
            err["noise"] = sc.errors.noise.model_copy(update=err["noise"])
        update["errors"] = sc.errors.model_copy(update=err)
    world = World(sc.model_copy(update=update))
    streams = RtcmStreams(world)
    streams.keep_epochs = True
    for blk in world.epochs():
        streams.add(blk)
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    return world, streams, stations


def truth_dd_ambiguity(world, block, e: int, ra: int, rb: int, sat: str, ref: str) -> np.ndarray:
    """Truth DD integer ambiguities (b - a, sat - ref) on the first two signals."""
    return true_dd_integers(world, block, e, ra, rb, [sat], {sat[0]: ref})[0]
