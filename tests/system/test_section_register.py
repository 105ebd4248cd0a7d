"""The section register's rules: stations insert at the entry and remove at the exit, reports never
reorder, dispatcher actions need authority and a reason; every refused change names its rule."""

import pytest

from augnet.system.section_register import (BOUNDARY_ZONE_M, LINE_END, Authority, RegisterError, SectionRegister,
                                            TrainRecord, line_sections)

DISPATCHER = Authority("dora", "dispatcher")


def rec(tid, km, track="L1-1", speed=50.0):
    return TrainRecord(tid, track, km, speed, 209.0, "unknown", 0.8, 0.4, 0.3, 0.5)


@pytest.fixture
def reg():
    # A (km 0-50) B (km 52-100): sections 1: line end - A, 2: A - B, 3: B - line end
    return SectionRegister(line_sections([("A", 50.0, 52.0), ("B", 100.0, 102.0)], 150.0))


def refused(code, fn, *args, **kw):
    with pytest.raises(RegisterError) as e:
        fn(*args, **kw)
    assert e.value.code == code, str(e.value)
    return e.value


def test_sections_between_stations(reg):
    s = reg.sections
    assert [(x.id, x.km_begin, x.km_end, x.station_begin, x.station_end) for x in s.values()] == [
        (1, 0.0, 50.0, LINE_END, "A"), (2, 52.0, 100.0, "A", "B"), (3, 102.0, 150.0, "B", LINE_END)]
    assert s[2].entry_station("up") == "A" and s[2].entry_station("down") == "B"


def test_insert_at_entry_remove_at_exit_in_order(reg):
    reg.insert(2, "up", rec("T1", 52.3), by="A")
    reg.update(rec("T1", 60.0))
    reg.insert(2, "up", rec("T2", 52.2), by="A")
    assert [r.train_id for r in reg.trains(2, "up")] == ["T1", "T2"]  # front first
    reg.update(rec("T1", 99.8))
    reg.update(rec("T2", 80.0))
    assert reg.remove(2, "up", "T1", by="B").km == 99.8
    assert [r.train_id for r in reg.trains(2, "up")] == ["T2"]
    assert reg.where("T1") is None and reg.where("T2") == (2, "up")


def test_down_direction_enters_at_high_km(reg):
    reg.insert(2, "down", rec("D1", 99.9, track="L1-2"), by="B")
    reg.update(rec("D1", 60.0, track="L1-2"))
    reg.insert(2, "down", rec("D2", 99.5, track="L1-2"), by="B")
    refused("not-at-exit", reg.remove, 2, "down", "D1", by="A")  # 8 km before the exit
    reg.update(rec("D1", 52.1, track="L1-2"))
    refused("not-at-exit", reg.remove, 2, "down", "D2", by="A")  # D1 is in front
    reg.remove(2, "down", "D1", by="A")
    assert reg.trains(2, "down")[0].train_id == "D2"


def test_refused_inserts(reg):
    reg.insert(2, "up", rec("T1", 52.5), by="A")
    refused("not-entry-side", reg.insert, 2, "up", rec("T2", 52.1), by="B")
    refused("duplicate", reg.insert, 2, "up", rec("T1", 52.1), by="A")
    refused("duplicate", reg.insert, 3, "up", rec("T1", 102.1), by="B")  # one train, one place
    refused("middle-insert", reg.insert, 2, "up", rec("T3", 52.8), by="A")  # ahead of the rear train
    refused("middle-insert", reg.insert, 2, "up", rec("T3", 52.0 + 2 * BOUNDARY_ZONE_M / 1e3), by="A")
    refused("unknown-section", reg.insert, 9, "up", rec("T3", 52.1), by="A")
    refused("bad-direction", reg.insert, 2, "sideways", rec("T3", 52.1), by="A")
    refused("outside-section", reg.insert, 2, "up", rec("T3", 10.0), by="A")
    refused("bad-record", reg.insert, 2, "up", TrainRecord("T3", "L1-1", 52.1, 1.0, -5.0, "ok", None, None,
                                                           None, None), by="A")
    assert [r.train_id for r in reg.trains(2, "up")] == ["T1"]


