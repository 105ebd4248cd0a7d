"""A train's RSSP-I link to its ATP simulator as `augnet up` runs it (decision 0281): the timer's passages
reach the ATP over real loopback UDP in order, each acknowledged; two consecutive linked groups missed become
a service-brake request the ATP receives. The timer runs on a stepped clock; the link on the real one."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from augnet.onboard.balise_timer import BaliseGroup, TimedBaliseDetector
from augnet.system.atp_link import AtpConnection

SPEED_MPS = 83.3  # 300 km/h
SIGMA_M = 0.01  # a fixed RTK along-track sigma
GROUPS = [BaliseGroup(f"VB-L1-1-{km:07.3f}", "L1-1", km * 1000.0, b"\x01", True) for km in (1.0, 3.0, 5.0, 7.0)]
DEADLINE_S = 20.0  # stops a hang only


def _drive(det: TimedBaliseDetector, until_s: float, outage) -> None:
    """1 Hz estimates of a train at SPEED_MPS from chainage 0, none during `outage(t)`; ticks every 10 ms."""
    for t in np.arange(0.0, until_s, 0.01):
        t = round(float(t), 2)
        if abs(t - round(t)) < 1e-9 and not outage(t):
            det.update(t, "L1-1", SPEED_MPS * t, SPEED_MPS, SIGMA_M ** 2, 2 * SIGMA_M ** 2)
        det.tick(t)


@pytest.mark.slow  # real-time link cycles (~5 s), as tests/onboard/test_balise_timer.py's RSSP-I test
def test_passages_and_a_service_brake_reach_the_atp_over_rssp1():
    async def main():
        conn = AtpConnection(1, GROUPS)
        await conn.start()
        try:
            det = TimedBaliseDetector(GROUPS, conn.sink, k=6.0)
            t2, t3 = GROUPS[1].along_m / SPEED_MPS, GROUPS[2].along_m / SPEED_MPS
            _drive(det, GROUPS[3].along_m / SPEED_MPS + 3.0, outage=lambda t: t2 - 4.0 < t < t3 + 4.0)
            t0 = time.monotonic()
            while len(conn.atp.passages) < 2 or not conn.atp.service_brake_requests or conn.link.pending:
                assert time.monotonic() - t0 < DEADLINE_S, conn.snapshot()
                await asyncio.sleep(0.1)
            return conn.snapshot(), conn
        finally:
            await conn.stop()

    snap, conn = asyncio.run(main())
    assert [t["group"] for t in snap["telegrams_received"]] == [GROUPS[0].id, GROUPS[3].id]  # in order
    assert [t["chainage_mm"] for t in snap["telegrams_received"]] == [1_000_000, 7_000_000]
    assert [m.group.id for m in conn.sink.misses] == [GROUPS[1].id, GROUPS[2].id]
    assert len(snap["service_brake_requests"]) == 1 and "2 consecutive linked groups missed" in \
        snap["service_brake_requests"][0]["text"]
    assert snap["atp_alarms"] == ["SERVICE_BRAKE"]  # no map mismatch, no order alarm
    assert snap["unacknowledged"] == 0 and snap["onboard_sent"] == 2
    # the predicted passage moment travels in the telegram (ms), as the timer computed it
    assert snap["telegrams_received"][0]["time_ms"] == round(conn.sink.passages[0].time * 1000)
