"""The page in a real browser (Debian's headless chromium driven by selenium): it loads, trains move on the
line diagram, acknowledging an alarm updates the page and the audit log; the history charts, the map and an
alarm the RBC raises (issue 19)."""

from __future__ import annotations

import datetime as dt
import math
import re
import shutil
import threading
from types import SimpleNamespace as NS

import pytest

from augnet.console.app import create_app
from augnet.console.live import BaselineLive, LiveState, StationLive, TrainLive
from augnet.console.server import ConsoleThread
from augnet.store import queries as q
from augnet.store.models import AlarmState, Severity
from augnet.system import persistence
from augnet.system.history_series import series_values
from augnet.system.live_state import LivePublisher
from augnet.system.rbc_link import RbcConnection, SectionPlan
from augnet.system.runtime import System
from augnet.system.train_alarms import TrainCorrectionWatch
from rssp1.messages import AlarmCode

from tests.console.conftest import add_accounts
from tests.console.helpers import PASSWORDS

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="Debian chromium and chromium-driver not installed (apt-get install chromium chromium-driver)")

WAIT_S = 20.0  # page loads, websocket connects, alarm poll (2 s) on a loaded 2-core machine
TRAIN_STEP_S = 0.2
TRAIN_SPEED_KM_PER_STEP = 0.4
LINE = {"id": "L1", "length_km": 96.4, "polyline": [[30.0, 114.0], [30.0, 115.0]]}


@pytest.fixture
def driver(tmp_path):
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1280,1000", f"--user-data-dir={tmp_path / 'chromium-profile'}"):
        options.add_argument(arg)
    d = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    yield d
    d.quit()


def attribute(driver, selector: str, name: str) -> str | None:
    """One attribute read inside the page (the diagram re-renders often: element handles go stale)."""
    return driver.execute_script("const e = document.querySelector(arguments[0]);"
                                 "return e ? e.getAttribute(arguments[1]) : null;", selector, name)


def text(driver, selector: str) -> str:
    """An element's text with its cells joined by single spaces ('' when absent)."""
    return driver.execute_script("const e = document.querySelector(arguments[0]);"
                                 "return e ? e.innerText.replace(/\\s+/g, ' ').trim() : '';", selector)


class MovingTrains:
    """The running system's stand-in for this test: a worker thread advancing trains along the line."""

    def __init__(self, live: LiveState) -> None:
        self.live = live
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.along = {"T1": 10.0, "T2": 70.0}

    def run(self) -> None:
        while not self.stop.wait(TRAIN_STEP_S):
            for tid, km in self.along.items():
                km = (km + TRAIN_SPEED_KM_PER_STEP) % LINE["length_km"]
                self.along[tid] = km
                self.live.update_train(TrainLive(tid, 30.0, 114.0 + km / LINE["length_km"], 20.0, "L1", km, 0.1,
                                                 "fix" if tid == "T1" else "float", 1.0, 0.15, 0.3, 120.0))


