"""The correction bus: same behaviour in process and on the NATS JetStream server at 127.0.0.1:4222."""

from __future__ import annotations

import asyncio
import socket

import pytest

from augnet.bus import BusError, InProcessBus, open_bus, subject_matches

NATS_URL = "nats://127.0.0.1:4222"


def nats_available() -> bool:
    try:
        with socket.create_connection(("127.0.0.1", 4222), timeout=0.5):
            return True
    except OSError:
        return False


@pytest.mark.parametrize("pattern,subject,ok", [
    ("augnet.corrections.>", "augnet.corrections.line1", True),
    ("augnet.corrections.>", "augnet.corrections", False),
    ("augnet.*.line1", "augnet.alarms.line1", True),
    ("augnet.*.line1", "augnet.alarms.line2", False),
    ("augnet.alarms", "augnet.alarms", True),
    ("augnet.alarms", "augnet.alarms.x", False),
])
def test_subject_matching_follows_nats(pattern, subject, ok):
    assert subject_matches(pattern, subject) is ok


async def _exercise(bus):
    corr = await bus.subscribe("augnet.corrections.>")
    alarms = await bus.subscribe("augnet.alarms.*")
    for i in range(5):
        await bus.publish("augnet.corrections.line1", b"model-%d" % i)
    await bus.publish("augnet.alarms.line1", b"station A down")
    got = [await corr.next(timeout=5) for _ in range(5)]
    assert [m.payload for m in got] == [b"model-%d" % i for i in range(5)]
    assert [m.seq for m in got] == [1, 2, 3, 4, 5]
    alarm = await alarms.next(timeout=5)
    assert alarm.subject == "augnet.alarms.line1" and alarm.payload == b"station A down"
    with pytest.raises(asyncio.TimeoutError):
        await alarms.next(timeout=0.2)
    with pytest.raises(BusError):
        await bus.publish("augnet.bad subject", b"")


def test_in_process_bus_delivers_in_order_to_matching_subscribers():
    async def main():
        async with InProcessBus() as bus:
            await _exercise(bus)
    asyncio.run(main())


def test_slow_subscriber_drops_oldest_and_counts_without_blocking_the_publisher():
    async def main():
        bus = InProcessBus()
        slow = await bus.subscribe("augnet.corrections.>", max_pending=3)
        for i in range(10):
            await bus.publish("augnet.corrections.line1", bytes([i]))
        assert slow.dropped == 7
        got = [await slow.next(timeout=1) for _ in range(3)]
        assert [m.payload for m in got] == [bytes([7]), bytes([8]), bytes([9])]
        assert [m.seq for m in got] == [8, 9, 10]  # the gap tells the subscriber it lost messages
        await bus.close()
    asyncio.run(main())


@pytest.mark.skipif(not nats_available(), reason="no NATS server with JetStream at 127.0.0.1:4222")
def test_jetstream_bus_behaves_like_the_in_process_one():
    async def main():
        bus = await open_bus(NATS_URL)
        try:
            await _exercise(bus)
            with pytest.raises(BusError):
                await bus.publish("other.subject", b"x")
        finally:
            await bus.close()
    asyncio.run(main())


def test_unknown_bus_url_is_refused_with_the_url():
    with pytest.raises(BusError, match="redis://x"):
        asyncio.run(open_bus("redis://x"))


@pytest.mark.skipif(not nats_available(), reason="no NATS server with JetStream at 127.0.0.1:4222")
def test_caster_change_events_travel_on_jetstream():
    from augnet.bus.config_events import CASTER_CONFIG_SUBJECT, CasterChange, decode_change, publish_change

    async def main():
        bus = await open_bus(NATS_URL)
        try:
            sub = await bus.subscribe(CASTER_CONFIG_SUBJECT)
            sent = [CasterChange("user", "train", "edit"), CasterChange("mountpoint", "VRS", "edit")]
            for change in sent:
                await publish_change(bus, change)
            got = [decode_change((await sub.next(timeout=5)).payload) for _ in sent]
            assert got == sent
        finally:
            await bus.close()
    asyncio.run(main())