def test_refused_removes(reg):
    reg.insert(2, "up", rec("T1", 52.5), by="A")
    reg.insert(2, "up", rec("T2", 52.1), by="A")
    reg.update(rec("T1", 99.9))
    refused("not-exit-side", reg.remove, 2, "up", "T1", by="A")
    refused("not-at-exit", reg.remove, 2, "up", "T2", by="B")
    refused("unknown-train", reg.remove, 2, "up", "T9", by="B")
    refused("unknown-train", reg.remove, 2, "down", "T1", by="A")
    assert [r.train_id for r in reg.trains(2, "up")] == ["T1", "T2"]


def test_reports_never_reorder(reg):
    reg.insert(2, "up", rec("T1", 52.5), by="A")
    reg.update(rec("T1", 70.0))
    reg.insert(2, "up", rec("T2", 52.1), by="A")
    e = refused("order-conflict", reg.update, rec("T2", 70.5))  # would pass T1
    assert "T1" in e.detail
    refused("order-conflict", reg.update, rec("T1", 52.0))  # would fall behind T2
    refused("unknown-train", reg.update, rec("T9", 60.0))
    refused("outside-section", reg.update, rec("T1", 120.0))
    assert [(r.train_id, r.km) for r in reg.trains(2, "up")] == [("T1", 70.0), ("T2", 52.1)]


def test_dispatcher_reorder_needs_authority_and_reason(reg):
    reg.insert(2, "up", rec("T1", 52.5), by="A")
    reg.insert(2, "up", rec("T2", 52.1), by="A")
    refused("no-authority", reg.reorder, 2, "up", ["T2", "T1"], None, "swap")
    refused("no-authority", reg.reorder, 2, "up", ["T2", "T1"], Authority("vic", "viewer"), "swap")
    refused("no-authority", reg.reorder, 2, "up", ["T2", "T1"], DISPATCHER, "  ")
    refused("not-a-permutation", reg.reorder, 2, "up", ["T2"], DISPATCHER, "swap")
    refused("not-a-permutation", reg.reorder, 2, "up", ["T2", "T2"], DISPATCHER, "swap")
    refused("not-a-permutation", reg.reorder, 2, "up", ["T2", "T1", "T3"], DISPATCHER, "swap")
    v = reg.queue(2, "up").version
    audit = reg.reorder(2, "up", ["T2", "T1"], DISPATCHER, "T1 positioned behind T2 after radio outage")
    assert (audit.actor, audit.action, audit.target) == ("dora", "section.reorder", "section 2 up")
    assert audit.before == ("T1", "T2") and audit.after == ("T2", "T1")
    assert [r.train_id for r in reg.trains(2, "up")] == ["T2", "T1"]
    assert reg.queue(2, "up").version == v + 1
    # the linked list is consistent both ways after the rebuild
    q = reg.queue(2, "up")
    assert q.front.record.train_id == "T2" and q.rear.record.train_id == "T1"
    assert q.rear.ahead is q.front and q.front.behind is q.rear and q.front.ahead is None


def test_admit_and_withdraw(reg):
    reg.insert(2, "up", rec("T1", 52.5), by="A")
    reg.update(rec("T1", 90.0))
    reg.insert(2, "up", rec("T2", 52.1), by="A")
    refused("no-authority", reg.admit, 2, "up", rec("T3", 70.0), None, "start of mission")
    a = reg.admit(2, "up", rec("T3", 70.0), DISPATCHER, "start of mission")
    assert a.after == ("T1", "T3", "T2") and reg.where("T3") == (2, "up")
    refused("duplicate", reg.admit, 3, "up", rec("T3", 110.0), DISPATCHER, "again")
    refused("no-authority", reg.withdraw, 2, "up", "T3", Authority("", "dispatcher"), "gone")
    w = reg.withdraw(2, "up", "T3", DISPATCHER, "train withdrawn from service")
    assert w.after == ("T1", "T2") and reg.where("T3") is None


