"""The RBC link and the ATP link, sans-IO in lockstep with a simulated clock."""

from __future__ import annotations

import pytest

from rssp1.atp import AtpSimulator, BaliseLocation, OnboardAtpLink
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.endpoint import Endpoint
from rssp1.envelope import Keyring, SealedEndpoint
from rssp1.frames import RSD_TYPES, decode_frame
from rssp1.messages import AlarmCode, SectionStatus, Severity
from rssp1.rbc import CentreRbcLink, RbcSimulator

from .linkpair import CENTRE, RBC

TIMING = LinkTiming(cycle_s=0.25, delta_time=3, life_time=4, delay_time=3)
TIME_TO_ALARM_LIMIT_S = 1.0  # issue 7: a fault at the centre is an alarm at the RBC within 1 s
ONBOARD = DeviceConfig(0x0301, (0x0BADCAFE, 0x600DF00D), dataver=(3, 4))
ATP = DeviceConfig(0x0302, (0x13572468, 0x24681357), dataver=(5, 6))


class Lockstep:
    def __init__(self, left, right) -> None:
        self.left, self.right = left, right
        self.now = 100.0
        self.drop_to_right = lambda frame: False
        self.cut = False

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            fl, fr = self.left.cycle(self.now), self.right.cycle(self.now)
            if not self.cut:
                for f in fl:
                    if not self.drop_to_right(f):
                        self.right.receive(f, self.now + 0.01)
                for f in fr:
                    self.left.receive(f, self.now + 0.01)
            self.now += TIMING.cycle_s


def rbc_pair(sealed: bool = False, **kw):
    centre_ep, rbc_ep = Endpoint(CENTRE, RBC, TIMING), Endpoint(RBC, CENTRE, TIMING)
    if sealed:
        keys = Keyring({1: bytes(range(32))})
        centre_ep, rbc_ep = SealedEndpoint(centre_ep, keys), SealedEndpoint(rbc_ep, keys)
    centre = CentreRbcLink(centre_ep, **kw)
    rbc = RbcSimulator(rbc_ep, **kw)
    return centre, rbc, Lockstep(centre, rbc)


