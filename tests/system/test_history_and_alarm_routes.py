"""What `augnet up` records into the quality history besides its baselines (correction age p99, trains fixed,
station data age: decision 0185), and the routes by which every alarm reaches the console: published to the
pages only once the store has it, and the RBC's own section alarms raised and cleared (issue 19)."""

from __future__ import annotations

import datetime as dt

import pytest

from augnet.console.live import LiveState
from augnet.store import open_store
from augnet.store import queries as q
from augnet.store import series
from augnet.system import persistence
from augnet.system.history_series import series_values
from augnet.system.live_state import LivePublisher
from augnet.system.rbc_link import RbcConnection, SectionPlan
from augnet.system.train_alarms import TrainCorrectionWatch
from rssp1.messages import SectionStatus
from tests.system.test_live_state import _epoch

CYCLE_S = 0.25  # rbc_link.LINK_TIMING's main cycle


@pytest.fixture
def sessions(tmp_path):
    factory = open_store(f"sqlite:///{tmp_path / 'augnet.sqlite'}")
    yield factory
    factory.kw["bind"].dispose()


def test_series_values_name_each_series_and_leave_out_silent_stations():
    values = series_values([9.0] * 10 + [0.5] * 300, ["fix", "float", "fix", "single"],
                           {"A": 0.8, "B": None, "C": float("nan")})
    assert values == {series.CORRECTION_AGE_P99: 0.5,  # over the last 300 epochs only, as the live summary
                      series.TRAINS_FIXED: 2.0, series.TRAINS_REPORTING: 4.0, "station:A:data_age_s": 0.8}
    assert series_values([], [], {}) == {series.TRAINS_FIXED: 0.0, series.TRAINS_REPORTING: 0.0}
    ages = series_values([float(k) for k in range(1, 101)], [], {})[series.CORRECTION_AGE_P99]
    assert ages == pytest.approx(99.01)


def test_quality_history_writes_baselines_and_series_at_its_cadence(sessions):
    writer = persistence.StoreWriter(sessions)
    history = persistence.QualityHistory(writer, interval_s=10.0)
    asked = []

    def values():
        asked.append(1)
        return {series.CORRECTION_AGE_P99: 1.25, series.TRAINS_FIXED: 3.0, "station:A:data_age_s": 0.4}

    t0 = 1_796_000_000.0
    for k in range(25):  # 25 s of 1 Hz epochs: rows at 0, 10 and 20 s
        history.on_epoch(_epoch().network, t0 + k, values)
    writer.close()
    assert len(asked) == 3  # the series are computed only when a row is due
    with sessions() as s:
        rows = q.quality_rows(s)
    at0 = dt.datetime.fromtimestamp(t0, dt.timezone.utc).replace(tzinfo=None)
    assert sorted({r[0] for r in rows}) == [at0, at0 + dt.timedelta(seconds=10), at0 + dt.timedelta(seconds=20)]
    first = {r[1]: r for r in rows if r[0] == at0}
    assert set(first) == {"A-B", series.CORRECTION_AGE_P99, series.TRAINS_FIXED, "station:A:data_age_s"}
    assert first["A-B"][2:] == (0.75, pytest.approx(0.01), 3)
    assert first[series.CORRECTION_AGE_P99][2:] == (1.25, None, 0)


def test_record_series_refuses_what_is_no_series(sessions):
    at = dt.datetime(2026, 12, 3, 12, 0, tzinfo=dt.timezone.utc)
    with sessions() as s:
        for bad in ("A-B", "A", "network:unknown", "station:" + "X" * 60 + series.STATION_DATA_AGE_SUFFIX):
            with pytest.raises(ValueError, match="not a series subject"):
                series.record_series(s, at, bad, 1.0)
        with pytest.raises(ValueError, match="finite"):
            series.record_series(s, at, series.TRAINS_FIXED, float("nan"))


