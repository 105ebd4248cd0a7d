"""Section routes: the register's trains per section and direction, the dispatcher's reorder (operator,
audited), the store's last picture when no register runs in the console's process."""

from __future__ import annotations

from fastapi.testclient import TestClient

from augnet.console.app import create_app
from augnet.console.live import LiveState
from augnet.onboard.position_report import PositionReport
from augnet.store import queries as q
from augnet.system.section_service import SectionService, StationArea

from tests.console.conftest import add_accounts

T0 = 1_400_000_000.0


def report(tid, t, km, direction="up"):
    return PositionReport(tid, 1, T0 + t, "L1-1", km, direction, 80.0, 209.0, "unknown", 0.7, 0.4, 0.3, 0.5, 0.9,
                          True)


def make(sessions):
    svc = SectionService([StationArea("Langfang East", 68.5, 70.5)], 150.0)
    svc.on_report(report("G1", 0, 90.0))
    svc.on_report(report("G2", 0, 80.0))
    svc.on_report(report("G3", 0, 20.0, "down"))
    tokens = add_accounts(sessions)
    return svc, TestClient(create_app(sessions, LiveState(), sections=svc)), tokens


def auth(tokens, who):
    return {"Authorization": f"Bearer {tokens[who]}"}


def test_sections_list_and_one_section(sqlite_sessions):
    svc, client, tokens = make(sqlite_sessions)
    with client:
        assert client.get("/api/sections").status_code == 401
        body = client.get("/api/sections", headers=auth(tokens, "vera")).json()
        assert body["live"] is True and body["stations"][0]["name"] == "Langfang East"
        by = {(s["section"], s["direction"]): s for s in body["sections"]}
        assert set(by) == {(1, "up"), (1, "down"), (2, "up"), (2, "down")}
        assert [t["train_id"] for t in by[(2, "up")]["trains"]] == ["G1", "G2"]
        assert by[(2, "up")]["entry"] == "Langfang East" and by[(1, "down")]["exit"] == "line end"
        one = client.get("/api/sections/2/up", headers=auth(tokens, "vera")).json()
        assert [t["train_id"] for t in one["trains"]] == ["G1", "G2"] and one["trains"][0]["km"] == 90.0
        assert client.get("/api/sections/9/up", headers=auth(tokens, "vera")).status_code == 404
        assert client.get("/api/sections/2/sideways", headers=auth(tokens, "vera")).status_code == 422


def test_reorder_needs_an_operator_and_a_reason_and_is_audited(sqlite_sessions):
    svc, client, tokens = make(sqlite_sessions)
    url = "/api/sections/2/up/reorder"
    body = {"order": ["G2", "G1"], "reason": "G1 reported ahead after a radio outage, confirmed by driver"}
    with client:
        assert client.post(url, json=body, headers=auth(tokens, "vera")).status_code == 403
        assert client.post(url, json={"order": ["G2", "G1"]}, headers=auth(tokens, "otto")).status_code == 422
        r = client.post(url, json={"order": ["G2"], "reason": "x"}, headers=auth(tokens, "otto"))
        assert r.status_code == 409 and r.json()["detail"]["code"] == "not-a-permutation"
        assert client.post("/api/sections/9/up/reorder", json=body, headers=auth(tokens, "otto")).status_code == 404
        r = client.post(url, json=body, headers=auth(tokens, "otto"))
        assert r.status_code == 200, r.text
        assert [t["train_id"] for t in r.json()["trains"]] == ["G2", "G1"]
    assert [x.train_id for x in svc.register.trains(2, "up")] == ["G2", "G1"]
    with sqlite_sessions() as s:
        (entry,) = [e for e in q.audit_log(s) if e.action == "section.reorder"]
        assert (entry.actor, entry.target) == ("otto", "section 2 up")
        assert entry.detail["before"] == ["G1", "G2"] and entry.detail["after"] == ["G2", "G1"]
        assert entry.detail["reason"].startswith("G1 reported ahead")


def test_without_a_register_the_store_answers(sessions):
    with sessions.begin() as s:
        q.replace_section_trains(s, 2, "up", [
            {"train_id": "G1", "track": "L1-1", "km": 90.0, "speed_m_s": 80.0, "length_m": 209.0,
             "integrity": "unknown", "correction_age_s": None, "along_pl_m": 0.4, "cross_pl_m": 0.3, "hpl_m": None,
             "time_s": T0}])
        q.replace_section_trains(s, 3, "up", [])
    tokens = add_accounts(sessions)
    with TestClient(create_app(sessions, LiveState())) as client:
        body = client.get("/api/sections", headers=auth(tokens, "vera")).json()
        assert body["live"] is False
        assert [(x["section"], [t["train_id"] for t in x["trains"]]) for x in body["sections"]] == [(2, ["G1"])]
        r = client.post("/api/sections/2/up/reorder", json={"order": ["G1"], "reason": "x"},
                        headers=auth(tokens, "otto"))
        assert r.status_code == 503
    # a train moves: it is stored in one place only
    with sessions.begin() as s:
        q.replace_section_trains(s, 3, "up", [
            {"train_id": "G1", "track": "L1-1", "km": 103.0, "speed_m_s": 80.0, "length_m": 209.0,
             "integrity": "unknown", "correction_age_s": None, "along_pl_m": None, "cross_pl_m": None,
             "hpl_m": None, "time_s": T0 + 200}])
    with sessions() as s:
        assert {k: [t["train_id"] for t in v] for k, v in q.section_trains(s).items()} == {(3, "up"): ["G1"]}


def test_dispatcher_withdraws_and_admits_a_train(sqlite_sessions):
    svc, client, tokens = make(sqlite_sessions)
    reason = {"train_id": "G2", "reason": "radio lost since km 80, train stopped by the driver"}
    with client:
        assert client.post("/api/sections/2/up/withdraw", json=reason, headers=auth(tokens, "vera")).status_code == 403
        r = client.post("/api/sections/2/up/withdraw", json=reason, headers=auth(tokens, "otto"))
        assert r.status_code == 200 and [t["train_id"] for t in r.json()["trains"]] == ["G1"]
        assert client.post("/api/sections/2/up/withdraw", json=reason,
                           headers=auth(tokens, "otto")).status_code == 404  # not there any more
        svc.on_report(report("G2", 10, 80.5))  # it reports again: withdrawn trains wait for a dispatcher
        body = client.get("/api/sections", headers=auth(tokens, "vera")).json()
        assert body["waiting"] == ["G2"] and svc.register.where("G2") is None
        assert client.post("/api/sections/admit", json={"train_id": "G9", "reason": "x"},
                           headers=auth(tokens, "otto")).status_code == 404
        r = client.post("/api/sections/admit", json={"train_id": "G2", "reason": "radio back, position confirmed"},
                        headers=auth(tokens, "otto"))
        assert r.status_code == 200 and [t["train_id"] for t in r.json()["trains"]] == ["G1", "G2"]
        assert r.json()["trains"][1]["km"] == 80.5
        assert client.get("/api/sections", headers=auth(tokens, "vera")).json()["waiting"] == []
    with sqlite_sessions() as s:
        actions = [(e.actor, e.action, e.target) for e in q.audit_log(s) if e.action.startswith("section.")]
        assert ("otto", "section.withdraw", "section 2 up") in actions
        assert ("otto", "section.admit", "section 2 up") in actions
