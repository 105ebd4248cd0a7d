"""The 4001 correction-error bound, opted into per mountpoint in the store (issue 15, decision 0281): the
centre service (its own process), a caster built from the store with two VRS mountpoints served by it, the
store's sync and the console app on one event loop (as `augnet up` runs them), real loopback sockets.

An operator turns `correction_bound` on for one mountpoint through the console API: an NTRIP client already
reading it starts receiving 4001 frames (pyrtcm parses them, our decoder reads them) without any restart;
a client of the other mountpoint gets exactly the message types it got before, never a 4001. Audited once."""

from __future__ import annotations

import asyncio
import threading
import time
from concurrent.futures import Future

import httpx
import numpy as np
import pytest
import uvicorn
from pyrtcm import RTCMReader
from sqlalchemy import select

from augnet.bus import InProcessBus
from augnet.console.app import create_app
from augnet.console.live import LiveState
from augnet.gnss.geometry import ecef_to_geodetic
from augnet.gnss.rtcm import RtcmStreamReader
from augnet.gnss.rtcm.correction_bound import CORRECTION_BOUND_MESSAGE, decode_correction_bound
from augnet.store import open_store
from augnet.store import queries as q
from augnet.store.models import AuditEntry, Role
from augnet.system import persistence
from augnet.system.caster_access import CasterAccessSync, caster_tables
from augnet.system.centre_service import CentreService, CentreSpec
from augwire.passwords import hash_password
from ntrip_caster.auth import User
from ntrip_caster.config import CasterConfig, Limits, MountConfig
from ntrip_caster.gga import format_gga
from ntrip_caster.server import Caster
from tests.centre.simdata import recorded_streams
from tests.ntrip.helpers import FAST, TRAIN_PW, open_client

pytestmark = pytest.mark.slow

EPOCHS = 20
BEFORE = 8  # epochs fed before the operator's change
DEADLINE_S = 30.0  # stops a hang only
ADMIN, ADMIN_PW = "ada", "admin-secret"
VRS_FACTORY = "augnet.system.centre_service:CentreService"  # not imported: the factories are given by name


def _seed() -> CasterConfig:
    users = {"train1": User("train1", hash_password(TRAIN_PW, **FAST), frozenset({"trains"}))}
    mounts = tuple(MountConfig(name, "vrs", frozenset({"trains"}), frozenset(), {"identifier": name}, VRS_FACTORY)
                   for name in ("VRS", "VRSB"))
    return CasterConfig(host="127.0.0.1", port=0, limits=Limits(), users=users, mounts=mounts)


class _Reader(threading.Thread):
    """An NTRIP 1.0 client with its GGA: every byte it reads, with the reading clock."""

    def __init__(self, port: int, mount: str, gga: bytes):
        super().__init__(daemon=True)
        self.sock, self.head = open_client(port, mount, version=1, gga=gga)
        self.data = bytearray()
        self.marks: list[tuple[float, int]] = []  # (monotonic time, bytes so far)
        self.lock = threading.Lock()

    def run(self) -> None:
        self.sock.settimeout(0.5)
        while True:
            try:
                chunk = self.sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            if not chunk:
                return
            with self.lock:
                self.data += chunk

    def take(self) -> bytes:
        with self.lock:
            return bytes(self.data)


def _types(data: bytes) -> list[int]:
    reader = RtcmStreamReader()
    return [f.msg_type for f in reader.feed(data) + reader.close()]


def _until(pred, what: str) -> None:
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > DEADLINE_S:
            raise AssertionError(f"{what}: not within {DEADLINE_S} s")
        time.sleep(0.05)


