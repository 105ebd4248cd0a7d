"""Alarms: the system raises and clears them in the store; operators list and acknowledge them."""

from __future__ import annotations

import datetime as dt

import pytest

from augnet.store import queries as q
from augnet.store.models import AlarmState, Severity

from tests.console.helpers import error_fields


def _raise(sessions, kind="satellite-excluded", subject="G12", severity=Severity.CRITICAL, message="clock step"):
    with sessions.begin() as s:
        a = q.raise_alarm(s, kind, subject, severity, message)
        s.flush()
        return a.id


def test_list_newest_first_and_cleared_only_when_asked(console):
    c = console
    first = _raise(c.sessions, subject="G12")
    second = _raise(c.sessions, kind="station-down", subject="STA3", severity=Severity.WARNING, message="no data 30 s")
    third = _raise(c.sessions, kind="station-down", subject="STA4")
    with c.sessions.begin() as s:
        q.clear_alarm(s, "station-down", "STA4")
    r = c.client.get("/api/alarms", headers=c.as_("vera"))
    assert r.status_code == 200
    rows = r.json()
    assert [a["id"] for a in rows] == [second, first]
    assert rows[0] | {"raised_at": None} == {
        "id": second, "kind": "station-down", "subject": "STA3", "severity": "warning", "message": "no data 30 s",
        "state": "raised", "raised_at": None, "acknowledged_at": None, "acknowledged_by": None, "cleared_at": None}
    raised = dt.datetime.fromisoformat(rows[0]["raised_at"])
    assert raised.tzinfo is not None and abs(raised - dt.datetime.now(dt.timezone.utc)) < dt.timedelta(minutes=1)
    everything = c.client.get("/api/alarms?include_cleared=true", headers=c.as_("vera")).json()
    assert [a["id"] for a in everything] == [third, second, first]
    assert everything[0]["state"] == "cleared" and everything[0]["cleared_at"] is not None
    assert [a["id"] for a in c.client.get("/api/alarms?limit=1", headers=c.as_("vera")).json()] == [second]
    one = c.client.get(f"/api/alarms/{first}", headers=c.as_("vera"))
    assert one.status_code == 200 and one.json()["subject"] == "G12"
    assert c.client.get("/api/alarms/999999", headers=c.as_("vera")).status_code == 404


@pytest.mark.parametrize("query, field", [("limit=0", "limit"), ("limit=1001", "limit"), ("limit=many", "limit"),
                                          ("include_cleared=perhaps", "include_cleared")])
def test_list_bad_query_422_names_the_parameter(sqlite_console, query, field):
    r = sqlite_console.client.get(f"/api/alarms?{query}", headers=sqlite_console.as_("vera"))
    assert field in error_fields(r)


def test_bad_alarm_id_is_422(sqlite_console):
    c = sqlite_console
    assert "alarm_id" in error_fields(c.client.get("/api/alarms/abc", headers=c.as_("vera")))
    assert "alarm_id" in error_fields(c.client.post("/api/alarms/abc/acknowledge", headers=c.as_("otto")))
    assert "alarm_id" in error_fields(c.client.get(f"/api/alarms/{2**31}", headers=c.as_("vera")))
    assert "alarm_id" in error_fields(c.client.get("/api/alarms/0", headers=c.as_("vera")))


def test_acknowledge_by_operator_audited_and_pushed(console):
    c = console
    alarm_id = _raise(c.sessions)
    seen = []
    c.live.publish = seen.append  # capture what the websocket subscribers would get
    assert c.client.post(f"/api/alarms/{alarm_id}/acknowledge", headers=c.as_("vera")).status_code == 403
    r = c.client.post(f"/api/alarms/{alarm_id}/acknowledge", headers=c.as_("otto"))
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["state"] == "acknowledged" and body["acknowledged_by"] == "otto"
    assert body["acknowledged_at"] is not None
    assert seen == [{"type": "alarm", "action": "acknowledged", "alarm": body}]
    with c.sessions() as s:
        a = q.get_alarm(s, alarm_id)
        assert a.state is AlarmState.ACKNOWLEDGED and a.acknowledged_by == "otto"
        e = q.audit_log(s, 1)[0]
        assert (e.actor, e.action, e.target) == ("otto", "alarm.acknowledge", f"alarm:{alarm_id}")
    # acknowledging again changes nothing, audits nothing, pushes nothing
    again = c.client.post(f"/api/alarms/{alarm_id}/acknowledge", headers=c.as_("ada"))
    assert again.status_code == 200 and again.json()["acknowledged_by"] == "otto"
    assert len(seen) == 1
    with c.sessions() as s:
        assert len([e for e in q.audit_log(s) if e.action == "alarm.acknowledge"]) == 1
    assert c.client.post("/api/alarms/424242/acknowledge", headers=c.as_("otto")).status_code == 404