@pytest.mark.parametrize("sealed", [False, True], ids=["open", "sealed"])
@pytest.mark.parametrize("fault", ["section", "link"])
def test_time_to_alarm_within_the_limit_at_the_worst_phase(fault, sealed):
    """Field timing, the fault just after both ends' cycle ran (it waits a whole cycle for the next):
    the alarm within the issue's 1 s on the stepped clock."""
    centre, rbc, net = rbc_pair(sealed)
    centre.set_section(5, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    net.step(4)
    assert rbc.effective_status(5) is SectionStatus.OK
    fault_at = net.now - TIMING.cycle_s  # the last cycle's instant: the worst phase
    if fault == "section":
        centre.set_section(5, SectionStatus.DO_NOT_USE)
        code, section = AlarmCode.SECTION_DO_NOT_USE, 5
    else:
        net.cut = True
        code, section = AlarmCode.LINK_LOST, None
    net.step(round(TIME_TO_ALARM_LIMIT_S / TIMING.cycle_s))
    alarm = rbc.first_alarm(code, section)
    assert alarm is not None and alarm.at_s - fault_at <= TIME_TO_ALARM_LIMIT_S, rbc.alarms


def test_reports_reach_the_rbc_fail_safe_until_then():
    centre, rbc, net = rbc_pair()
    for s in (1, 2, 3):
        centre.set_section(s, SectionStatus.OK, hpl_m=0.4)
    centre.set_section(2, SectionStatus.DEGRADED, hpl_m=2.5)
    centre.set_exclusions(["G05", "C19"], [7])
    centre.corrections_updated(1_000, produced_at_s=net.now)
    assert rbc.effective_status(1) is SectionStatus.DO_NOT_USE  # nothing known yet: fail safe
    net.step(4)
    assert centre.is_up and rbc.endpoint.is_up
    assert [rbc.effective_status(s) for s in (1, 2, 3, 99)] == [
        SectionStatus.OK, SectionStatus.DEGRADED, SectionStatus.OK, SectionStatus.DO_NOT_USE]
    assert rbc.view.reported[2].hpl_dm == 25
    assert rbc.view.satellites == ("C19", "G05") and rbc.view.stations == (7,)
    assert rbc.alarms == [] and centre.last_acked_report > 0


def test_section_do_not_use_raises_an_rbc_alarm_in_the_next_cycle():
    centre, rbc, net = rbc_pair()
    centre.set_section(5, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    net.step(4)
    fault_at = net.now
    centre.set_section(5, SectionStatus.DO_NOT_USE)
    net.step(1)
    alarm = rbc.first_alarm(AlarmCode.SECTION_DO_NOT_USE, 5)
    assert alarm is not None and alarm.origin == "status" and alarm.at_s - fault_at <= TIMING.cycle_s
    assert rbc.effective_status(5) is SectionStatus.DO_NOT_USE
    net.step(5)
    assert len(rbc.alarms) == 1  # raised once, not every cycle


def test_one_section_alarm_per_transition_even_while_not_fresh():
    centre, rbc, net = rbc_pair(max_correction_age_s=0.5)
    centre.set_section(5, SectionStatus.DO_NOT_USE)
    centre.set_section(6, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    net.step(20)  # corrections go stale after 2 cycles and stay stale
    assert rbc.first_alarm(AlarmCode.CORRECTION_STALE) is not None
    assert [a.section_id for a in rbc.alarms if a.code is AlarmCode.SECTION_DO_NOT_USE] == [5]
    centre.set_section(5, SectionStatus.OK)
    net.step(2)
    centre.set_section(5, SectionStatus.DO_NOT_USE)
    net.step(2)
    assert [a.section_id for a in rbc.alarms if a.code is AlarmCode.SECTION_DO_NOT_USE] == [5, 5]


def test_centre_alarms_repeat_until_acknowledged_and_are_deduplicated():
    centre, rbc, net = rbc_pair()
    centre.set_section(1, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    net.step(4)
    lost = iter([True, True])  # the first two RSDs carrying the alarm are lost: the link drops
    net.drop_to_right = lambda f: f[1] in RSD_TYPES and next(lost, False)
    alarm_id = centre.raise_alarm(AlarmCode.STATION_FAILED, Severity.WARNING, text="station 7 silent")
    net.step(1)
    assert centre.unacked and rbc.first_alarm(AlarmCode.STATION_FAILED) is None
    net.step(TIMING.resync_bound_cycles + 2)  # repeated through the resynchronisation
    got = [a for a in rbc.alarms if a.code is AlarmCode.STATION_FAILED]
    assert len(got) == 1 and got[0].alarm_id == alarm_id and got[0].text == "station 7 silent"
    assert centre.unacked == {} and centre.stats["alarms_acked"] == 1


def test_correction_age_watchdog():
    centre, rbc, net = rbc_pair(max_correction_age_s=1.0)
    centre.set_section(1, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    net.step(2)
    for _ in range(8):  # fresh corrections every cycle
        centre.corrections_updated(2_000, produced_at_s=net.now)
        net.step(1)
    assert rbc.effective_status(1) is SectionStatus.OK and rbc.alarms == []
    stopped_at = net.now  # the network engine stops producing
    net.step(12)
    alarm = rbc.first_alarm(AlarmCode.CORRECTION_STALE)
    assert alarm is not None and alarm.origin == "watchdog"
    assert 1.0 <= alarm.at_s - stopped_at <= 1.0 + 2 * TIMING.cycle_s
    assert rbc.effective_status(1) is SectionStatus.DO_NOT_USE
    assert sum(a.code is AlarmCode.CORRECTION_STALE for a in rbc.alarms) == 1
    centre.corrections_updated(3_000, produced_at_s=net.now)
    net.step(2)
    assert rbc.effective_status(1) is SectionStatus.OK and rbc.stats["cleared_correction_stale"] == 1


def test_link_loss_alarms_and_everything_becomes_do_not_use():
    centre, rbc, net = rbc_pair()
    centre.set_section(1, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    net.step(4)
    cut_at = net.now
    net.cut = True
    net.step(6)
    alarm = rbc.first_alarm(AlarmCode.LINK_LOST)
    assert alarm is not None and alarm.at_s - cut_at <= (TIMING.delay_time + 1) * TIMING.cycle_s
    assert rbc.effective_status(1) is SectionStatus.DO_NOT_USE
    net.cut = False
    centre.corrections_updated(2_000, produced_at_s=net.now)
    net.step(TIMING.resync_bound_cycles)
    assert rbc.effective_status(1) is SectionStatus.OK


def test_rbc_counts_undecodable_payloads_and_keeps_going():
    centre_ep = Endpoint(CENTRE, RBC, TIMING)
    rbc = RbcSimulator(Endpoint(RBC, CENTRE, TIMING))
    now = 0.0
    for payload in [b"", b"\x01\x01", b"\x09\x01\x00\x00", b"\x01\x7f\x02\x00ab", b"\x01\x03\x01\x00z"] * 3:
        frames, _ = centre_ep.cycle(payload)
        for f in rbc.cycle(now):
            centre_ep.receive(f)
        for f in frames:
            rbc.receive(f, now)
        now += 0.25
    assert rbc.endpoint.is_up
    assert rbc.stats["truncated"] >= 2 and rbc.stats["version"] >= 2 and rbc.stats["unknown_type"] >= 2
    assert rbc.stats["length"] >= 2 and rbc.view.report_cycle is None


BALISES = {70_001: BaliseLocation(3, 1_000_000), 70_002: BaliseLocation(3, 1_500_000), 70_003: BaliseLocation(3, 2_000_000)}


def atp_pair():
    onboard = OnboardAtpLink(Endpoint(ONBOARD, ATP, TIMING), train_id=1001)
    atp = AtpSimulator(Endpoint(ATP, ONBOARD, TIMING), BALISES)
    return onboard, atp, Lockstep(onboard, atp)


def passage(onboard, group, **kw):
    args = dict(time_ms=1, balise_group=group, location=BALISES.get(group, BaliseLocation(3, 5)), reverse=False,
                confidence_mm=900, speed_mm_s=40_000)
    args.update(kw)
    return onboard.report_balise(**args)


def test_virtual_balise_passages_survive_lost_frames_and_are_taken_once():
    onboard, atp, net = atp_pair()
    net.step(3)
    assert onboard.is_up
    lost = iter([True, True])  # two in a row: the ATP's link drops and resynchronises
    net.drop_to_right = lambda f: f[1] in RSD_TYPES and decode_frame(f).data != b"" and next(lost, False)
    passage(onboard, 70_001)
    net.step(TIMING.resync_bound_cycles + 2)
    passage(onboard, 70_002)
    net.step(4)
    assert [t.balise_group for t in atp.passages] == [70_001, 70_002]
    assert atp.stats["duplicate"] >= 1 and onboard.pending == [] and onboard.stats["acked"] == 2
    assert [a.kind for a in atp.alarms] == ["LINK_LOST"]


def test_unacknowledged_passages_expire():
    onboard, atp, net = atp_pair()
    net.step(3)
    net.cut = True
    passage(onboard, 70_001)
    net.step(int(onboard.max_age_s / TIMING.cycle_s) + 2)
    assert onboard.pending == [] and onboard.stats["expired"] == 1 and atp.passages == []


def test_atp_rejects_unknown_mismatched_and_out_of_order_passages():
    onboard, atp, net = atp_pair()
    net.step(3)
    passage(onboard, 70_002)
    passage(onboard, 99_999)  # not in the ATP's map
    passage(onboard, 70_003, location=BaliseLocation(3, 2_000_500))  # map disagrees
    passage(onboard, 70_001)  # behind the last passage while running forward
    passage(onboard, 70_003, integrity=SectionStatus.DO_NOT_USE)
    net.step(4)
    assert [t.balise_group for t in atp.passages] == [70_002, 70_003]
    kinds = [a.kind for a in atp.alarms]
    assert kinds == ["UNKNOWN_BALISE", "MAP_MISMATCH", "PASSAGE_ORDER", "INTEGRITY_LOST"]
    assert atp.stats["unknown_balise"] == atp.stats["map_mismatch"] == atp.stats["order"] == 1


def test_onboard_restart_new_passages_are_taken_stale_acks_do_not_swallow_them():
    onboard, atp, net = atp_pair()
    net.step(3)
    for group in (70_001, 70_002):
        passage(onboard, group)
        net.step(2)
    assert [t.balise_group for t in atp.passages] == [70_001, 70_002]
    # reboot: a new endpoint (TC from 0) and a new link object, whose ids start elsewhere
    restarted = OnboardAtpLink(Endpoint(ONBOARD, ATP, TIMING, initial_tc=0), train_id=1001)
    net.left = restarted
    passage(restarted, 70_003)
    net.step(TIMING.resync_bound_cycles + 4)
    assert [t.balise_group for t in atp.passages] == [70_001, 70_002, 70_003]
    assert restarted.pending == [] and restarted.stats["expired"] == 0


def test_centre_restart_new_alarms_reach_the_rbc():
    centre, rbc, net = rbc_pair()
    centre.set_section(1, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    net.step(4)
    centre.raise_alarm(AlarmCode.OPERATOR, Severity.INFO, text="before restart")
    net.step(3)
    restarted = CentreRbcLink(Endpoint(CENTRE, RBC, TIMING, initial_tc=0))  # random first alarm id
    restarted.set_section(1, SectionStatus.OK)
    restarted.corrections_updated(2_000, produced_at_s=net.now)
    net.left = restarted
    restarted.raise_alarm(AlarmCode.OPERATOR, Severity.INFO, text="after restart")
    net.step(TIMING.resync_bound_cycles + 4)
    texts = [a.text for a in rbc.alarms if a.code is AlarmCode.OPERATOR]
    assert texts == ["before restart", "after restart"] and restarted.unacked == {}


def test_a_centre_without_corrections_yet_is_reported_as_such_not_as_a_huge_age():
    centre, rbc, net = rbc_pair(max_correction_age_s=1.0)
    centre.set_section(1, SectionStatus.OK)
    net.step(4)  # reports flow, but the centre has produced no corrections
    alarm = rbc.first_alarm(AlarmCode.CORRECTION_STALE)
    assert alarm is not None and alarm.text == "no corrections yet", alarm


def test_service_brake_request_survives_lost_frames_and_is_taken_once():
    onboard, atp, net = atp_pair()
    net.step(4)
    onboard.request_service_brake(time_ms=5, text="2 consecutive linked groups missed")
    lost = {"n": 0}

    def drop_first(frame):  # the first RSD carrying the request is lost: it must be repeated
        lost["n"] += 1
        return lost["n"] == 1

    net.drop_to_right = drop_first
    net.step(8)
    assert len(atp.service_brake_requests) == 1 and atp.service_brake_requests[0].code is AlarmCode.SERVICE_BRAKE
    assert [a.kind for a in atp.alarms].count("SERVICE_BRAKE") == 1
    assert onboard.pending == [] and onboard.stats["service_brake_requests"] == 1 and lost["n"] > 1
    assert atp.passages == []  # not mistaken for a balise passage
