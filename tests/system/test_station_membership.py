"""The running network's stations follow the store's registry (`augnet.system.station_membership`, issue 19):
the plan from running to registry, its application to the centre and the caster's taps, a refused step
retried, and the triggers (a console poke from another thread, a bus event, the periodic reconcile)."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from augnet.bus.config_events import CasterChange, publish_change
from augnet.bus.inprocess import InProcessBus
from augnet.store import queries as q
from augnet.store.db import open_store
from augnet.system.persistence import StationRecord
from augnet.system.station_membership import MOVE_THRESHOLD_M, StationSync, plan_membership

XYZ = {"STA1": (4_789_000.0, 176_000.0, 4_195_000.0), "STA2": (4_797_000.0, 160_000.0, 4_187_000.0),
       "STA3": (4_770_000.0, 200_000.0, 4_210_000.0)}


def rec(code: str, xyz=None, enabled: bool = True, mountpoint: str | None = None) -> StationRecord:
    return StationRecord(code, xyz or XYZ[code], enabled, mountpoint or code, 100 + int(code[-1]))


class FakeCentre:
    """What StationSync drives of a CentreService: membership, enabled flags and the feed."""

    def __init__(self, codes, refuse: dict[str, int] | None = None):
        self.members = set(codes)
        self.disabled: set[str] = set()
        self.calls: list[tuple] = []
        self.fed: list[tuple[str, bytes]] = []
        self.refuse = dict(refuse or {})  # code -> how many more times its add is refused

    def add_station(self, code, xyz):
        if self.refuse.get(code, 0) > 0:
            self.refuse[code] -= 1
            raise ValueError(f"station {code}: refused")
        assert code not in self.members
        self.members.add(code)
        self.calls.append(("add", code, tuple(xyz)))

    def remove_station(self, code):
        self.members.remove(code)
        self.calls.append(("remove", code))

    def move_station(self, code, xyz):
        self.calls.append(("move", code, tuple(xyz)))

    def set_station_enabled(self, code, on):
        (self.disabled.discard if on else self.disabled.add)(code)
        self.calls.append(("enabled", code, on))

    def feed(self, code, data):
        self.fed.append((code, data))


class FakeCaster:
    def __init__(self, mounts):
        self.mounts = set(mounts)
        self.taps: dict[str, list] = {}

    def tap(self, mount, callback):
        if mount not in self.mounts:
            raise ValueError(f"cannot tap {mount!r}")
        self.taps.setdefault(mount, []).append(callback)
        return lambda: self.taps[mount].remove(callback)

    def send(self, mount, data):
        for cb in list(self.taps.get(mount, [])):
            cb(data)


def test_the_plan_removes_first_then_moves_adds_flags_and_mountpoints():
    running = {"STA1": rec("STA1"), "STA2": rec("STA2")}
    registry = {"STA1": rec("STA1", (XYZ["STA1"][0] + 0.02, *XYZ["STA1"][1:]), enabled=False, mountpoint="M1"),
                "STA3": rec("STA3", enabled=False)}
    plan = [(s.action, s.code) for s in plan_membership(running, registry)]
    assert plan == [("remove", "STA2"), ("move", "STA1"), ("add", "STA3"), ("disable", "STA1"),
                    ("disable", "STA3"), ("retap", "STA1")]
    assert plan_membership(registry, registry) == []
    nudged = {"STA1": rec("STA1", (XYZ["STA1"][0] + MOVE_THRESHOLD_M / 2, *XYZ["STA1"][1:]))}
    assert plan_membership({"STA1": rec("STA1")}, nudged) == []  # below the threshold: the same place


def test_apply_drives_the_centre_and_the_taps_and_retries_a_refused_step():
    centre = FakeCentre(["STA1", "STA2"], refuse={"STA3": 1})
    caster = FakeCaster(["STA1", "STA2"])
    sync = StationSync(centre, caster, sessions=None)
    sync.adopt({"STA1": rec("STA1"), "STA2": rec("STA2", enabled=False)})
    assert centre.disabled == {"STA2"}
    caster.send("STA1", b"a")
    assert centre.fed == [("STA1", b"a")]
    # STA2 leaves; STA3 joins (refused once by the centre), its mountpoint not yet in the caster
    registry = {"STA1": rec("STA1"), "STA3": rec("STA3")}
    done = sync.apply(registry)
    assert [(s.action, s.code) for s in done] == [("remove", "STA2")]
    assert sync.failures == 1 and "STA3" not in sync.running and caster.taps["STA2"] == []
    done = sync.apply(registry)  # the next reconcile: accepted; no mountpoint STA3 yet, so no data
    assert [(s.action, s.code) for s in done] == [("add", "STA3")] and "STA3" in centre.members
    caster.mounts.add("STA3")  # the operator adds its mountpoint: the next reconcile taps it
    assert sync.apply(registry) == []
    caster.send("STA3", b"b")
    assert centre.fed[-1] == ("STA3", b"b")
    # re-pointed to another mountpoint: the old tap is gone
    caster.mounts.add("STA3B")
    sync.apply({"STA1": rec("STA1"), "STA3": rec("STA3", mountpoint="STA3B")})
    caster.send("STA3", b"old")
    caster.send("STA3B", b"new")
    assert centre.fed[-1] == ("STA3", b"new") and ("STA3", b"old") not in centre.fed


@pytest.fixture
def store(tmp_path):
    sessions = open_store(f"sqlite:///{tmp_path / 'augnet.db'}")
    with sessions.begin() as s:
        for code in ("STA1", "STA2"):
            q.add_station(s, "seed", code, XYZ[code], 100 + int(code[-1]), code)
    return sessions


async def _until(cond, timeout: float = 10.0) -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError("timed out")
        await asyncio.sleep(0.01)


def test_a_console_poke_from_another_thread_applies_the_registry_at_once(store):
    """With the reconcile an hour away, only the poke can have applied the change (the console's routes run
    on a thread pool)."""

    async def main():
        centre = FakeCentre(["STA1", "STA2"])
        sync = StationSync(centre, FakeCaster(["STA1", "STA2", "STA3"]), store, reconcile_s=3600)
        sync.adopt(sync.read())
        await sync.start()
        with store.begin() as s:
            q.add_station(s, "ada", "STA3", XYZ["STA3"], 103, "STA3")
            q.delete_station(s, "ada", "STA1")
        t = threading.Thread(target=sync.poke)
        t.start()
        t.join()
        await _until(lambda: "STA3" in sync.running and "STA1" not in sync.running)
        assert centre.members == {"STA2", "STA3"} and sync.stats()["failures"] == 0
        assert {a.trigger for a in sync.applied} == {"change"}
        await sync.stop()

    asyncio.run(main())


def test_a_bus_event_applies_it_and_a_bad_event_is_counted(store):
    async def main():
        bus = InProcessBus()
        centre = FakeCentre(["STA1", "STA2"])
        sync = StationSync(centre, FakeCaster(["STA1", "STA2"]), store, bus=bus, reconcile_s=3600)
        sync.adopt(sync.read())
        await sync.start()
        with store.begin() as s:
            q.update_station(s, "ada", "STA2", enabled=False)
        await bus.publish("augnet.config.stations", b"not json")
        await publish_change(bus, CasterChange("station", "STA2", "disable"))
        await _until(lambda: centre.disabled == {"STA2"})
        assert sync.events == 2 and sync.bad_events == 1
        await sync.stop()
        await bus.close()

    asyncio.run(main())


def test_the_periodic_reconcile_catches_a_missed_change(store):
    async def main():
        centre = FakeCentre(["STA1", "STA2"])
        sync = StationSync(centre, FakeCaster(["STA1", "STA2"]), store, reconcile_s=0.05)
        sync.adopt(sync.read())
        await sync.start()
        with store.begin() as s:
            q.update_station(s, "ada", "STA1", x_m=XYZ["STA1"][0] + 1.0)
        await _until(lambda: ("move", "STA1", (XYZ["STA1"][0] + 1.0, *XYZ["STA1"][1:])) in centre.calls)
        assert sync.applied[-1].trigger == "reconcile"
        await sync.stop()

    asyncio.run(main())
