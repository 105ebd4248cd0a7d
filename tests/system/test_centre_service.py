"""The centre service of `augnet up`: the engine in its own process behind the caster's stream-factory
interface. Station bytes in, each session's VRS out through its sink, moves and closes obeyed; a centre
process that dies is reported and replaced; shutdown leaves no process behind; bad input is survived."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from augnet.centre.ingest import StationDecoder
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.system.centre_protocol import MoveSession, OpenSession, VrsGroup
from augnet.system.centre_service import MAX_DELIVERY_S, CentreService, CentreSpec
from ntrip_caster.gga import GgaFix
from ntrip_caster.stream_factory import StreamFactory
from tests.centre.simdata import recorded_streams

pytestmark = pytest.mark.slow

EPOCHS = 12


@pytest.fixture(scope="module")
def recorded():
    return recorded_streams(EPOCHS)


def _fix(ecef) -> GgaFix:
    lat, lon, h = ecef_to_geodetic(np.asarray(ecef, float))
    return GgaFix(float(np.degrees(lat)), float(np.degrees(lon)), float(h), 1, 12, "GN", b"")


async def _until(cond, timeout: float = 30.0) -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError("timed out")
        await asyncio.sleep(0.02)


def _service(world, stations, **kw) -> tuple[CentreService, list, list]:
    epochs, alarms = [], []
    spec = CentreSpec({k: tuple(map(float, v)) for k, v in stations.items()}, world.t0, "test")
    svc = CentreService(spec, asyncio.get_running_loop(), on_epoch=lambda r, at: epochs.append(r),
                        on_alarm=lambda *a: alarms.append(a), **kw)
    return svc, epochs, alarms


async def _feed(svc, streams, stations, epochs_range, pause: float = 0.0) -> None:
    for e in epochs_range:
        for name in stations:
            svc.feed(name, streams.epoch_bytes[name][e][1])
        await asyncio.sleep(pause)


def test_a_session_gets_its_vrs_moves_and_closes(recorded):
    world, streams, stations = recorded
    check = world.receivers[world.receiver_ids.index("check1")].ecef[0]
    west = stations["WEST"]

    async def main():
        svc, epochs, alarms = _service(world, stations)
        assert isinstance(svc, StreamFactory) and sorted(svc.stations) == sorted(stations)
        await svc.start()
        got = bytearray()
        handle = svc.open("VRS/1", "VRS", _fix(check), got.extend)
        await _feed(svc, streams, stations, range(0, 6), 0.05)
        await _until(lambda: len(epochs) >= 5)
        dec = StationDecoder("VRS", world.t0)
        first = dec.feed(bytes(got))
        assert first and np.linalg.norm(dec.arp_ecef - check) < 0.01  # its own VRS at its own point
        # the train moves: the next epochs come from the new point
        moved = 0.5 * (check + west)
        handle.update_position(_fix(moved))
        n = len(got)
        await _feed(svc, streams, stations, range(6, 9), 0.05)
        await _until(lambda: len(epochs) >= 8)
        dec2 = StationDecoder("VRS", world.t0)
        assert dec2.feed(bytes(got[n:])) and np.linalg.norm(dec2.arp_ecef - moved) < 0.01
        # closed: nothing more reaches its sink
        handle.close()
        await asyncio.sleep(0.2)
        n = len(got)
        await _feed(svc, streams, stations, range(9, EPOCHS), 0.05)
        await _until(lambda: len(epochs) >= EPOCHS - 1)
        assert len(got) == n
        # what the loop side keeps for the console and the run report
        r = epochs[-1]
        assert r.network.present and set(r.network.present) <= set(stations) and r.arrival is not None
        assert svc.timings.epochs == len(epochs) and svc.errors == 0 and not alarms
        assert svc.latency_ms_p99()["vrs_ready_ms_p99"] is not None and svc.stages_ms()["sessions"] == 1
        proc = svc._proc
        await svc.stop()
        assert not proc.is_alive() and proc.exitcode == 0  # stopped by its message, not killed

    asyncio.run(main())


def test_bad_input_is_survived_and_a_disabled_station_is_not_fed(recorded):
    world, streams, stations = recorded

    async def main():
        svc, epochs, alarms = _service(world, stations)
        await svc.start()
        svc.feed("NOSUCH", b"\xd3\x00\x13garbage")  # unknown station
        svc.feed("WEST", b"\xd3\x03\xff" + bytes(range(256)) * 4)  # garbage in a known station's stream
        svc._send(MoveSession("never-opened", 0.0, 0.0, 0.0))
        svc._send(OpenSession("bad", "not a latitude", None, None))  # the codec refuses it; the rest goes on
        svc.set_station_enabled("WEST", False)
        await _feed(svc, streams, stations, range(0, 4), 0.05)
        await _until(lambda: len(epochs) >= 3)
        assert svc.alive and "WEST" not in epochs[-1].network.present and "EAST" in epochs[-1].network.present
        assert svc.errors >= 1  # the refused session was reported
        await svc.stop()

    asyncio.run(main())


def test_a_dead_centre_is_reported_and_replaced_and_stop_leaves_no_process(recorded):
    world, streams, stations = recorded
    check = world.receivers[world.receiver_ids.index("check1")].ecef[0]

    async def main():
        svc, epochs, alarms = _service(world, stations)
        await svc.start()
        got = bytearray()
        svc.open("VRS/1", "VRS", _fix(check), got.extend)
        await _until(lambda: svc.alive)
        first = svc._proc
        first.kill()
        await _until(lambda: alarms)
        kind, subject, severity, message, cleared = alarms[0]
        assert (kind, severity, cleared) == ("centre-process", "critical", False) and "died" in message
        assert svc.errors == 1
        await _until(lambda: svc.alive and svc._proc is not first)
        # the new centre serves the session the caster still has
        await _feed(svc, streams, stations, range(0, 5), 0.05)
        await _until(lambda: len(epochs) >= 4 and len(got) > 0)
        assert alarms[-1][4] is True  # cleared by the new centre's first epoch
        second = svc._proc
        await svc.stop()
        assert not first.is_alive() and not second.is_alive() and svc.restarts == 1

    asyncio.run(main())


def test_stop_kills_a_centre_that_does_not_answer(recorded):
    world, _, stations = recorded

    async def main():
        import os
        import signal

        svc, _, alarms = _service(world, stations)
        await svc.start()
        await _until(lambda: svc.alive)
        os.kill(svc.pid, signal.SIGSTOP)  # hung: it will not read its "stop"
        await asyncio.wait_for(svc.stop(timeout=0.5), 10)  # hang guard: the kill follows the 0.5 s
        assert not svc._proc.is_alive()
        assert not alarms  # a stop is not a crash

    asyncio.run(main())


def test_a_centre_that_stops_answering_is_killed_reported_and_replaced(recorded):
    world, streams, stations = recorded

    async def main():
        import os
        import signal

        svc, epochs, alarms = _service(world, stations, hang_s=2.0)
        await svc.start()
        await _until(lambda: svc.ready)
        first = svc._proc
        os.kill(first.pid, signal.SIGSTOP)  # alive, but silent
        await _until(lambda: alarms, timeout=20)
        assert alarms[0][0] == "centre-process" and alarms[0][4] is False
        await _until(lambda: svc.alive and svc._proc is not first, timeout=20)
        assert not first.is_alive() and svc.restarts == 1
        await _feed(svc, streams, stations, range(0, 3), 0.05)
        await _until(lambda: len(epochs) >= 2)
        await svc.stop()

    asyncio.run(main())


def test_a_starting_centre_has_start_s_to_answer_not_hang_s(recorded):
    """A loaded machine can take longer than HANG_S to spawn a centre and build its engine: until it says Ready
    the watchdog waits START_S, and only then takes it for hung."""
    world, _, stations = recorded

    async def main():
        import os
        import signal

        svc, _, alarms = _service(world, stations, hang_s=0.5, start_s=6.0)
        await svc.start()
        first = svc._proc
        os.kill(first.pid, signal.SIGSTOP)  # stopped during its start-up, before Ready
        await asyncio.sleep(2.0)  # four times hang_s
        assert first.is_alive() and svc.restarts == 0 and not alarms
        await _until(lambda: alarms, timeout=30)  # killed after start_s, reported and replaced
        assert not first.is_alive() and alarms[0][0] == "centre-process"
        await svc.stop()

    asyncio.run(main())


def test_delivering_lasts_from_an_epochs_first_vrs_group_to_its_last(recorded):
    """What the onboard trains on the loop wait for: the caster writing an epoch's VRS (its groups arrive
    one message each, the last flagged) to every client; then `on_written` runs."""
    world, _, stations = recorded
    check = world.receivers[world.receiver_ids.index("check1")].ecef[0]

    async def main():
        written = []
        svc, _, _ = _service(world, stations, on_written=written.append)
        got = {cid: bytearray() for cid in ("VRS/1", "VRS/2")}
        for cid, sink in got.items():
            svc.open(cid, "VRS", _fix(check), sink.extend)
        t = world.t0 + 5.0
        assert not svc.delivering()
        svc._on_message(VrsGroup(t, ["VRS/1"], [b"one"], time.time(), None, None, False))
        assert svc.delivering() and got["VRS/1"] == b"one" and not got["VRS/2"]
        await asyncio.sleep(0.01)
        assert written == [] and svc.delivering()
        svc._on_message(VrsGroup(t, ["VRS/2"], [b"two"], time.time(), None, None, True))
        assert not svc.delivering() and got["VRS/2"] == b"two"
        await asyncio.sleep(0.01)
        assert written == [t]
        assert svc.timings.stages[-1][1] == 2  # one epoch of two sessions in the figures
        # an epoch whose last group never comes does not hold the others for ever
        svc._on_message(VrsGroup(t + 1.0, ["VRS/1"], [b"three"], time.time(), None, None, False))
        assert svc.delivering()
        svc._delivering_since -= MAX_DELIVERY_S + 0.1  # as if that long had passed
        assert not svc.delivering()

    asyncio.run(main())


def test_stations_join_move_and_leave_the_running_centre_and_a_restart_keeps_them(recorded):
    """The registry's changes (`station_membership.py`) reach the centre process; a bad one is refused on the
    loop side (ValueError, nothing sent); a replaced centre is built with the stations as they are now."""
    world, streams, stations = recorded
    names = sorted(stations)
    leaving = names[-1]

    async def main():
        svc, epochs, alarms = _service(world, stations)
        await svc.start()
        await _feed(svc, streams, stations, range(0, 3), 0.05)
        await _until(lambda: len(epochs) >= 2 and leaving in epochs[-1].network.stations)
        with pytest.raises(ValueError, match="already"):
            svc.add_station(names[0], stations[names[0]])
        with pytest.raises(ValueError, match="surface"):
            svc.move_station(names[0], (1.0, 2.0, 3.0))
        svc.remove_station(leaving)
        assert leaving not in svc.stations
        await _feed(svc, streams, stations, range(3, 6), 0.05)  # its bytes are no longer read
        await _until(lambda: len(epochs) >= 5 and leaving not in epochs[-1].network.stations)
        assert all(leaving not in b for b in epochs[-1].network.baselines)
        assert svc.errors == 0
        first = svc._proc
        first.kill()  # the replacement is built without the station that left
        await _until(lambda: svc.alive and svc._proc is not first)
        n = len(epochs)
        await _feed(svc, streams, stations, range(0, 4), 0.05)  # a fresh centre: the navigation data again
        await _until(lambda: len(epochs) >= n + 2)
        assert leaving not in epochs[-1].network.stations
        svc.add_station(leaving, stations[leaving])  # and it joins again
        await _feed(svc, streams, stations, range(4, EPOCHS), 0.05)
        await _until(lambda: leaving in epochs[-1].network.stations)
        assert svc.errors == 1  # the killed centre only
        await svc.stop()

    asyncio.run(main())
