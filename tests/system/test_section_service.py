"""The centre's section service from position reports: codec, transitions through stations, overtaking on
a loop track, refusals alarmed, the RSSP-I picture (synthetic reports on a stepped GPS clock)."""

from __future__ import annotations

import dataclasses

import pytest

from augnet.onboard.position_report import (REPORT_BYTES, PositionReport, ReportBuilder, ReportError, decode,
                                            encode)
from augnet.system.section_register import Authority
from augnet.system.section_service import SectionService, StationArea, record_of

T0 = 1_400_000_000.0


def report(tid, t, km, track="L1-1", direction="up", seq=1, **kw):
    base = dict(train_id=tid, seq=seq, time_s=T0 + t, track=track, km=km, direction=direction, speed_m_s=50.0,
                length_m=209.0, integrity="unknown", correction_age_s=0.9, along_pl_m=0.4, cross_pl_m=0.3,
                hpl_m=0.5, vpl_m=0.9, track_confirmed=True)
    base.update(kw)
    return PositionReport(**base)


def test_report_round_trip_and_refusals():
    r = report("G101", 10.0, 80.123456, correction_age_s=None, hpl_m=None)
    data = encode(r)
    assert len(data) == REPORT_BYTES and decode(data) == r
    for bad, what in [(data[:-1], "length"), (data[:-4] + b"\0\0\0\0", "crc32"),
                      (b"XX" + data[2:], "crc32")]:
        with pytest.raises(ReportError, match=what):
            decode(bad)
    with pytest.raises(ReportError):
        encode(dataclasses.replace(r, train_id="X" * 21))
    with pytest.raises(ReportError):
        encode(dataclasses.replace(r, direction="north"))


def test_builder_takes_direction_and_speed_from_the_chainage():
    b = ReportBuilder("G1", 209.0)
    kw = dict(correction_age_s=None, along_pl_m=None, cross_pl_m=None, hpl_m=None, vpl_m=None, track_confirmed=False)
    assert b.build(T0, "L1-2", 100.0, **kw).direction == "unknown"
    assert b.build(T0 + 1, "L1-2", 100.0005, **kw).direction == "unknown"  # 0.5 m: noise, not a direction
    r = b.build(T0 + 2, "L1-2", 99.9165, **kw)
    assert r.direction == "down" and r.speed_m_s == pytest.approx(84.0, abs=0.1) and r.seq == 3
    # standing, a single-point solution wanders 5 m back and forth: within its 12 m PL, no flip
    for i, km in enumerate([99.9215, 99.9165, 99.9215]):
        assert b.build(T0 + 3 + i, "L1-2", km, **dict(kw, along_pl_m=12.0)).direction == "down"
    assert b.build(T0 + 6, "L1-2", 99.9300, **dict(kw, along_pl_m=12.0)).direction == "up"  # 13.5 m: moved


@pytest.fixture
def svc():
    alarms = []
    audits = []
    s = SectionService([StationArea("A", 50.0, 52.0), StationArea("B", 100.0, 102.0)], 150.0,
                       on_alarm=lambda *a: alarms.append(a), on_audit=audits.append)
    s.alarms, s.audits = alarms, audits
    return s


def order(svc, sid, d="up"):
    return [r.train_id for r in svc.register.trains(sid, d)]


def test_start_of_mission_then_through_a_station(svc):
    svc.on_datagram(encode(report("T1", 0, 45.0)))
    assert order(svc, 1) == ["T1"] and svc.audits[0].action == "section.admit"
    svc.on_report(report("T1", 1, 50.05))  # past the exit: B? no, A removes it
    assert svc.register.where("T1") is None and svc.in_station["T1"] == ("A", "L1-1")
    svc.on_report(report("T1", 2, 51.0, track="L1-S1-1"))
    svc.on_report(report("T1", 3, 52.1))
    assert order(svc, 2) == ["T1"]
    kinds = [(e.action, e.section_id, e.by) for e in svc.events]
    assert kinds == [("admit", 1, "start-of-mission"), ("remove", 1, "A"), ("insert", 2, "A")]
    assert svc.alarms == []