def test_the_bound_is_switched_on_per_mountpoint_through_the_console_without_restart(tmp_path):
    world, streams, stations = recorded_streams(EPOCHS)
    sessions = open_store(f"sqlite:///{tmp_path / 'augnet.db'}")
    seed = _seed()
    with sessions.begin() as s:
        persistence.seed_caster(s, seed)
        op = q.add_operator(s, "fixture", ADMIN, hash_password(ADMIN_PW, **FAST), Role.ADMIN)
        token = q.issue_token(s, op)
    with sessions() as s:
        assert [mp.correction_bound for mp in q.list_mountpoints(s)] == [False, False]  # default off
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    epochs: list = []
    parts: dict = {}

    def call(coro, timeout: float = 60.0):
        return asyncio.run_coroutine_threadsafe(coro, loop).result(timeout)

    def on_loop(fn):
        fut: Future = Future()
        loop.call_soon_threadsafe(lambda: fut.set_result(fn()))
        return fut.result(10)

    async def start():
        bus = InProcessBus()
        spec = CentreSpec({k: tuple(map(float, v)) for k, v in stations.items()}, world.t0, "test")
        svc = CentreService(spec, loop, on_epoch=lambda r, at: epochs.append(r))
        await svc.start()
        described = {m.name: m for m in seed.mounts}
        with sessions() as s:
            users, mounts = caster_tables(s, described)
        caster = Caster(CasterConfig(host="127.0.0.1", port=0, limits=Limits(), users=users, mounts=tuple(mounts)),
                        {"VRS": svc, "VRSB": svc})
        port = await caster.start()
        sync = CasterAccessSync(caster, sessions, described, bus, reconcile_s=600.0,
                                on_bound_mounts=svc.set_bound_mounts)
        await sync.start()
        server = uvicorn.Server(uvicorn.Config(create_app(sessions, LiveState(), bus=bus), host="127.0.0.1", port=0,
                                               log_level="warning", lifespan="off", access_log=False))
        server.install_signal_handlers = lambda: None
        serving = asyncio.ensure_future(server.serve())
        while not server.started:
            await asyncio.sleep(0.02)
        parts.update(bus=bus, svc=svc, caster=caster, port=port, sync=sync, server=server, serving=serving,
                     console=server.servers[0].sockets[0].getsockname()[1])

    async def feed(rng):
        for e in rng:
            for name in stations:
                parts["svc"].feed(name, streams.epoch_bytes[name][e][1])
            await asyncio.sleep(0.05)

    async def stop():
        parts["server"].should_exit = True
        await parts["serving"]
        await parts["sync"].stop()
        await parts["caster"].stop()
        await parts["svc"].stop()
        await parts["bus"].close()

    call(start())
    try:
        check = world.receivers[world.receiver_ids.index("check1")].ecef[0]
        lat, lon, h = ecef_to_geodetic(np.asarray(check, float))
        gga = format_gga(float(np.degrees(lat)), float(np.degrees(lon)), float(h))
        readers = {m: _Reader(parts["port"], m, gga) for m in ("VRS", "VRSB")}
        for r in readers.values():
            assert r.head.startswith(b"ICY 200"), r.head
            r.start()
        _until(lambda: on_loop(lambda: len(parts["svc"]._sinks)) == 2, "both VRS sessions open")
        call(feed(range(0, BEFORE)))
        _until(lambda: len(epochs) >= BEFORE - 1, "epochs before the change")
        _until(lambda: all(1006 in _types(r.take()) for r in readers.values()), "VRS before the change")
        time.sleep(0.3)
        before = {m: len(r.take()) for m, r in readers.items()}
        types_before = {m: set(_types(r.take())) for m, r in readers.items()}
        assert all(CORRECTION_BOUND_MESSAGE not in t for t in types_before.values())  # off: no 4001 anywhere

        api = httpx.Client(base_url=f"http://127.0.0.1:{parts['console']}/api",
                           headers={"Authorization": f"Bearer {token}"}, timeout=10.0)
        with api:
            r = api.patch("/caster/mountpoints/VRS", json={"correction_bound": True})
            assert r.status_code == 200, r.text
            assert r.json()["correction_bound"] is True
            listed = {m["name"]: m["correction_bound"] for m in api.get("/caster/mountpoints").json()}
            assert listed == {"VRS": True, "VRSB": False}
        _until(lambda: on_loop(lambda: parts["sync"].bound) == frozenset({"VRS"}), "the change applied")
        assert on_loop(lambda: parts["svc"].bound_mounts) == frozenset({"VRS"})
        call(feed(range(BEFORE, EPOCHS)))
        _until(lambda: len(epochs) >= EPOCHS - 1, "epochs after the change")
        time.sleep(0.5)
        after = {m: r.take()[before[m]:] for m, r in readers.items()}
        # the opted-in mountpoint's client now gets a 4001 with every VRS epoch (none before the change)
        reader = RtcmStreamReader()
        frames = reader.feed(readers["VRS"].take()) + reader.close()
        bound = [f for f in frames if f.msg_type == CORRECTION_BOUND_MESSAGE]
        msm = [f for f in frames if f.msg_type in (1077, 1087, 1097, 1127)]
        assert len(bound) >= EPOCHS - BEFORE - 2
        assert {RTCMReader.parse(f.raw).identity for f in bound} == {str(CORRECTION_BOUND_MESSAGE)}
        msgs = [decode_correction_bound(f.payload) for f in bound]
        assert all(m.sats for m in msgs) and len({m.epoch_ms for m in msgs}) == len(msgs)  # one per epoch
        assert CORRECTION_BOUND_MESSAGE in _types(after["VRS"]) and len(msm) > len(bound)
        # the other mountpoint's client: the same message types as before the change, never a 4001
        assert CORRECTION_BOUND_MESSAGE not in _types(readers["VRSB"].take())
        assert set(_types(after["VRSB"])) <= types_before["VRSB"] and after["VRSB"]
        for r in readers.values():
            r.sock.close()
    finally:
        call(stop())
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)
    with sessions() as s:
        edits = [(e.actor, e.action, e.target, e.detail) for e in s.scalars(select(AuditEntry)) if e.actor == ADMIN]
    assert edits == [(ADMIN, "mountpoint.edit", "VRS",
                      {"before": {"correction_bound": False}, "after": {"correction_bound": True}})]