def test_overtaking_on_a_loop_goes_through_the_station(reg):
    """Slow S leaves A first, fast F follows; at B, S waits on a loop track and F overtakes: B removes
    them in arrival order and inserts them into section 3 in departure order."""
    reg.insert(2, "up", rec("S", 52.1, speed=30.0), by="A")
    reg.update(rec("S", 70.0))
    reg.insert(2, "up", rec("F", 52.1, speed=80.0), by="A")
    reg.update(rec("S", 99.9))
    reg.update(rec("F", 99.5))
    refused("not-at-exit", reg.remove, 2, "up", "F", by="B")  # F cannot leave the section before S
    reg.remove(2, "up", "S", by="B")  # S to the loop track L1-S2-1
    reg.update(rec("F", 99.95))
    reg.remove(2, "up", "F", by="B")  # F on the main track through the station
    reg.insert(3, "up", rec("F", 102.2, speed=80.0), by="B")
    reg.update(rec("F", 103.5))
    reg.insert(3, "up", rec("S", 102.1, speed=10.0), by="B")
    assert [r.train_id for r in reg.trains(3, "up")] == ["F", "S"]
    refused("not-entry-side", reg.insert, 3, "up", rec("X", 102.1), by="A")


def irec(tid, km, integrity, length=209.0):
    return TrainRecord(tid, "L1-1", km, 50.0, length, integrity, 0.8, 0.4, 0.3, 0.5)


def test_rear_follows_confirmed_integrity_and_freezes_without_it(reg):
    reg.insert(2, "up", irec("T1", 52.3, "unknown"), by="A")
    assert reg.record("T1").rear_km == 52.0  # never confirmed: the whole section behind it stays occupied
    reg.update(irec("T1", 60.0, "confirmed"))
    assert reg.record("T1").rear_km == pytest.approx(60.0 - 0.209)
    reg.update(irec("T1", 61.0, "lost"))
    assert reg.record("T1").rear_km == pytest.approx(60.0 - 0.209)  # frozen at the last confirmed rear
    reg.update(irec("T1", 62.0, "unknown"))
    assert reg.record("T1").rear_km == pytest.approx(60.0 - 0.209)
    assert reg.queue(2, "up").occupied_from_km() == pytest.approx(59.791)
    reg.insert(2, "down", irec("D1", 99.9, "confirmed", length=400.0), by="B")
    assert reg.record("D1").rear_km == pytest.approx(100.3)  # down: the rear is at the higher chainage


def test_a_train_leaving_without_confirmed_integrity_keeps_the_section_occupied(reg):
    reg.insert(2, "up", irec("T1", 52.3, "confirmed"), by="A")
    reg.update(irec("T1", 90.0, "confirmed"))
    reg.update(irec("T1", 95.0, "lost"))  # split: the rear is somewhere behind km 89.791
    reg.update(irec("T1", 99.9, "lost"))
    reg.remove(2, "up", "T1", by="B")
    q = reg.queue(2, "up")
    assert len(q) == 0 and q.left_behind == {"T1": pytest.approx(89.791)}
    assert q.occupied_from_km() == pytest.approx(89.791)
    assert reg.release(irec("T1", 101.0, "lost")) == []  # still lost: nothing released
    refused("no-authority", reg.clear_behind, 2, "up", "T1", None, "rear found")
    refused("no-authority", reg.clear_behind, 2, "up", "T1", DISPATCHER, " ")
    refused("unknown-train", reg.clear_behind, 2, "up", "T9", DISPATCHER, "rear found")
    audit = reg.clear_behind(2, "up", "T1", DISPATCHER, "rear part recovered")
    assert audit.action == "section.clear_behind" and audit.before == ("T1",)
    assert q.occupied_from_km() is None


def test_a_confirmed_rear_past_the_exit_releases_the_section(reg):
    reg.insert(2, "up", irec("T1", 52.3, "confirmed"), by="A")
    reg.update(irec("T1", 99.95, "confirmed"))
    reg.remove(2, "up", "T1", by="B")
    q = reg.queue(2, "up")
    assert q.left_behind == {"T1": pytest.approx(99.741)}  # its last 209 m are still in the section
    assert reg.release(irec("T1", 100.1, "confirmed")) == [(2, "up")]  # rear at 99.891: moved on
    assert q.left_behind == {"T1": pytest.approx(99.891)}
    assert reg.release(irec("T1", 100.25, "confirmed")) == [(2, "up")]  # rear at 100.041: past the exit
    assert q.left_behind == {} and q.occupied_from_km() is None
