"""The section view in a real browser (headless chromium, as tests/console/test_browser.py): trains in order
per section and direction, a train passing a station moves to the next section, the dispatcher's reorder
needs a reason and lands in the audit log."""

from __future__ import annotations

import pytest

from augnet.console.app import create_app
from augnet.console.live import LiveState
from augnet.console.server import ConsoleThread
from augnet.onboard.position_report import PositionReport
from augnet.store import queries as q
from augnet.system.section_service import SectionService, StationArea

from tests.console.conftest import add_accounts
from tests.console.helpers import PASSWORDS
from tests.console.test_browser import CHROMEDRIVER, CHROMIUM, WAIT_S, attribute, driver, text  # noqa: F401

pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="Debian chromium and chromium-driver not installed (apt-get install chromium chromium-driver)")]

T0 = 1_400_000_000.0


def report(tid, t, km, direction="up"):
    return PositionReport(tid, int(t) + 1, T0 + t, "L1-1" if direction == "up" else "L1-2", km, direction, 80.0,
                          209.0, "unknown", 0.7, 0.4, 0.3, 0.5, 0.9, True)


def chip(section, direction, train):
    return f'.section-box[data-section="{section}"][data-direction="{direction}"] li[data-train="{train}"]'


def test_section_view_order_station_passage_and_dispatcher_reorder(driver, sqlite_sessions, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    svc = SectionService([StationArea("Langfang East", 68.5, 70.5)], 150.0)
    svc.on_report(report("G1", 0, 90.0))
    svc.on_report(report("G2", 0, 80.0))
    svc.on_report(report("G4", 0, 60.0))
    svc.on_report(report("G3", 0, 20.0, "down"))
    add_accounts(sqlite_sessions)
    wait = WebDriverWait(driver, WAIT_S)
    with ConsoleThread(create_app(sqlite_sessions, LiveState(), sections=svc)) as server:
        driver.get(server.url + "/")
        wait.until(lambda d: d.find_element(By.ID, "login-form").is_displayed())
        driver.find_element(By.ID, "login-name").send_keys("otto")
        driver.find_element(By.ID, "login-password").send_keys(PASSWORDS["otto"])
        driver.find_element(By.ID, "login-submit").click()
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, chip(2, "up", "G1")))
        assert attribute(driver, chip(2, "up", "G1"), "data-position") == "0"  # front: nearest the exit
        assert attribute(driver, chip(2, "up", "G2"), "data-position") == "1"
        assert attribute(driver, chip(1, "up", "G4"), "data-position") == "0"
        assert attribute(driver, chip(1, "down", "G3"), "data-position") == "0"
        assert "Langfang East" in text(driver, '.section-row[data-direction="up"]')

        # G4 runs through Langfang East: removed from section 1 by it, shown in it, then inserted into 2
        svc.on_report(report("G4", 100, 68.6))
        wait.until(lambda d: "Langfang East [G4]" in text(d, '.section-row[data-direction="up"]'))
        assert not driver.find_elements(By.CSS_SELECTOR, chip(1, "up", "G4"))
        svc.on_report(report("G4", 130, 70.6))
        wait.until(lambda d: attribute(d, chip(2, "up", "G4"), "data-position") == "2")

        # the dispatcher moves G2 ahead of G1: refused without a reason, then done and audited
        button = chip(2, "up", "G2") + " button.move-ahead"
        driver.find_element(By.CSS_SELECTOR, button).click()
        wait.until(lambda d: "needs a reason" in text(d, "#section-error"))
        assert attribute(driver, chip(2, "up", "G2"), "data-position") == "1"
        driver.find_element(By.ID, "section-reason").send_keys("G2 ahead of G1 after the radio outage at km 85")
        driver.find_element(By.CSS_SELECTOR, button).click()
        wait.until(lambda d: attribute(d, chip(2, "up", "G2"), "data-position") == "0")
        assert attribute(driver, chip(2, "up", "G1"), "data-position") == "1"
        wait.until(lambda d: "otto section.reorder section 2 up" in text(d, "#audit tbody"))
        assert not driver.find_elements(By.CSS_SELECTOR, chip(2, "up", "G2") + " button.move-ahead")  # the front

        # the dispatcher withdraws G4 (it reports again: it waits), then admits it back
        driver.find_element(By.ID, "section-reason").send_keys("radio lost, driver stopped at km 71")
        driver.find_element(By.CSS_SELECTOR, chip(2, "up", "G4") + " button.withdraw").click()
        wait.until(lambda d: not d.find_elements(By.CSS_SELECTOR, chip(2, "up", "G4")))
        svc.on_report(report("G4", 140, 71.0))
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, '#sections-waiting button.admit[data-train="G4"]'))
        driver.find_element(By.ID, "section-reason").send_keys("radio back, position confirmed by the driver")
        driver.find_element(By.CSS_SELECTOR, '#sections-waiting button.admit[data-train="G4"]').click()
        wait.until(lambda d: attribute(d, chip(2, "up", "G4"), "data-position") == "2")
        wait.until(lambda d: "otto section.admit section 2 up" in text(d, "#audit tbody"))
        driver.save_screenshot(str(tmp_path / "sections.png"))
    assert [r.train_id for r in svc.register.trains(2, "up")] == ["G2", "G1", "G4"]
    with sqlite_sessions() as s:
        entry = next(e for e in q.audit_log(s) if e.action == "section.reorder")
        assert entry.detail["after"] == ["G2", "G1", "G4"] and entry.actor == "otto"