@pytest.mark.slow
def test_page_trains_move_and_acknowledge_updates_page_and_audit(driver, sqlite_sessions, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    live = LiveState()
    live.set_line(LINE)
    for code, km, up in (("STA1", 0.0, True), ("STA2", 48.2, True), ("STA3", 96.4, False)):
        live.update_station(StationLive(code, 100 + int(code[-1]), 30.0, 114.0 + km / 96.4, 20.0, km, up,
                                        True, 0.5, 20))
    live.set_baselines([BaselineLive("STA1", "STA2", 48.2, "fixed", 0.98, 1.0),
                        BaselineLive("STA2", "STA3", 48.2, "none", 0.0, None)])
    live.set_network({"master": "STA2", "quality": "ok", "excluded_satellites": ["G12"]})
    add_accounts(sqlite_sessions)
    trains = MovingTrains(live)
    wait = WebDriverWait(driver, WAIT_S)

    with ConsoleThread(create_app(sqlite_sessions, live)) as server:
        trains.thread.start()
        try:
            driver.get(server.url + "/")
            wait.until(lambda d: d.find_element(By.ID, "login-form").is_displayed())
            driver.find_element(By.ID, "login-name").send_keys("otto")
            driver.find_element(By.ID, "login-password").send_keys(PASSWORDS["otto"])
            driver.find_element(By.ID, "login-submit").click()

            # the page loads: stations, baselines coloured by state, the live feed over the websocket
            wait.until(lambda d: d.find_element(By.ID, "main").is_displayed())
            assert not driver.find_element(By.ID, "login").is_displayed()
            wait.until(lambda d: d.find_element(By.ID, "feed-status").text == "live")
            wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#layer-stations g.station")) == 3)
            assert attribute(driver, 'g[data-station="STA3"]', "class") == "station down"
            assert attribute(driver, 'g[data-station="STA1"]', "class") == "station up"
            assert attribute(driver, 'path[data-baseline="STA1-STA2"]', "class") == "baseline fixed"
            assert attribute(driver, 'path[data-baseline="STA2-STA3"]', "class") == "baseline none"

            # trains move on the diagram and in the table
            marker = 'g.train[data-train="T1"]'
            wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, marker))
            def position(d):  # the marker's transform and km, read together (renders run between reads)
                return d.execute_script(
                    "const g = document.querySelector(arguments[0]);"
                    "return [g.getAttribute('transform'), parseFloat(g.getAttribute('data-along-km'))];", marker)

            first_transform, first_km = position(driver)
            wait.until(lambda d: position(d)[1] > first_km)
            later_transform, later_km = position(driver)
            assert later_transform != first_transform
            x = [float(t.split("(")[1].split(",")[0]) for t in (first_transform, later_transform)]
            assert x[1] > x[0]  # moved right along the line
            assert attribute(driver, 'g.train[data-train="T2"]', "class") == "train float"
            # the train table shows the same km as the marker (both drawn in one frame from one state)
            table_km, marker_km = driver.execute_script(
                "return [document.querySelector('#trains tr[data-train=\"T1\"] td.num').textContent,"
                " document.querySelector(arguments[0]).getAttribute('data-along-km')];", marker)
            assert float(table_km) == float(marker_km) >= later_km

            # the system raises an alarm in the store; the page shows it; the operator acknowledges it
            with sqlite_sessions.begin() as s:
                alarm = q.raise_alarm(s, "satellite-excluded", "G12", Severity.CRITICAL, "clock step 30 m")
                s.flush()
                alarm_id = alarm.id
            button = f'button.ack[data-alarm="{alarm_id}"]'
            wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, button))
            driver.find_element(By.CSS_SELECTOR, button).click()
            row = f'#alarms tr[data-alarm="{alarm_id}"]'
            wait.until(lambda d: attribute(d, row, "data-state") == "acknowledged")
            assert not driver.find_elements(By.CSS_SELECTOR, button)
            assert text(driver, row + " td.alarm-state") == "acknowledged"
            wait.until(lambda d: "otto alarm.acknowledge alarm:" in text(d, "#audit tbody"))
            driver.save_screenshot(str(tmp_path / "console.png"))
        finally:
            trains.stop.set()
            trains.thread.join()

    with sqlite_sessions() as s:
        a = q.get_alarm(s, alarm_id)
        assert a.state is AlarmState.ACKNOWLEDGED and a.acknowledged_by == "otto"
        entry = next(e for e in q.audit_log(s) if e.action == "alarm.acknowledge")
        assert (entry.actor, entry.target) == ("otto", f"alarm:{alarm_id}")