def test_overtaking_on_a_loop_track(svc):
    """S (slow) and F (fast) leave A in that order; at B S waits on loop track L1-S2-1 while F passes on
    the main track: section 3's order is F, S."""
    svc.on_report(report("S", 0, 51.0))  # both start in station A
    svc.on_report(report("F", 0, 50.5))
    svc.on_report(report("S", 1, 52.2))
    svc.on_report(report("F", 60, 52.1))
    assert order(svc, 2) == ["S", "F"]
    svc.on_report(report("S", 100, 99.0))
    svc.on_report(report("F", 100, 98.0))
    svc.on_report(report("S", 110, 100.3, track="L1-S2-1"))  # S into the station, onto the loop
    svc.on_report(report("F", 110, 100.2))
    svc.on_report(report("S", 120, 101.0, track="L1-S2-1", speed_m_s=0.0))  # standing on the loop
    svc.on_report(report("F", 130, 102.3))  # F leaves B first
    svc.on_report(report("S", 200, 102.2))
    assert order(svc, 3) == ["F", "S"]
    assert [e.by for e in svc.events if e.action == "insert" and e.section_id == 3] == ["B", "B"]
    assert not any(k.startswith("refused") for k in svc.stats)


def test_refusals_alarmed_once_and_cleared(svc):
    svc.on_report(report("T1", 0, 60.0))
    svc.on_report(report("T2", 0, 55.0))
    svc.on_report(report("T2", 1, 61.0))  # a report putting T2 ahead of T1: refused, order kept
    svc.on_report(report("T2", 2, 61.5))
    assert order(svc, 2) == ["T1", "T2"] and svc.stats["refused_order-conflict"] == 2
    assert [a[0] for a in svc.alarms] == ["section-register-refused"] and not svc.alarms[0][4]
    svc.on_report(report("T2", 3, 59.0))
    assert svc.alarms[-1][4] is True  # cleared by the next accepted report
    svc.on_report(report("T1", 4, 59.5, seq=2, time_s=T0 - 5))  # older than the last: dropped
    assert svc.stats["stale_reports"] == 1
    svc.on_datagram(b"garbage")
    assert svc.stats["bad_reports"] == 1


def test_without_start_authority_a_train_waits_for_a_dispatcher():
    svc = SectionService([StationArea("A", 50.0, 52.0)], 100.0, start_authority=None)
    svc.on_report(report("T1", 0, 70.0))
    assert svc.register.where("T1") is None and svc.stats["waiting_for_admission"] == 1
    audit = svc.register.admit(2, "up", record_of(report("T1", 0, 70.0)), Authority("dora", "dispatcher"),
                               "train identified by the driver")
    assert audit.after == ("T1",)


def test_telegram_and_dirty_sections(svc):
    assert len(svc.take_dirty()) == 6  # every section and direction at the first flush
    svc.on_report(report("T1", 0, 60.0, correction_age_s=None, along_pl_m=None))
    assert svc.take_dirty() == [(2, "up")]
    assert svc.take_dirty() == []
    m = svc.telegram(2, "up", 123)
    (t,) = m.trains
    assert (m.section_id, m.direction, t.train_id, t.chainage_mm, t.length_dm) == (2, 0, "T1", 60_000_000, 2090)
    assert t.correction_age_ms == 0xFFFFFFFF and t.along_pl_cm == 0xFFFF and t.cross_pl_cm == 30
    audit = svc.reorder(2, "up", ["T1"], Authority("dora", "dispatcher"), "check")
    assert audit.action == "section.reorder" and svc.take_dirty() == [(2, "up")]


