"""Configuration parsing, the A/B machine redundancy, and the UDP transport's source filter."""

from __future__ import annotations

import asyncio
import socket

import pytest

from rssp1.config import LinkTiming, link_config_from_mapping
from rssp1.endpoint import DataReceived, Endpoint
from rssp1.frames import TYPE_RSD_B, CATEGORY_STANDBY
from rssp1.transport import EndpointNode, UdpLink

from .linkpair import CENTRE, RBC, LinkPair, received


def test_link_config_from_mapping():
    cfg = link_config_from_mapping({
        "local": {"address": "0x0101", "sid": ["0x1A2B3C4D", "0x5E6F7081"], "dataver": [1, 2]},
        "peer": {"address": 41, "sid": "0x311616DC,0x07643EDE", "sinit": [5, 6], "dataver": ["10", "11"]},
        "timing": {"cycle_s": 0.5, "delta_time": 5},
    })
    assert cfg.local.address == 0x0101 and cfg.local.sid == (0x1A2B3C4D, 0x5E6F7081)
    assert cfg.peer.address == 0x29 and cfg.peer.timestamp_seed == (5, 6) and cfg.peer.dataver == (10, 11)
    assert cfg.timing == LinkTiming(cycle_s=0.5, delta_time=5, life_time=4, delay_time=3)
    for bad in (
        {"local": {"address": 1, "sid": [1]}, "peer": {"address": 2, "sid": [1, 2]}},
        {"local": {"address": 0x10000, "sid": [1, 2]}, "peer": {"address": 2, "sid": [1, 2]}},
        {"local": {"address": 1, "sid": [1, 2 ** 32]}, "peer": {"address": 2, "sid": [1, 2]}},
        {"local": {"address": 1, "sid": [1, 2]}, "peer": {"address": 2, "sid": [1, 2]}, "timing": {"cycle": 1}},
        {"local": {"address": 1, "sid": [1, 2]}, "peer": {"address": 2, "sid": [1, 2]}, "timing": {"delta_time": 0}},
        {"local": {"address": 1, "sid": [1, 2]}, "peer": {"address": 2, "sid": [1, 2]}, "extra": 1},
    ):
        with pytest.raises(ValueError):
            link_config_from_mapping(bad)


def test_machines_a_and_b_carry_one_stream():
    """A 2oo2 sender's machines A and B send the same TC and data; the receiver takes the first."""
    pair = LinkPair()
    machine_b = Endpoint(CENTRE, RBC, pair.timing, initial_tc=1000, machine=TYPE_RSD_B, category=CATEGORY_STANDBY)
    pair.bring_up()
    # B runs in step with A (same TC, same timestamps): fast-forward it to A's cycle
    while machine_b.tc != pair.a.tc:
        machine_b.cycle(None)
    events = []
    for i in range(10):
        frames_b, _ = machine_b.cycle(b"data%d" % i)
        events += pair.step(b"data%d" % i)
        for f in frames_b:
            if f[1] == TYPE_RSD_B:
                events += pair.b.receive(f)
    assert received(events) == [b"data%d" % i for i in range(10)]
    assert pair.b.stats["dropped_repeat"] == 10
    # when A falls silent, B's frames keep the link up on their own
    events = []
    for i in range(10, 20):
        frames_b, _ = machine_b.cycle(b"data%d" % i)
        pair.a.cycle(b"data%d" % i)
        pair.b.cycle(b"ack")
        for f in frames_b:
            events += pair.b.receive(f)
    assert received(events) == [b"data%d" % i for i in range(10, 20)] and pair.b.is_up


@pytest.mark.timeout(30)
def test_udp_link_drops_datagrams_from_strangers():
    async def scenario():
        ep = Endpoint(RBC, CENTRE, LinkTiming(cycle_s=0.05))
        link = await UdpLink.open(EndpointNode(ep), 0.05, ("127.0.0.1", 0), ("127.0.0.2", 9))
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                for _ in range(5):
                    s.sendto(b"\x01\x80junk", link.local_address)
            for _ in range(100):
                await asyncio.sleep(0.01)
                if link.stats["foreign_source"] == 5:
                    break
            assert link.stats["foreign_source"] == 5 and ep.stats["rx_frames"] == 0
        finally:
            link.close()

    asyncio.run(scenario())


@pytest.mark.timeout(30)
def test_udp_dual_network_copies_are_taken_once():
    async def scenario():
        timing = LinkTiming(cycle_s=0.05)
        got = []
        rbc_ep, centre_ep = Endpoint(RBC, CENTRE, timing), Endpoint(CENTRE, RBC, timing)
        rbc = await UdpLink.open(EndpointNode(rbc_ep, on_event=lambda e, t: got.append(e)), 0.05,
                                 ("127.0.0.1", 0), ("127.0.0.1", 9))
        centre = await UdpLink.open(EndpointNode(centre_ep, payload=lambda: b"status"), 0.05, ("127.0.0.1", 0),
                                    rbc.local_address, redundant=[rbc.local_address])
        rbc.remote = centre.local_address
        tasks = [asyncio.create_task(rbc.run()), asyncio.create_task(centre.run(cycles=30))]
        try:
            await tasks[1]
            await asyncio.sleep(0.1)
        finally:
            rbc.close()
            centre.close()
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        data = [e.data for e in got if isinstance(e, DataReceived)]
        assert len(data) >= 20 and rbc_ep.stats["rx_rsd_ok"] == len(data)
        # every accepted frame's twin was dropped as a repeat (the first copies during sync excepted)
        assert rbc_ep.stats["dropped_repeat"] >= len(data)
        assert centre.stats["tx"] == 2 * (centre_ep.stats["tx_rsd"] + centre_ep.stats["tx_sse"] + centre_ep.stats["tx_ssr"])

    asyncio.run(scenario())