@pytest.mark.slow
def test_page_from_a_bootstrap_link_obeys_its_csp_and_logout_keeps_the_token(driver, sqlite_sessions):
    """The page opened with the state file's `#token=` link: no Content-Security-Policy violation while it
    loads and goes live over the websocket; "Log out" revokes the page's own session token only."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    from augnet.console.security import ensure_admin

    boot = ensure_admin(sqlite_sessions, "admin", "admin-password")
    driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": (
        "window.__csp = []; document.addEventListener('securitypolicyviolation',"
        " e => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));")})
    wait = WebDriverWait(driver, WAIT_S)
    live = LiveState()
    live.set_line(LINE)
    with ConsoleThread(create_app(sqlite_sessions, live)) as server:
        driver.get(f"{server.url}/#token={boot.token}")
        wait.until(lambda d: d.find_element(By.ID, "main").is_displayed())
        wait.until(lambda d: d.find_element(By.ID, "feed-status").text == "live")
        assert "#token" not in driver.current_url  # dropped from the address bar
        page_token = driver.execute_script("return sessionStorage.getItem('augnet.token');")
        assert page_token and page_token != boot.token  # the page holds a session token of its own
        driver.find_element(By.ID, "logout").click()
        wait.until(lambda d: d.find_element(By.ID, "login").is_displayed())
        assert driver.execute_script("return window.__csp;") == []

        def me(token):
            with sqlite_sessions() as s:
                return q.operator_for_token(s, token)

        WebDriverWait(driver, WAIT_S).until(lambda d: me(page_token) is None)  # the page's token revoked
        assert me(boot.token).name == "admin"  # the bootstrap token still works


# --- the console an operator would trust (issue 19): history charts, the map, the RBC's alarms -------------

GEO_STATIONS = {  # code: (lat, lon); STA4 sits 200 m from STA1, so their labels must be moved apart
    "STA1": (30.0, 114.0), "STA2": (30.1, 114.5), "STA3": (30.0, 115.0), "STA4": (30.0018, 114.0),
}
GEO_TRAINS = {"T1": (30.02, 114.25), "T2": (30.05, 114.75)}
HISTORY_SAMPLES = 30  # at the system's 10 s cadence: five minutes, inside the page's 15 min window
HISTORY_STEP_S = 10
KM_PER_DEG_LAT = 6378.137 * 3.141592653589793 / 180  # the page's projection: WGS84 semi-major axis sphere


def seed_history(sessions, now: dt.datetime) -> None:
    """Five minutes of the quality history as `augnet up` records it: baselines, then the network series."""
    with sessions.begin() as s:
        for i in range(HISTORY_SAMPLES):
            at = (now - dt.timedelta(seconds=HISTORY_STEP_S * (HISTORY_SAMPLES - i))).replace(microsecond=0)
            persistence.record_quality_batch(
                s, at, [("STA1-STA2", 0.5 + i / 60, 0.01, 20), ("STA2-STA3", 0.9, 0.012, 18)],
                series_values([0.5 + 0.01 * i], ["fix", "fix", "float"],
                              {"STA1": 0.4 + 0.01 * i, "STA2": 0.6, "STA3": None}))


def svg_text(driver, selector: str) -> str:
    """An SVG element's text (SVG elements have no innerText)."""
    return driver.execute_script("const e = document.querySelector(arguments[0]);"
                                 "return e ? e.textContent : '';", selector)


def boxes(driver, selector: str) -> list[dict]:
    """Screen boxes of the elements matching selector (each with its text)."""
    return driver.execute_script(
        "return [...document.querySelectorAll(arguments[0])].map(e => { const r = e.getBoundingClientRect();"
        " return {x: r.left, y: r.top, w: r.width, h: r.height, text: e.textContent}; });", selector)


def overlapping(a: dict, b: dict) -> bool:
    return min(a["x"] + a["w"], b["x"] + b["w"]) > max(a["x"], b["x"]) and \
        min(a["y"] + a["h"], b["y"] + b["h"]) > max(a["y"], b["y"])


def assert_apart(items: list[dict], others: list[dict] = ()) -> None:
    for i, a in enumerate(items):
        assert a["w"] > 0 and a["h"] > 0, a
        for b in items[i + 1:]:
            assert not overlapping(a, b), (a, b)
        for b in others:
            assert not overlapping(a, b), (a, b)