def test_an_alarm_reaches_the_pages_only_after_the_store_has_it(sessions):
    live = LiveState()
    pub = LivePublisher()
    pub.live = live
    seen_in_store = []
    live.publish = lambda event: seen_in_store.append((event, _open_alarms(sessions)))
    writer = persistence.StoreWriter(sessions)
    alarms = persistence.AlarmRecorder(writer)

    def route(kind, subject, severity, message, cleared):  # as System._alarm
        alarms.record(kind, subject, severity, message, cleared,
                      on_stored=lambda: pub.publish_alarm(kind, subject, severity, cleared))

    route("rbc-correction-stale", "rbc", "critical", "RBC: corrections 6000 ms old", False)
    route("rbc-correction-stale", "rbc", "critical", "again", False)  # open already: nothing to tell
    route("rbc-correction-stale", "rbc", "critical", "RBC: cleared", True)
    writer.close()
    assert [(e["action"], e["kind"], open_) for e, open_ in seen_in_store] == [
        ("raised", "rbc-correction-stale", ["rbc-correction-stale"]), ("cleared", "rbc-correction-stale", [])]


def _open_alarms(sessions) -> list[str]:
    with sessions() as s:
        return [a.kind for a in q.list_alarms(s)]


class BrokenStore:
    def begin(self):
        raise RuntimeError("store gone")


def test_a_failed_alarm_write_tells_no_page():
    told = []
    writer = persistence.StoreWriter(BrokenStore())
    persistence.AlarmRecorder(writer).record("station-down", "A", "warning", "", False, on_stored=lambda: told.append(1))
    writer.close()
    assert writer.failures == 1 and told == []


def _section_events(conn: RbcConnection) -> list[tuple]:
    return [e for e in conn.rbc_alarm_events() if e[0] == "rbc-section-do-not-use"]


def _step(conn: RbcConnection, now: float, cycles: int) -> float:
    """Both ends of the link in lockstep, frames handed straight across (no sockets)."""
    for _ in range(cycles):
        for frame in conn.centre.cycle(now):
            conn.rbc.receive(frame, now + 0.01)
        for frame in conn.rbc.cycle(now):
            conn.centre.receive(frame, now + 0.01)
        now += CYCLE_S
    return now


def test_a_section_the_rbc_sees_do_not_use_is_an_alarm_until_it_is_usable_again():
    conn = RbcConnection(SectionPlan(20.0, {"A": 0.0, "B": 20.0}), {"A": 1, "B": 2})
    now = _step(conn, 100.0, 8)  # link up; the centre reports both sections DO_NOT_USE from the start
    conn.centre.corrections_updated(1_000, produced_at_s=now)
    now = _step(conn, now, 4)
    events = _section_events(conn)
    assert [(k, s, sev, cl) for k, s, sev, _m, cl in events] == [
        ("rbc-section-do-not-use", "section 1", "warning", False), ("rbc-section-do-not-use", "section 2", "warning", False)]
    assert _section_events(conn) == []  # once while it lasts
    conn.centre.set_section(2, SectionStatus.OK)
    conn.centre.corrections_updated(2_000, produced_at_s=now)
    now = _step(conn, now, 4)
    assert [(e[1], e[4]) for e in _section_events(conn)] == [("section 2", True)]
    conn.centre.set_section(2, SectionStatus.DO_NOT_USE)
    conn.centre.corrections_updated(3_000, produced_at_s=now)
    _step(conn, now, 4)
    assert [(e[1], e[4]) for e in _section_events(conn)] == [("section 2", False)]


def test_a_train_whose_corrections_go_stale_raises_an_alarm_until_they_are_fresh():
    watch = TrainCorrectionWatch(limit_s=5.0)
    assert watch.check("T1", None, 1000.0) == []  # no corrections yet: starting, not judged
    assert watch.check("T1", 999.0, 1000.0) == []
    (kind, subject, severity, message, cleared), = watch.check("T1", 994.0, 1000.0)
    assert (kind, subject, severity, cleared) == ("train-correction-stale", "train T1", "warning", False)
    assert "6.0 s old" in message
    assert watch.check("T1", 994.0, 1001.0) == []  # once per episode
    assert watch.check("T2", 1000.5, 1001.0) == []  # each train on its own
    assert [(e[1], e[4]) for e in watch.check("T1", 1000.0, 1001.0)] == [("train T1", True)]
    assert watch.check("T1", 1000.0, 1001.0) == []
