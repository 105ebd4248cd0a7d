"""`augnet up demo` end to end, as an operator and an integrator would meet it.

One real run (a subprocess, real sockets, the real clock) is shared by the tests of this module:
  * while it runs: the console answers with the trains and the network, the caster's sourcetable lists
    the VRS mountpoint (curl), and RTKLIB's rtkrcv - a receiver nobody here wrote - rides as a third
    train: rover stream `TRAIN-G101-RAW`, base from our VRS mountpoint with its GGA upload, and fixes;
  * after `--duration` ends it: both trains hold an RTK fix (the must-show: within 5 minutes), the run
    report and the store say what happened.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from tests.conftest import REPO_ROOT, require_tool

pytestmark = [pytest.mark.slow, pytest.mark.system]

RUN_S = 240.0  # the system's run: both trains fix well within it (TTFF 25-50 s); rtkrcv fixes 20-24 solutions
# after our VRS first carries observations (~30 s after the start) and holds it: >= 150 solutions to judge by
# A hang guard, not the start-up goal (console URL within a minute, issue 8): `augnet bench up` measures
# and judges the start-up time; a guard twice the goal keeps a loaded machine from failing a sound start.
START_TIMEOUT_S = 120.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def up_run(tmp_path_factory):
    work = tmp_path_factory.mktemp("up")
    caster_port, console_port = _free_port(), _free_port()
    cmd = [sys.executable, "-m", "augnet", "up", "demo", "--duration", str(RUN_S), "--no-view",
           "--db", f"sqlite:///{work / 'augnet.db'}", "--caster-port", str(caster_port),
           "--console-port", str(console_port), "--state", str(work / "state.json"),
           "--report", str(work / "report.json")]
    env = dict(os.environ, PYTHONUNBUFFERED="1")  # `augnet up` sets its own BLAS threads
    log = open(work / "up.log", "w")
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=work, stdout=log, stderr=subprocess.STDOUT, env=env)
    state_file = work / "state.json"
    while not state_file.exists():
        if proc.poll() is not None or time.monotonic() - t0 > START_TIMEOUT_S:
            proc.kill()
            pytest.fail(f"augnet up did not start: {(work / 'up.log').read_text()[-2000:]}")
        time.sleep(0.2)
    state = json.loads(state_file.read_text())
    info = {"work": work, "proc": proc, "state": state, "caster_port": caster_port,
            "console_port": console_port, "started": t0}
    yield info
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    log.close()


def _finished(up_run) -> dict:
    proc = up_run["proc"]
    try:
        proc.wait(RUN_S + 120)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("augnet up did not stop by itself after --duration")
    out = (up_run["work"] / "up.log").read_text()
    assert proc.returncode == 0, out[-3000:]
    return json.loads((up_run["work"] / "report.json").read_text())


def test_console_url_printed(up_run, rtkrcv_live):  # rtkrcv starts riding now
    assert up_run["state"]["console_url"] == f"http://127.0.0.1:{up_run['console_port']}/"
    log = (up_run["work"] / "up.log").read_text()
    assert f"console: http://127.0.0.1:{up_run['console_port']}/" in log
    state = up_run["state"]  # the secrets are in the 0600 state file, not on stdout (issue 19)
    assert state["admin_password"] not in log and state["admin_token"] not in log
    store_files = sorted(up_run["work"].glob("augnet.db*"))  # the database, its -wal and -shm
    assert store_files and all(f.stat().st_mode & 0o777 == 0o600 for f in [up_run["work"] / "state.json", *store_files])


def test_console_and_caster_serve_while_it_runs(up_run):
    state = up_run["state"]
    base = state["console_url"].rstrip("/")
    headers = {"Authorization": f"Bearer {state['admin_token']}"}
    deadline = time.monotonic() + 60
    trains = []
    while time.monotonic() < deadline:
        r = httpx.get(f"{base}/api/trains", headers=headers, timeout=5)
        assert r.status_code == 200
        trains = r.json()
        if len(trains) == 2 and all(t["track_id"] for t in trains):
            break
        time.sleep(2)
    assert sorted(t["id"] for t in trains) == ["G101", "G303"]
    assert {t["track_id"] for t in trains} == {"L1-1", "L1-2"}  # G101 on track 1, G303 on track 2
    net = httpx.get(f"{base}/api/network", headers=headers, timeout=5).json()
    assert net["stations_total"] == 6
    assert httpx.get(f"{base}/api/trains", timeout=5).status_code == 401  # no token, no data
    assert "augnet" in httpx.get(f"{base}/metrics", headers=headers, timeout=5).text
    curl = require_tool("curl")
    table = subprocess.run([curl, "-s", "-H", "Ntrip-Version: Ntrip/2.0", f"http://127.0.0.1:{up_run['caster_port']}/"],
                           capture_output=True, timeout=20, text=True).stdout
    assert "STR;VRS;" in table and "STR;STA1;" in table and "ENDSOURCETABLE" in table


def test_many_trains_each_get_their_own_vrs_every_epoch(up_run):
    """`augnet loadtest trains` (the same code as the 2,000-train benchmark, here 40 trains for 8 s)."""
    from augnet.system.loadtest import run_trains

    # the VRS carries observations once the network has fixed ambiguities near the trains
    time.sleep(max(0.0, up_run["started"] + 100 - time.monotonic()))
    result = run_trains(up_run["state"], 40, 8, 1, "demo", warmup_s=5.0)
    assert result["connected"] == 40 and result["statuses"] == {"ICY 200 OK": 20, "HTTP/1.1 200 OK": 20}
    assert result["distinct_vrs_station_ids"] == 40 and result["station_ids_shared"] == 0  # its own VRS each
    assert result["epochs"] >= 6
    assert result["lost_epochs"] <= 0.05 * 40 * result["epochs"], result
    age = result["correction_age_ms"]
    assert 0 < age["p50"] < 1500 and age["p99"] < 3000, result  # MSM epoch times parsed, ages sane
    assert result["up_cpu_percent"] is not None


# Debian's RTKLIB 2.4.3 b34 rtkrcv opens an "ntripcli" input as FTP (its option table and its stream
# library number the stream types differently: the console shows "ftp error (11)"), so rtkrcv reads
# each mountpoint through RTKLIB's own str2str (an NTRIP client, serving the stream on a local TCP port)
# and `-b 1` relays what rtkrcv writes back (its GGA, inpstr2-nmeareq=single) up to our caster.
# misc-timeinterp stays off (RTKLIB's default): its time interpolation of the base ("for post-processing"
# in rtkpos.c) keeps the last base epoch that arrived in step with a rover epoch and extrapolates from it
# with the base position of now. Our VRS reaches rtkrcv ~0.1-0.3 s after the rover's epoch, so rtkrcv pairs
# nearly every rover epoch with the VRS of one second before (age 1 s), and each time the VRS point moves
# with the train (at most every 10 s) the stale epoch, computed at the new position, puts DD residuals of
# 30-380 m on every satellite, decaying as 1/age for up to a minute: 1,200-1,800 outliers per 200 s run
# with it on, none with it off (2026-11-22, RTKLIB 2.4.3 trace level 2). A base one second old needs no
# interpolation: rtkrcv evaluates the satellites at the base's own epoch.
RTKRCV_CONF = """\
inpstr1-type       =tcpcli
inpstr2-type       =tcpcli
inpstr1-path       =127.0.0.1:{rover_port}
inpstr2-path       =127.0.0.1:{base_port}
inpstr1-format     =rtcm3
inpstr2-format     =rtcm3
inpstr2-nmeareq    =single
outstr1-type       =file
outstr1-path       ={out}
outstr1-format     =llh
pos1-posmode       =kinematic
pos1-frequency     =l1+2+3
pos1-soltype       =forward
pos1-elmask        =15
pos1-navsys        =41
pos1-ionoopt       =brdc
pos1-tropopt       =saas
pos2-armode        =fix-and-hold
pos2-arthres       =3
pos2-arlockcnt     =20
ant2-postype       =rtcm
misc-timeinterp    =off
"""


@pytest.fixture(scope="module")
def rtkrcv_live(up_run):
    """RTKLIB rtkrcv as a third train on G101's receiver, started as soon as the system is up."""
    rtkrcv, str2str = shutil.which("rtkrcv"), shutil.which("str2str")
    if not rtkrcv or not str2str:
        yield None
        return
    work, state = up_run["work"], up_run["state"]
    user, password, port = state["caster"]["user"], state["caster"]["password"], up_run["caster_port"]
    sol = work / "rtkrcv.pos"
    rover_port, base_port = _free_port(), _free_port()
    procs = [
        subprocess.Popen([str2str, "-in", f"ntrip://{user}:{password}@127.0.0.1:{port}/TRAIN-G101-RAW",
                          "-out", f"tcpsvr://:{rover_port}"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL),
        subprocess.Popen([str2str, "-in", f"ntrip://{user}:{password}@127.0.0.1:{port}/VRS",
                          "-out", f"tcpsvr://:{base_port}", "-b", "1"], stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL),
    ]
    conf = work / "rtkrcv.conf"
    conf.write_text(RTKRCV_CONF.format(rover_port=rover_port, base_port=base_port, out=sol))
    console = _free_port()
    # its console on a TCP port (it crashes without a terminal otherwise); "start" begins processing
    procs.append(subprocess.Popen([rtkrcv, "-p", str(console), "-w", "", "-o", str(conf)], cwd=work,
                                  stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    started = False
    for _ in range(50):
        try:
            with socket.create_connection(("127.0.0.1", console), timeout=5) as con:
                con.sendall(b"start\r\n")
                time.sleep(0.5)
            started = True
            break
        except OSError:
            time.sleep(0.2)
    live = {"sol": sol, "procs": procs, "started": started, "rows": None}
    yield live
    _stop(procs)


def _stop(procs) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def _rtkrcv_rows(live, up_run) -> list[list[str]]:
    """rtkrcv's solutions over the run (waits for the run's end the first time)."""
    if live is None:
        pytest.skip("RTKLIB rtkrcv / str2str not installed (make test installs rtklib)")
    if live["rows"] is None:
        time.sleep(max(0.0, up_run["started"] + RUN_S - 5 - time.monotonic()))
        _stop(live["procs"])
        text = live["sol"].read_text() if live["sol"].exists() else ""
        live["rows"] = [ln.split() for ln in text.splitlines() if ln and not ln.startswith("%") and len(ln.split()) > 6]
    return live["rows"]


def test_rtkrcv_rides_as_a_train_on_our_streams(rtkrcv_live, up_run):
    """rtkrcv decodes the train's raw stream and our VRS (obtained with its own GGA) into RTK solutions."""
    assert rtkrcv_live is None or rtkrcv_live["started"], "rtkrcv's console never answered"
    rows = _rtkrcv_rows(rtkrcv_live, up_run)
    rtk = [r for r in rows if r[5] in ("1", "2")]  # Q: 1 fix, 2 float
    assert len(rows) >= 60, f"rtkrcv wrote {len(rows)} solutions"
    assert len(rtk) >= 0.5 * len(rows), f"only {len(rtk)} of {len(rows)} solutions are RTK"
    assert max(int(r[6]) for r in rtk) >= 8  # satellites with both rover and VRS data


def test_rtkrcv_fixes_on_our_vrs(rtkrcv_live, up_run):
    """RTKLIB's own real-time engine reaches a fix on our VRS (fix-and-hold, ratio 3, 20-epoch lock: RTKLIB
    2.4.3 has no partial ambiguity resolution, so a satellite the VRS adds must wait before it joins).
    Measured 2026-11-22 under three skies (clock faked to 03:00, 05:00, 07:00 UTC) and the real one (09:00),
    on a machine at load average 3-5: first fix after 20-24 solutions, then fixed in every epoch. With
    misc-timeinterp on (see RTKRCV_CONF) the same skies lost the fix for up to 72 epochs, and two of four
    full-suite CI runs of the day before never fixed."""
    q = [r[5] for r in _rtkrcv_rows(rtkrcv_live, up_run)]
    first = q.index("1") if "1" in q else len(q)
    print(f"rtkrcv: {q.count('1')} fixed of {len(q)}, first fix after {first} solutions")
    assert "1" in q, f"rtkrcv never fixed: {q.count('2')} float of {len(q)}"
    assert q[first:].count("1") >= 0.9 * len(q[first:]), f"rtkrcv lost its fix: {q.count('1')} fixed of {len(q)}"


def test_both_trains_hold_a_fix_and_the_run_is_reported(up_run):
    report = _finished(up_run)
    assert set(report["trains"]) == {"G101", "G303"}
    for tid, tr in report["trains"].items():
        assert tr["holds_fix"], (tid, tr)
        assert tr["time_to_first_fix_s"] is not None and tr["time_to_first_fix_s"] < 300, (tid, tr)
        assert tr["errors"] == 0
        assert tr["vrs_epochs"] > 0.5 * tr["epochs"]
    assert report["network_epochs"] >= 0.6 * RUN_S
    assert report["centre_errors"] == 0
    assert report["rbc"]["link_up"] and report["rbc"]["rbc_fresh"]
    assert report["store"]["failures"] == 0


def test_the_atp_simulators_receive_the_timer_passages_in_order(up_run):
    """Issue 15: in `augnet up` the timer-based virtual balise passages reach each train's ATP simulator over
    RSSP-I, in order and acknowledged, and report.json lists them with their error against the truth."""
    report = _finished(up_run)
    total = 0
    for tid, tr in report["trains"].items():
        timed, atp = tr["timed_balises"], tr["atp"]
        sent = timed["passages"]
        got = atp["telegrams_received"]
        assert [t["group"] for t in got] == [p["group"] for p in sent], (tid, timed, atp)
        assert [t["time_ms"] for t in got] == [round(p["time_gpst"] * 1000) for p in sent]
        chain = [t["chainage_mm"] for t in got]
        assert chain == sorted(chain, reverse=tid == "G303")  # G303 runs towards decreasing km
        assert atp["link_up"] and atp["unacknowledged"] == 0 and atp["atp_alarms"] == []
        for p in sent:
            assert p["error_m"] is not None and abs(p["error_m"]) <= 0.5, (tid, p)  # issue 15 must-show
            assert p["emitted_at_gpst"] >= p["time_gpst"]  # never before the predicted moment
        total += len(sent)
    assert total >= 3


def test_the_store_holds_the_run(up_run):
    _finished(up_run)
    db = sqlite3.connect(up_run["work"] / "augnet.db")
    stations = {r[0] for r in db.execute("select code from stations")}
    assert stations == {"STA1", "STA2", "STA3", "STA4", "OFF1", "OFF2"}
    mounts = {r[0]: r[1] for r in db.execute("select name, kind from mountpoints")}
    assert mounts["VRS"] == "vrs" and mounts["TRAIN-G101-RAW"] == "source"
    hashes = [r[0] for r in db.execute("select password_hash from caster_users")]
    assert hashes and all(h.startswith("scrypt$") for h in hashes)  # hashed, never the password
    sessions = list(db.execute("select t.code, s.ended_at, s.fix_rate, s.bytes_sent from train_sessions s "
                               "join trains t on t.id = s.train_id"))
    assert {s[0] for s in sessions} == {"G101", "G303"}
    assert all(s[1] is not None and s[3] > 0 for s in sessions)
    n_quality = db.execute("select count(*) from quality_history").fetchone()[0]
    assert n_quality >= len(stations)  # a row per baseline every 10 s
    subjects = {r[0] for r in db.execute("select distinct subject from quality_history")}
    assert {"network:correction_age_p99_s", "trains:fixed", "trains:reporting",
            "station:STA1:data_age_s"} <= subjects  # the charts' series at the same cadence (decision 0185)


def test_the_section_register_follows_the_trains_and_reaches_the_rbc(up_run):
    """Train information per section (issue 16): each train's position reports reach the centre, which
    keeps every train in one place (a section's queue or a station), sends each section's picture to the
    RBC over RSSP-I (SECTION_TRAINS) and stores it."""
    report = _finished(up_run)
    sec = report["sections"]
    print(json.dumps({k: sec[k] for k in ("stats", "order", "in_station", "reports_sent")}))
    sent = sec["reports_sent"]
    assert set(sent) == {"G101", "G303"} and all(n > 0 for n in sent.values())
    assert sec["stats"]["reports"] >= 0.99 * sum(sent.values())  # loopback UDP: none lost
    assert not [k for k in sec["stats"] if k.startswith("refused_")], sec["stats"]
    placed = [t for ids in sec["order"].values() for t in ids] + list(sec["in_station"])
    assert sorted(placed) == ["G101", "G303"]  # every train in exactly one place
    admitted = {e["train_id"] for e in sec["events"] if e["action"] == "admit"}
    assert admitted == {"G101", "G303"}  # start of mission inside a section, once each
    n_sections = len({k.split()[0] for k in sec["order"]})
    assert report["rbc"]["section_trains"]["pictures"] == 2 * n_sections
    assert report["rbc"]["section_trains"]["trains"] >= 1
    db = sqlite3.connect(up_run["work"] / "augnet.db")
    stored = {r[0]: (r[1], r[2]) for r in db.execute("select train_code, section_id, direction from section_trains")}
    in_sections = {t: (int(k.split()[0]), k.split()[1]) for k, ids in sec["order"].items() for t in ids}
    assert stored == in_sections
    audits = {r[0] for r in db.execute("select target from audit_log where action = 'section.admit'")}
    assert audits and all(a.startswith("section ") for a in audits)
