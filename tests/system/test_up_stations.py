"""Issue 19 on a running `augnet up demo`: a station deleted in the console leaves the running network (its
baselines go, a `station-left` alarm is raised, the trains keep their fix) and one added through the API
joins it (its baselines come back and fix); each change audited once. Its own run: it changes the network."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import httpx
import pytest

from tests.system.test_up import START_TIMEOUT_S, _free_port

pytestmark = [pytest.mark.slow, pytest.mark.system]

RUN_S = 200.0
STATION = "STA4"
# a membership change is applied on the console's poke and shows in the next 1 Hz network epoch; the
# console's network view is refreshed with each epoch: a few seconds is a hang guard, the figure is printed
APPLY_TIMEOUT_S = 10.0
FIX_TIMEOUT_S = 150.0  # the rejoined station's baselines fix again (the demo's first fixes take 25-60 s)


@pytest.fixture(scope="module")
def up(tmp_path_factory):
    work = tmp_path_factory.mktemp("up-stations")
    console_port = _free_port()
    cmd = [sys.executable, "-m", "augnet", "up", "demo", "--duration", str(RUN_S), "--no-view",
           "--db", f"sqlite:///{work / 'augnet.db'}", "--caster-port", str(_free_port()),
           "--console-port", str(console_port), "--state", str(work / "state.json"),
           "--report", str(work / "report.json")]
    log = open(work / "up.log", "w")
    proc = subprocess.Popen(cmd, cwd=work, stdout=log, stderr=subprocess.STDOUT,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    t0 = time.monotonic()
    while not (work / "state.json").exists():
        if proc.poll() is not None or time.monotonic() - t0 > START_TIMEOUT_S:
            proc.kill()
            pytest.fail(f"augnet up did not start: {(work / 'up.log').read_text()[-2000:]}")
        time.sleep(0.2)
    state = json.loads((work / "state.json").read_text())
    yield {"work": work, "proc": proc, "base": state["console_url"].rstrip("/"),
           "headers": {"Authorization": f"Bearer {state['admin_token']}"}}
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    log.close()


def _wait(cond, timeout: float, what: str):
    t0 = time.monotonic()
    while True:
        got = cond()
        if got:
            return got, time.monotonic() - t0
        if time.monotonic() - t0 > timeout:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.1)


def test_a_deleted_station_leaves_and_a_re_added_one_joins_the_running_network(up):
    base, h = up["base"], up["headers"]

    def get(path):
        r = httpx.get(base + path, headers=h, timeout=5)
        assert r.status_code == 200, r.text
        return r.json()

    def baselines_with(code):
        return [b for b in get("/api/network/baselines") if code in (b["a"], b["b"])]

    def trains_fixed():
        trains = get("/api/trains")
        return len(trains) == 2 and all(t["fix_state"] == "fix" for t in trains)

    _wait(lambda: trains_fixed() and any(b["state"] == "fixed" for b in baselines_with(STATION)), 180,
          f"both trains fixed and a fixed baseline of {STATION}")
    st = get(f"/api/stations/{STATION}")

    r = httpx.delete(f"{base}/api/stations/{STATION}", headers=h, timeout=5)
    assert r.status_code == 204, r.text
    _, took = _wait(lambda: not baselines_with(STATION), APPLY_TIMEOUT_S, f"{STATION}'s baselines to go")
    print(f"{STATION} deleted: its baselines gone from the console after {took:.1f} s")
    alarms = _wait(lambda: [a for a in get("/api/alarms") if a["kind"] == "station-left"
                            and a["subject"] == STATION], APPLY_TIMEOUT_S, "the station-left alarm")[0]
    assert alarms[0]["severity"] == "warning"
    assert STATION not in {s["code"] for s in get("/api/stations")}
    time.sleep(5)
    assert trains_fixed()  # the network without it still serves the trains

    body = {"code": STATION, "name": st["name"], "lat_deg": st["lat_deg"], "lon_deg": st["lon_deg"],
            "h_m": st["h_m"], "rtcm_station_id": st["rtcm_station_id"], "mountpoint": st["mountpoint"]}
    r = httpx.post(f"{base}/api/stations", headers=h, json=body, timeout=5)
    assert r.status_code == 201, r.text
    _, took = _wait(lambda: baselines_with(STATION), APPLY_TIMEOUT_S, f"{STATION}'s baselines to come back")
    print(f"{STATION} re-added: its baselines back after {took:.1f} s")
    _, took = _wait(lambda: any(b["state"] == "fixed" for b in baselines_with(STATION)), FIX_TIMEOUT_S,
                    f"{STATION}'s baselines to fix again")
    print(f"{STATION} re-added: a baseline fixed after {took:.1f} s")
    assert trains_fixed()
    audit = [(e["action"], e["target"]) for e in get("/api/audit?limit=500") if e["target"] == STATION]
    assert audit.count(("station.delete", STATION)) == 1 and audit.count(("station.add", STATION)) == 2  # seed too