def test_reports_travel_as_datagrams_from_the_trains_reporter():
    """A train's reporter -> one UDP datagram per second of GPS time -> the centre's register (loopback)."""
    import asyncio
    from types import SimpleNamespace as NS

    from augnet.system.section_service import TrainReporter, open_receiver, open_sender

    async def go():
        svc = SectionService([StationArea("A", 50.0, 52.0)], 100.0)
        transport, address = await open_receiver(svc)
        sender = await open_sender(address)
        train = NS(id="G7", protection_levels=lambda: (0.05, 0.09), correction_age_s=lambda: 1.2)
        rep = TrainReporter(train, sender.send)
        for i, km in enumerate([60.0, 60.05, 60.1, 60.15, 60.2]):
            match = NS(track="L1-1", km=km, along_pl_m=0.04, cross_pl_m=0.03, confirmed=True)
            rep.on_output(NS(match=match, solution=NS(time=T0 + i * 0.5)))  # 2 Hz outputs: every other sent
        rep.on_output(NS(match=None, solution=NS(time=T0 + 9)))  # off the map: nothing to report
        for _ in range(100):
            if svc.stats["reports"] == rep.sent:
                break
            await asyncio.sleep(0.01)
        sender.close()
        transport.close()
        return svc, rep

    svc, rep = asyncio.run(go())
    assert rep.sent == 3 and svc.stats["reports"] == 3
    (r,) = svc.register.trains(2, "up")
    assert (r.train_id, r.km, r.hpl_m, r.correction_age_s, r.length_m) == ("G7", 60.2, 0.05, 1.2, 209.0)
    assert r.speed_m_s == pytest.approx(100.0)  # 100 m in 1 s of GPS time


def test_the_systems_flush_sends_changed_sections_to_the_rbc_and_the_store(svc):
    """`System.flush_sections`: what changed since the last flush, to the RBC link and the store writer; a
    section too full for one RSD is counted, the others still go."""
    from types import SimpleNamespace as NS

    from augnet.system.runtime import System
    from rssp1.config import LinkTiming
    from rssp1.endpoint import Endpoint
    from rssp1.messages import decode_payload
    from rssp1.rbc import CentreRbcLink
    from tests.rssp1.linkpair import CENTRE, RBC

    jobs = []
    system = System.__new__(System)
    system.sections = svc
    system.rbc = NS(centre=CentreRbcLink(Endpoint(CENTRE, RBC, LinkTiming())))
    system.writer = NS(submit=jobs.append)
    system.flush_sections()
    assert len(system.rbc.centre.section_trains) == 6 and len(jobs) == 6  # the first flush: every section
    for i in range(18):  # 18 trains in section 2 up: more than one RSD carries
        svc.on_report(report(f"T{i:02d}", 0, 99.0 - i))
    svc.on_report(report("D1", 0, 120.0, direction="down"))
    jobs.clear()
    system.flush_sections()
    assert svc.stats["rbc_picture_too_large"] == 1 and len(jobs) == 2  # both stored
    assert len(system.rbc.centre.section_trains) == 6
    (pic,) = decode_payload(system.rbc.centre.section_trains[(3, 1)]).messages
    assert [t.train_id for t in pic.trains] == ["D1"]


def test_a_split_train_keeps_the_section_behind_it_until_confirmed_again(svc):
    """T1 confirms its integrity in section 2, loses it (split), arrives at B: section 2 stays occupied from its
    last confirmed rear; only a confirmed report with the rear past B's entry releases it."""
    svc.on_report(report("T1", 0, 51.0))
    svc.on_report(report("T1", 1, 52.2, integrity="confirmed"))
    svc.on_report(report("T1", 50, 90.0, integrity="confirmed"))
    svc.on_report(report("T1", 60, 95.0, integrity="lost"))
    svc.take_dirty()
    svc.on_report(report("T1", 80, 100.1, integrity="lost"))  # B removes it
    q = svc.register.queue(2, "up")
    assert svc.register.where("T1") is None and q.left_behind == {"T1": pytest.approx(89.791)}
    svc.on_report(report("T1", 81, 100.5, integrity="lost"))
    assert q.occupied_from_km() == pytest.approx(89.791)
    svc.take_dirty()
    svc.on_report(report("T1", 90, 101.0, integrity="confirmed"))  # rear at 100.791: past the exit
    assert q.left_behind == {} and (2, "up") in svc.take_dirty()
