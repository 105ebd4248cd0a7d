"""The live state and its websocket feed: snapshot first, then events, from any thread; bounded queues."""

from __future__ import annotations

import asyncio
import threading

import pytest
from starlette.websockets import WebSocketDisconnect

from augnet.console.live import BaselineLive, LiveState, StationLive, TrainLive
from augnet.console.routers.live import WS_UNAUTHORIZED


def _train(i: int, along_km: float) -> TrainLive:
    return TrainLive(f"T{i}", 30.0, 114.0 + along_km / 96.4, 20.0, "L1", along_km, 0.0, "fix", 1.0, 0.1, 0.2, 200.0)


def _events(ws, want: int) -> list[dict]:
    events = []
    while len(events) < want:
        events += ws.receive_json()["events"]
    return events


def test_websocket_sends_snapshot_then_events_from_other_threads(sqlite_console):
    c = sqlite_console
    c.live.set_line({"id": "L1", "length_km": 96.4, "polyline": [[30.0, 114.0], [30.0, 115.0]]})
    c.live.update_train(_train(1, 10.0))
    with c.client.websocket_connect(f"/api/live?token={c.tokens['vera']}") as ws:
        first = ws.receive_json()["events"]
        assert len(first) == 1 and first[0]["type"] == "snapshot"
        assert first[0]["line"]["id"] == "L1" and [t["id"] for t in first[0]["trains"]] == ["T1"]

        def writer():  # the running system updates from its own worker thread
            c.live.update_train(_train(1, 10.5))
            c.live.update_station(StationLive("STA1", 101, 30.0, 114.0, 20.0, 0.0, True, True, 0.3, 22))
            c.live.set_baselines([BaselineLive("STA1", "STA2", 48.2, "float", 0.4, 3.0)])
            c.live.set_network({"master": "STA1"})

        t = threading.Thread(target=writer)
        t.start()
        t.join()
        events = _events(ws, 4)
        assert [e["type"] for e in events] == ["train", "station", "baselines", "network"]
        assert events[0]["train"]["along_km"] == 10.5
        assert events[2]["baselines"][0]["state"] == "float"
        assert c.live.subscriber_count == 1
    # the server notices the client leaving and drops its queue
    for _ in range(200):
        if c.live.subscriber_count == 0:
            break
        threading.Event().wait(0.01)
    assert c.live.subscriber_count == 0


@pytest.mark.parametrize("query", ["", "?token=wrong"])
def test_websocket_without_valid_token_is_closed_4401(sqlite_console, query):
    with sqlite_console.client.websocket_connect(f"/api/live{query}") as ws:
        with pytest.raises(WebSocketDisconnect) as exc:
            ws.receive_json()
    assert exc.value.code == WS_UNAUTHORIZED


def test_snapshot_route_polling_fallback(sqlite_console):
    c = sqlite_console
    c.live.update_train(_train(2, 33.0))
    r = c.client.get("/api/live/snapshot", headers=c.as_("vera"))
    assert r.status_code == 200 and r.json()["trains"][0]["along_km"] == 33.0
    assert c.client.get("/api/live/snapshot").status_code == 401


def test_slow_subscriber_keeps_the_newest_events():
    live = LiveState(queue_events=5)

    async def run():
        q = live.subscribe()
        for i in range(12):
            live.update_train(_train(1, float(i)))
        await asyncio.sleep(0)  # let the loop run the queued puts
        await asyncio.sleep(0)
        got = []
        while not q.empty():
            got.append(q.get_nowait()["train"]["along_km"])
        live.unsubscribe(q)
        return got

    assert asyncio.run(run()) == [7.0, 8.0, 9.0, 10.0, 11.0]
    assert live.subscriber_count == 0


def test_subscriber_on_a_closed_loop_is_dropped():
    live = LiveState()
    loop = asyncio.new_event_loop()
    loop.run_until_complete(asyncio.sleep(0))

    async def sub():
        return live.subscribe()

    loop.run_until_complete(sub())
    loop.close()
    assert live.subscriber_count == 1
    live.update_train(_train(1, 1.0))  # must not raise in the writer
    assert live.subscriber_count == 0


def test_concurrent_writers_and_readers():
    live = LiveState()
    errors = []

    def write(k):
        for i in range(300):
            live.update_train(_train(k * 1000 + i % 20, float(i)))

    def read():
        try:
            for _ in range(300):
                snap = live.snapshot()
                assert all(t["id"].startswith("T") for t in snap["trains"])
        except Exception as exc:  # surfaced below
            errors.append(exc)

    threads = [threading.Thread(target=write, args=(k,)) for k in range(3)] + [threading.Thread(target=read)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert len(live.trains) == 60 and live.events_published == 900


def test_station_changed_updates_live_enabled_and_calls_the_hook():
    live = LiveState()
    live.update_station(StationLive("STA1", 101, 30.0, 114.0, 20.0))
    seen = []
    live.on_station_change = lambda code, change: seen.append((code, change))
    live.station_changed("STA1", {"action": "disable", "enabled": False})
    assert live.stations["STA1"].enabled is False and seen == [("STA1", {"action": "disable", "enabled": False})]
