"""Issue 19 on a running `augnet up demo`: a station deleted in the console leaves the running network (its
baselines go, a `station-left` alarm is raised, the trains keep their fix) and one added through the API
joins it (its baselines come back and fix); each change audited once. The trains keep their fix throughout: the
sessions a change re-homes hand their VRS phase over to the new master (decision 0223); a timeline of the trains'
states, sampled every TIMELINE_S, is printed on failure. Its own run: it changes the network."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import httpx
import pytest

from tests.system.test_up import START_TIMEOUT_S, _free_port

pytestmark = [pytest.mark.slow, pytest.mark.system]

# the test's waits add up to START_TIMEOUT_S + 180 + SETTLE_TIMEOUT_S + 4 x APPLY_TIMEOUT_S + 5 + FIX_TIMEOUT_S + HOLD_S at most
# (~530 s); 200 s ended the run during the test under CI load: the run must outlast the test (checked below)
RUN_S = 600.0
# the harsh demo's trains may flip fix/float in their first minute (their own announced slips): the test starts
# from a fix both trains have held this long, so that it measures the station's change, not a train's start
SETTLE_S = 30.0
SETTLE_TIMEOUT_S = 150.0
TIMELINE_S = 0.5  # the trains' states are sampled this often
# after the rejoined station's baselines fix, the trains are watched this long more: the sessions it is nearest
# to move to it once the network has its integers (vrs.choose_masters)
HOLD_S = 20.0
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


class Timeline:
    """The trains' states (id, fix state, km along the line) every TIMELINE_S, in a thread of its own."""

    def __init__(self, base: str, headers: dict, proc):
        self.base, self.headers, self.proc = base, headers, proc
        self.t0 = time.monotonic()
        self.samples: list[tuple[float, list]] = []
        self.marks: list[tuple[float, str]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                trains = httpx.get(self.base + "/api/trains", headers=self.headers, timeout=5).json()
                row = sorted((t["id"], t["fix_state"], t["along_km"]) for t in trains)
            except Exception as exc:  # noqa: BLE001 - the run ended or the console is busy: on the timeline
                row = [("-", f"error {type(exc).__name__}", None)]
            self.samples.append((time.monotonic() - self.t0, row))
            self._stop.wait(TIMELINE_S)

    def mark(self, what: str) -> None:
        self.marks.append((time.monotonic() - self.t0, what))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10)

    def since(self, t: float) -> list:
        return [(ts, row) for ts, row in self.samples if ts >= t]

    def text(self) -> str:
        events = sorted([(t, f"-- {w}") for t, w in self.marks]
                        + [(t, "  ".join(f"{i} {f} km {k}" for i, f, k in row)) for t, row in self.samples])
        lines, last = [], None
        for t, line in events:  # a line per change of the trains' fix states, and every mark
            state = " ".join(w for w in line.split() if not w.replace(".", "").isdigit())
            if line.startswith("--") or state != last:
                lines.append(f"{t:7.1f} s  {line}")
            if not line.startswith("--"):
                last = state
        return "\n".join(lines) + f"\n({len(self.samples)} samples, the last at {self.samples[-1][0]:.1f} s)"


def test_a_deleted_station_leaves_and_a_re_added_one_joins_the_running_network(up):
    timeline = Timeline(up["base"], up["headers"], up["proc"])
    try:
        _delete_and_re_add(up, timeline)
    finally:
        timeline.stop()
        print(timeline.text())


def _delete_and_re_add(up, timeline: Timeline):
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
    timeline.mark("both trains fixed")

    def held(now: float) -> bool:  # both trains fixed in every sample of the last SETTLE_S
        rows = timeline.since(now - SETTLE_S)
        return (bool(rows) and rows[0][0] <= now - SETTLE_S + 1.0
                and all(f == "fix" for _, row in rows for _, f, _ in row) and len(rows[-1][1]) == 2)

    _wait(lambda: held(time.monotonic() - timeline.t0), SETTLE_TIMEOUT_S, f"both trains to hold a fix {SETTLE_S:.0f} s")
    timeline.mark(f"both trains held their fix {SETTLE_S:.0f} s")
    t_fixed = time.monotonic() - timeline.t0
    st = get(f"/api/stations/{STATION}")

    r = httpx.delete(f"{base}/api/stations/{STATION}", headers=h, timeout=5)
    assert r.status_code == 204, r.text
    timeline.mark(f"{STATION} deleted")
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
    timeline.mark(f"{STATION} re-added")
    _, took = _wait(lambda: baselines_with(STATION), APPLY_TIMEOUT_S, f"{STATION}'s baselines to come back")
    print(f"{STATION} re-added: its baselines back after {took:.1f} s")
    _, took = _wait(lambda: any(b["state"] == "fixed" for b in baselines_with(STATION)), FIX_TIMEOUT_S,
                    f"{STATION}'s baselines to fix again")
    print(f"{STATION} re-added: a baseline fixed after {took:.1f} s")
    timeline.mark(f"{STATION}'s baselines fixed")
    time.sleep(HOLD_S)
    timeline.mark("end of the watch")
    assert up["proc"].poll() is None, "the run ended during the test: RUN_S too short"
    assert trains_fixed()
    # every sample from the trains' first fix through both changes: both trains fixed
    lost = [(round(t, 1), row) for t, row in timeline.since(t_fixed)
            if len(row) != 2 or any(fix != "fix" for _, fix, _ in row)]
    assert not lost, f"the trains lost their fix: {lost[:5]} ... ({len(lost)} samples)"
    audit = [(e["action"], e["target"]) for e in get("/api/audit?limit=500") if e["target"] == STATION]
    assert audit.count(("station.delete", STATION)) == 1 and audit.count(("station.add", STATION)) == 2  # seed too
