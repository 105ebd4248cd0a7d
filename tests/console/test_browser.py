"""The page in a real browser (Debian's headless chromium driven by selenium): it loads, trains move on the
line diagram, and acknowledging an alarm updates the page and the audit log."""

from __future__ import annotations

import shutil
import threading

import pytest

from augnet.console.app import create_app
from augnet.console.live import BaselineLive, LiveState, StationLive, TrainLive
from augnet.console.server import ConsoleThread
from augnet.store import queries as q
from augnet.store.models import AlarmState, Severity

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