@pytest.mark.slow
def test_page_shows_history_charts_map_and_an_rbc_alarm(driver, sqlite_sessions, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select, WebDriverWait

    live = LiveState()
    live.set_line({"id": "L1", "length_km": 96.4, "polyline": [[30.0, 114.0], [30.1, 114.5], [30.0, 115.0]]})
    for n, (code, (lat, lon)) in enumerate(GEO_STATIONS.items()):
        live.update_station(StationLive(code, 101 + n, lat, lon, 20.0, None, code != "STA3", True, 0.5, 20))
    live.set_baselines([BaselineLive("STA1", "STA2", 50.0, "fixed", 0.98, 1.0),
                        BaselineLive("STA2", "STA3", 50.0, "float", 0.2, None),
                        BaselineLive("STA1", "STA4", 0.2, "none", 0.0, None)])
    for tid, (lat, lon) in GEO_TRAINS.items():
        live.update_train(TrainLive(tid, lat, lon, 20.0, None, None, None, "fix" if tid == "T1" else "float"))
    seed_history(sqlite_sessions, dt.datetime.now(dt.timezone.utc))
    add_accounts(sqlite_sessions)
    wait = WebDriverWait(driver, WAIT_S)
    writer = persistence.StoreWriter(sqlite_sessions)
    driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": (
        "window.__csp = []; document.addEventListener('securitypolicyviolation',"
        " e => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));")})

    with ConsoleThread(create_app(sqlite_sessions, live)) as server:
        driver.get(server.url + "/")
        wait.until(lambda d: d.find_element(By.ID, "login-form").is_displayed())
        driver.find_element(By.ID, "login-name").send_keys("vera")
        driver.find_element(By.ID, "login-password").send_keys(PASSWORDS["vera"])
        driver.find_element(By.ID, "login-submit").click()
        wait.until(lambda d: d.find_element(By.ID, "feed-status").text == "live")

        # history: every series of the seeded history drawn, one point per sample in the 15 min window
        Select(driver.find_element(By.ID, "history-window")).select_by_value("900")
        wait.until(lambda d: attribute(d, '#chart-fixed_fraction g[data-series="STA1-STA2"]', "data-points")
                   == str(HISTORY_SAMPLES))
        for chart, subject in (("fixed_fraction", "STA2-STA3"), ("correction_age_p99", "network:correction_age_p99_s"),
                               ("trains", "trains:fixed"), ("trains", "trains:reporting"),
                               ("station_data_age", "station:STA1:data_age_s"),
                               ("station_data_age", "station:STA2:data_age_s")):
            group = f'#chart-{chart} g[data-series="{subject}"]'
            assert attribute(driver, group, "data-points") == str(HISTORY_SAMPLES), subject
            points = attribute(driver, group + " polyline", "points").split()
            assert len(points) == HISTORY_SAMPLES, subject  # no gap: one line
        assert not driver.find_elements(By.CSS_SELECTOR, '#chart-station_data_age g[data-series="station:STA3:data_age_s"]')
        rising = [tuple(map(float, p.split(","))) for p in
                  attribute(driver, '#chart-fixed_fraction g[data-series="STA1-STA2"] polyline', "points").split()]
        assert all(b[0] > a[0] for a, b in zip(rising, rising[1:]))  # time runs right
        assert rising[-1][1] < rising[0][1]  # a rising fixed fraction climbs on the screen
        trains_fixed = [float(p.split(",")[1]) for p in
                        attribute(driver, '#chart-trains g[data-series="trains:fixed"] polyline', "points").split()]
        trains_seen = [float(p.split(",")[1]) for p in
                       attribute(driver, '#chart-trains g[data-series="trains:reporting"] polyline', "points").split()]
        assert len(set(trains_fixed)) == 1 and trains_seen[0] < trains_fixed[0]  # 3 reporting above 2 fixed
        for chart in ("fixed_fraction", "correction_age_p99", "trains", "station_data_age"):
            ticks = boxes(driver, f"#chart-{chart} text.tick-x")
            assert len(ticks) >= 2 and all(re.fullmatch(r"\d\d:\d\d", t["text"]) for t in ticks), ticks
            assert_apart(ticks)
            assert_apart(boxes(driver, f"#chart-{chart} text.tick-y"))
            assert "time (UTC)" in svg_text(driver, f"#chart-{chart}")
        assert "fixed %" in svg_text(driver, "#chart-fixed_fraction")
        assert "age s" in svg_text(driver, "#chart-correction_age_p99")
        assert "STA1-STA2" in text(driver, "#legend-fixed_fraction")

        # the map: stations and trains where the projection puts them, baselines by fixed fraction
        wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#geo-stations g.geo-station")) == 4)
        wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#geo-trains g.geo-train")) == 2)

        def xy(selector):
            return tuple(float(attribute(driver, selector, k)) for k in ("data-x", "data-y"))

        st = {c: xy(f'#geo g.geo-station[data-station="{c}"]') for c in GEO_STATIONS}
        tr = {t: xy(f'#geo g.geo-train[data-train="{t}"]') for t in GEO_TRAINS}
        assert st["STA1"][0] < tr["T1"][0] < st["STA2"][0] < tr["T2"][0] < st["STA3"][0]  # west to east
        assert st["STA2"][1] < tr["T2"][1] < st["STA1"][1]  # north is up
        assert st["STA1"][1] == pytest.approx(st["STA3"][1], abs=0.1)
        # one scale in both directions, and the scale bar's: px per km from STA1-STA3 (east) and STA1-STA4 (north)
        scale = float(attribute(driver, "#geo g[data-scale-km]", "data-scale-px")) / \
            float(attribute(driver, "#geo g[data-scale-km]", "data-scale-km"))
        east_km = KM_PER_DEG_LAT * 1.0 * math.cos(math.radians(30.0))
        assert (st["STA3"][0] - st["STA1"][0]) / east_km == pytest.approx(scale, rel=1e-3)
        assert (st["STA1"][1] - st["STA4"][1]) / (KM_PER_DEG_LAT * 0.0018) == pytest.approx(scale, rel=0.02)
        assert attribute(driver, '#geo line[data-baseline="STA1-STA2"]', "stroke").startswith("hsl(118")
        assert attribute(driver, '#geo line[data-baseline="STA2-STA3"]', "stroke").startswith("hsl(24")
        assert attribute(driver, '#geo line[data-baseline="STA1-STA4"]', "class") == "geo-baseline none"
        assert svg_text(driver, "#geo g.north") == "N"
        labels = boxes(driver, "#geo-labels text")
        assert sorted(b["text"] for b in labels) == sorted([*GEO_STATIONS, *GEO_TRAINS])
        assert_apart(labels, boxes(driver, "#geo-stations polygon") + boxes(driver, "#geo-trains circle"))

        # the map follows the live feed: T1 moves east
        live.update_train(TrainLive("T1", 30.02, 114.4, 20.0, None, None, None, "fix"))
        wait.until(lambda d: xy('#geo g.geo-train[data-train="T1"]')[0] > tr["T1"][0])
        assert_apart(boxes(driver, "#geo-labels text"))

        # the RBC's correction-age watchdog fires: through the RBC link's alarm events and the system's alarm
        # route (System._alarm: store write, then the live event) to the page
        rbc = RbcConnection(SectionPlan(96.4, {"STA1": 0.0, "STA3": 96.4}), {"STA1": 101, "STA3": 103})
        rbc.rbc._watchdog(AlarmCode.CORRECTION_STALE, True, "corrections 6000 ms old")
        publisher = LivePublisher()
        publisher.live = live
        system = NS(alarms=persistence.AlarmRecorder(writer), publisher=publisher)
        for event in rbc.rbc_alarm_events():
            System._alarm(system, *event)
        kinds = '#alarms tr[data-alarm] td:nth-child(3)'
        wait.until(lambda d: "rbc-correction-stale" in [b["text"] for b in boxes(d, kinds)])
        assert "RBC: corrections 6000 ms old" in text(driver, "#alarms tbody")
        # and a train's: its newest corrections 8 s old
        for event in TrainCorrectionWatch().check("T2", 1000.0, 1008.0):
            System._alarm(system, *event)
        wait.until(lambda d: "train-correction-stale" in [b["text"] for b in boxes(d, kinds)])
        assert "train T2: corrections 8.0 s old" in text(driver, "#alarms tbody")
        assert driver.execute_script("return window.__csp;") == []  # charts and map within the page's CSP
        driver.save_screenshot(str(tmp_path / "console-views.png"))
        driver.find_element(By.ID, "geo").screenshot(str(tmp_path / "console-map.png"))
    writer.close()
