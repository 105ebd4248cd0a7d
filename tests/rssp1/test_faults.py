"""Fault injection on the sans-IO endpoint, threat by threat (EN 50159 / rssp1.md), with counts."""

from __future__ import annotations

import random
import struct
from collections import deque

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rssp1 import checkword
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.crc import crc16
from rssp1.endpoint import DataReceived, Endpoint, FrameDropped, LinkState
from rssp1.frames import encode_rsd, encode_ssr
from rssp1.timestamp import timestamp_at

from .linkpair import CENTRE, RBC, LinkPair, downs, received, ups

FIELD = LinkTiming(cycle_s=0.25, delta_time=3, life_time=4, delay_time=3)  # rssp1.md field example


def with_fixed_crc16(frame: bytes) -> bytes:
    return frame[:-2] + struct.pack("<H", crc16(frame[:-2]))


def drive(pair: LinkPair, cycles: int):
    events = []
    for _ in range(cycles):
        events += pair.step(b"msg%04d" % pair.cycle_no)
    return events


def test_link_comes_up_and_carries_data_both_ways():
    pair = LinkPair(FIELD)
    assert pair.bring_up() <= 3
    events = drive(pair, 50)
    assert received(events) == [b"msg%04d" % i for i in range(pair.cycle_no - 50, pair.cycle_no)]
    assert sum(1 for e in pair.a_events if isinstance(e, DataReceived)) >= 50
    assert downs(pair.b_events) == [] and pair.b.stats["link_up"] == 1
    assert pair.b.stats["tx_sse"] == 1 and pair.a.stats["tx_ssr"] == 1


def test_repetition_is_dropped_silently():
    pair = LinkPair(FIELD)
    pair.bring_up()
    pair.to_b = lambda cycle, frame: [frame, frame]
    events = drive(pair, 20)
    assert len(received(events)) == 20 and pair.b.stats["dropped_repeat"] == 20
    # replaying the whole recorded stream later is repetition too
    pair.to_b = lambda cycle, frame: [frame]
    old = [f for f in pair.sent_to_b if f[1] in (0x80, 0x81)]
    before = pair.b.stats["rx_rsd_ok"]
    replay_events = [e for f in old for e in pair.b.receive(f)]
    assert received(replay_events) == [] and pair.b.stats["rx_rsd_ok"] == before
    assert pair.b.stats["dropped_repeat"] == 20 + len(old)
    assert downs(pair.b_events) == [] and pair.b.is_up


def test_deletion_single_losses_tolerated_two_in_a_row_drop_the_link():
    pair = LinkPair(FIELD)
    pair.bring_up()
    pair.to_b = lambda cycle, frame: [] if cycle % 5 == 0 else [frame]
    events = drive(pair, 20)
    assert len(received(events)) == 16 and downs(events) == []  # gap 2 < deltaTime 3
    lost = {pair.cycle_no, pair.cycle_no + 1}  # two consecutive: gap 3 = deltaTime
    pair.to_b = lambda cycle, frame: [] if cycle in lost else [frame]
    sse_before = pair.b.stats["tx_sse"]
    events = drive(pair, 3)
    assert downs(events) == ["gap"] and pair.b.stats["dropped_gap"] == 1
    pair.step()
    assert pair.b.stats["tx_sse"] == sse_before + 1  # the detecting side asks for resynchronisation
    events = drive(pair, 4)
    assert ups(events) == 1 and pair.b.is_up
    # three in a row: the DelayTime watchdog fires before any gap can be seen
    lost = {pair.cycle_no, pair.cycle_no + 1, pair.cycle_no + 2}
    events = drive(pair, 4)
    assert downs(events) == ["timeout"]


def test_insertion_by_a_stranger_or_with_bad_check_words_is_rejected():
    pair = LinkPair(FIELD)
    pair.bring_up()
    stranger = DeviceConfig(0x0077, (0xDEADBEEF, 0x01234567))
    t = timestamp_at(stranger.sid, 5)
    from_stranger = encode_rsd(0x0077, RBC.address, 5, checkword.svc(b"evil", stranger.sid, t), b"evil")
    next_tc = pair.a.tc
    rng = random.Random(11)
    bad_svc = [encode_rsd(CENTRE.address, RBC.address, next_tc + k, (rng.getrandbits(32), rng.getrandbits(32)), b"evil")
               for k in range(2)]
    unsolicited_ssr = encode_ssr(CENTRE.address, RBC.address, next_tc, 1234, (1, 2))
    events = [e for f in [from_stranger, *bad_svc, unsolicited_ssr] for e in pair.b.receive(f)]
    assert received(events) == []
    assert pair.b.stats["dropped_address"] == 1
    assert pair.b.stats["dropped_svc"] == 2
    assert pair.b.stats["dropped_ssr_unexpected"] == 1
    events = drive(pair, 5)  # the real stream continues untouched
    assert len(received(events)) == 5 and downs(pair.b_events) == []


def test_resequencing_keeps_only_newer_frames_in_order():
    pair = LinkPair(FIELD)
    pair.bring_up()
    held: list[bytes] = []

    def swap_pairs(cycle, frame):
        if not held:
            held.append(frame)
            return []
        return [frame, held.pop()]  # n+1 arrives before n

    pair.to_b = swap_pairs
    events = drive(pair, 20)
    got = received(events)
    assert len(got) == 10 and pair.b.stats["dropped_repeat"] == 10
    assert got == sorted(got) and downs(events) == []


def test_every_single_bit_flip_is_detected():
    pair = LinkPair(FIELD)
    pair.bring_up()
    accepted_before = pair.b.stats["rx_rsd_ok"]
    dropped_before = sum(v for k, v in pair.b.stats.items() if k.startswith("dropped_"))
    frame = None

    def capture(cycle, f):
        nonlocal frame
        frame = f
        return []

    pair.to_b = capture
    pair.step(b"integrity: section 12 OK")
    assert frame is not None and len(frame) == 46
    flips = 0
    for bit in range(len(frame) * 8):
        corrupted = bytearray(frame)
        corrupted[bit // 8] ^= 1 << (bit % 8)
        assert received(pair.b.receive(bytes(corrupted))) == []
        flips += 1
    rejected = sum(v for k, v in pair.b.stats.items() if k.startswith("dropped_")) - dropped_before
    assert flips == 368 and rejected == 368 and pair.b.stats["rx_rsd_ok"] == accepted_before
    assert pair.b.stats["dropped_crc16"] + pair.b.stats["dropped_length"] + pair.b.stats["dropped_type"] == 368
    # the true frame still goes through afterwards
    assert received(pair.b.receive(frame)) == [b"integrity: section 12 OK"]


def test_bit_flips_that_pass_crc16_are_caught_by_the_check_words():
    """An adversarial channel that recomputes CRC16: the safety code still protects TC, source and data.

    Only the category byte and the A/B bit of the type are outside the safety code (they are not
    safety data: A and B carry the same data); those flips deliver the original data unchanged.
    """
    pair = LinkPair(FIELD)
    pair.bring_up()
    sent: list[bytes] = []
    pair.to_b = lambda cycle, f: sent.append(f) or []
    pair.step(b"integrity: section 12 OK")
    frame = sent[-1]
    outcomes = {"rejected": 0, "header_only": 0}
    for bit in range(len(frame[:-2]) * 8):
        corrupted = bytearray(frame)
        corrupted[bit // 8] ^= 1 << (bit % 8)
        probe = Endpoint(pair.b.local, pair.b.peer, FIELD)  # a copy of B's state per probe
        probe.__dict__.update({k: (v.copy() if hasattr(v, "copy") else v) for k, v in pair.b.__dict__.items()})
        got = received(probe.receive(with_fixed_crc16(bytes(corrupted))))
        if got:
            assert got == [b"integrity: section 12 OK"]
            assert bit < 8 or bit == 8  # category byte, or bit 0 of the type (0x80 <-> 0x81)
            outcomes["header_only"] += 1
        else:
            outcomes["rejected"] += 1
    assert outcomes == {"rejected": 44 * 8 - 9, "header_only": 9}


def test_random_bursts_are_detected():
    rng = random.Random(20260707)
    pair = LinkPair(FIELD)
    pair.bring_up()
    sent: list[bytes] = []
    pair.to_b = lambda cycle, f: sent.append(f) or [f]
    bursts = rejected = 0
    for _ in range(300):
        pair.step(bytes(rng.getrandbits(8) for _ in range(rng.randrange(1, 64))))
        frame = sent[-1]
        for _ in range(5):
            n_bits = len(frame) * 8
            length = rng.randrange(2, 65)
            start = rng.randrange(0, n_bits - length)
            value = int.from_bytes(frame, "little") ^ ((rng.getrandbits(length - 2) << 1 | 1 | 1 << (length - 1)) << start)
            corrupted = value.to_bytes(len(frame), "little")
            bursts += 1
            ev = pair.b.receive(corrupted)
            rejected += not received(ev)
    assert bursts == rejected == 1500
    assert pair.b.is_up and downs(pair.b_events) == []


class DelayLine:
    def __init__(self) -> None:
        self.delay = 0
        self.queue: deque[tuple[int, bytes]] = deque()

    def __call__(self, cycle: int, frame: bytes) -> list[bytes]:
        self.queue.append((cycle + self.delay, frame))
        out = []
        while self.queue and self.queue[0][0] <= cycle:
            out.append(self.queue.popleft()[1])
        return out


@pytest.mark.parametrize(
    "timing", [FIELD, LinkTiming(cycle_s=0.25, delta_time=3, life_time=4, delay_time=8)], ids=["field", "long_delaytime"]
)
def test_delay_within_limits_is_accepted_beyond_limits_drops_the_link_until_it_ends(timing):
    """Field timing: the DelayTime watchdog fires before the first stale frame arrives. With a long
    DelayTime the stale frames do arrive, and the freshness rule (TC older than the estimate of the
    sender's TC by deltaTime or more) drops them."""
    pair = LinkPair(timing)
    pair.bring_up()
    to_b, to_a = DelayLine(), DelayLine()
    pair.to_b, pair.to_a = to_b, to_a
    to_b.delay = to_a.delay = 1
    events = drive(pair, 20)
    assert len(received(events)) == 19 and downs(events) == [] and pair.b.stats["dropped_late"] == 0
    # The bearer's delay grows by one cycle every other cycle up to 6 (beyond deltaTime = 3): the
    # TC gaps stay at 2, so only the freshness rule can notice that the frames are getting stale.
    events = []
    for i in range(40):
        to_b.delay = to_a.delay = min(1 + i // 2, 6)
        events += drive(pair, 1)
    # Stale frames are dropped (`late`); the link then falls to the DelayTime watchdog, or with a
    # long DelayTime to the gap rule, as the stale frames leave last-accepted TC further behind.
    assert downs(events) == (["timeout"] if timing is FIELD else ["gap"])
    assert pair.b.stats["dropped_late"] >= 1
    accepted_tcs = [e.tc for e in events if isinstance(e, DataReceived)]
    assert all(tc - 1000 < 20 + 8 for tc in accepted_tcs)  # nothing sent after the delay passed 3
    # SSE -> SSR round trips of 8+ cycles exceed lifeTime (4): never resynchronised while delayed
    assert pair.b.stats["dropped_ssr_stale"] + pair.b.stats["dropped_ssr_unexpected"] >= 3
    assert pair.b.stats["link_up"] == 1 and not pair.b.is_up
    to_b.delay = to_a.delay = 0
    start = pair.cycle_no
    while not pair.b.is_up:
        pair.step()
        assert pair.cycle_no - start <= timing.resync_bound_cycles
    assert pair.b.stats["link_up"] == 2


@pytest.mark.parametrize("wrong", ["sid", "dataver"])
def test_wrong_sid_or_dataver_never_brings_the_link_up(wrong):
    """The receiver holds a wrong SID or DATAVER for the sender.

    Changed expectation (a protocol reason, not a tolerance): the SSR reveals the sender's timestamp
    at TC_R, T(TC_R) = SEQINI ^ SEQENQ ^ SID ^ DATAVER, and the timestamp of a TC is SINIT advanced
    TC cycles (rssp1.md "Codes": T(0) = SID_i, T(n) = LFSR_i(T(n-1)); SVC_i carries T_i(TC)). Decoded
    with a wrong SID or DATAVER it is not T(TC_R), so the SSR is refused (`ssr_inconsistent`) and the
    link never reaches SYNCING. Before TC_R was bound to its timestamp the SSR was taken and every RSD
    then failed against it (`svc`, `sync_failed`); that path is still tested where the SSR check
    cannot see a SID error (TC_R = 0, test_wrong_sid_that_cancels_in_the_ssr_...)."""
    real = CENTRE
    if wrong == "sid":
        as_seen = DeviceConfig(real.address, (real.sid[0], real.sid[1] ^ 0x00010000), real.dataver)
    else:
        as_seen = DeviceConfig(real.address, real.sid, (real.dataver[0] ^ 1, real.dataver[1]))
    pair = LinkPair(FIELD, sender_as_seen=as_seen)
    events = drive(pair, 40)
    assert received(events) == [] and pair.b.stats["link_up"] == 0
    st_ = pair.b.stats
    assert st_["rx_ssr"] >= 5 and st_["dropped_ssr_inconsistent"] == st_["rx_ssr"]  # every SSR refused
    assert st_["ssr_accepted"] == 0 and st_["sync_failed"] == 0 and pair.b.state is LinkState.DOWN
    assert st_["dropped_unsynchronised"] == 40  # so no RSD is even checked
    assert pair.a.is_up  # the other direction is fine


def test_wrong_sid_that_cancels_in_the_ssr_is_caught_by_the_sync_point_rule_and_the_check_words():
    """With SINIT = SID, a SID error d shows in the SSR check as (I ^ M^TC_R) d, which is zero at
    TC_R = 0: a sender that has just started answers an SSE at TC 0. The SSR is then taken, the RSD
    at TC_R is not (`at_sync_point`: there d cancels too), and from TC_R + 1 on the check words see
    d (I ^ M^k invertible, test_wrong_sid_cannot_cancel_for_any_allowed_gap)."""
    as_seen = DeviceConfig(CENTRE.address, (CENTRE.sid[0], CENTRE.sid[1] ^ 0x00010000), CENTRE.dataver)
    a = Endpoint(CENTRE, RBC, FIELD, initial_tc=0)
    b = Endpoint(RBC, as_seen, FIELD, initial_tc=50)
    for f in b.cycle(b"ack")[0]:  # B is down: its SSE
        a.receive(f)
    frames = a.cycle(b"data 0")[0]  # the SSR with TC_R = 0, then the RSD with TC 0
    events = [e for f in frames for e in b.receive(f)]
    assert b.stats["ssr_accepted"] == 1 and b.stats["dropped_at_sync_point"] == 1
    for n in range(1, 20):
        frames_b, events_b = b.cycle(b"ack")
        events += events_b
        for f in a.cycle(b"data %d" % n)[0]:
            events += b.receive(f)
        for f in frames_b:  # B's next SSEs: answered at TC_R > 0, where the SSR check sees d
            a.receive(f)
    assert received(events) == [] and b.stats["link_up"] == 0
    assert b.stats["dropped_svc"] >= 2 and b.stats["sync_failed"] == 1
    assert b.stats["ssr_accepted"] == 1 and b.stats["dropped_ssr_inconsistent"] >= 2


def test_tc_r_and_following_tcs_shifted_by_the_bearer_are_refused():
    """The fault Hypothesis found: a bearer flips the same bit of the TC field in every frame and
    recomputes CRC16, so the SSR's TC_R and the TCs of the RSDs after it move by the same offset.
    The RSD check words only bind TC differences to timestamp steps, so without binding TC_R to its
    own timestamp the receiver delivered genuine data under a TC the sender used for other data."""
    pair = LinkPair(FIELD)
    sent: dict[int, bytes] = {}

    def shift_tc(cycle, frame):
        bad = bytearray(frame)
        bad[6] ^= 1 << 2  # bit 2 of the TC field (TC_R in an SSR)
        return [with_fixed_crc16(bytes(bad))]

    pair.to_b = shift_tc
    events = []
    for n in range(30):
        sent[pair.a.tc] = b"cycle %d" % n
        events += pair.step(b"cycle %d" % n)
    st_ = pair.b.stats
    assert received(events) == [] and st_["ssr_accepted"] == 0 and st_["link_up"] == 0
    assert st_["rx_ssr"] >= 5 and st_["dropped_ssr_inconsistent"] == st_["rx_ssr"]
    pair.to_b = lambda cycle, frame: [frame]  # clean bearer: up within the bound, labels right
    for n in range(FIELD.resync_bound_cycles):
        sent[pair.a.tc] = b"clean %d" % n
        events += pair.step(b"clean %d" % n)
    assert pair.b.is_up
    got = [e for e in events if isinstance(e, DataReceived)]
    assert got and all(sent[e.tc] == e.data for e in got)


def test_every_tc_r_bit_flip_past_crc16_is_refused_and_keeps_the_sse_open():
    pair = LinkPair(FIELD)
    captured: list[bytes] = []
    pair.to_b = lambda cycle, frame: captured.append(frame) or []
    pair.step()  # B sends its SSE
    pair.step()  # A answers: SSR (to the capture)
    ssr = next(f for f in captured if f[1] == 0x91)
    for bit in range(32):
        bad = bytearray(ssr)
        bad[6 + bit // 8] ^= 1 << (bit % 8)
        assert pair.b.receive(with_fixed_crc16(bytes(bad))) == [FrameDropped("ssr_inconsistent")], bit
    assert pair.b.stats["dropped_ssr_inconsistent"] == 32 and pair.b.state is LinkState.DOWN
    # a refused SSR does not use up the SSE: the true SSR, arriving later within lifeTime, is taken
    assert pair.b.receive(ssr) == [] and pair.b.state is LinkState.SYNCING


def test_sinit_from_configuration_is_what_tc_r_is_checked_against():
    """SINIT (T(0)) is per-device configuration (rssp1.md); both ends must hold the same value."""
    centre = DeviceConfig(CENTRE.address, CENTRE.sid, CENTRE.dataver, sinit=(0x0BADF00D, 0x600DCAFE))
    pair = LinkPair(FIELD, sender=centre)
    pair.bring_up()
    assert len(received(drive(pair, 10))) == 10
    # the receiver holds the default SINIT (= SID) for a sender seeded otherwise: every SSR refused
    pair = LinkPair(FIELD, sender=centre, sender_as_seen=CENTRE)
    events = drive(pair, 20)
    st_ = pair.b.stats
    assert received(events) == [] and st_["ssr_accepted"] == 0
    assert st_["rx_ssr"] >= 3 and st_["dropped_ssr_inconsistent"] == st_["rx_ssr"]


@pytest.mark.parametrize(
    "timing", [FIELD, LinkTiming(cycle_s=0.1, delta_time=5, life_time=3, delay_time=6)], ids=["field", "lenient"]
)
def test_resynchronisation_after_link_loss_within_configured_cycles(timing):
    worst = 0
    for outage in range(1, 25):
        pair = LinkPair(timing)
        pair.bring_up()
        pair.to_b = pair.to_a = lambda cycle, f: []
        pair.run(outage)
        pair.to_b = pair.to_a = lambda cycle, f: [f]
        # lost frames = outage: the gap rule fires at outage + 1 >= deltaTime, the watchdog at
        # outage >= DelayTime
        short = outage + 1 < timing.delta_time and outage < timing.delay_time
        up_since = 0
        for n in range(1, timing.resync_bound_cycles + 4):
            pair.step()
            up_since = up_since if (pair.a.is_up and pair.b.is_up) else n
        assert pair.b.stats["link_down"] == (0 if short else 1), outage
        assert pair.a.stats["link_down"] == (0 if short else 1), outage
        assert up_since <= timing.resync_bound_cycles, (outage, up_since, pair.b.stats)
        worst = max(worst, up_since)
    assert worst <= timing.resync_bound_cycles


def test_tc_wraps_around_u32():
    pair = LinkPair(FIELD, initial_tc=(1 << 32) - 5)
    pair.bring_up()
    events = drive(pair, 20)
    assert len(received(events)) == 20 and downs(events) == []
    assert pair.a.tc < 100


def test_after_the_tc_wrap_the_timestamp_restarts_from_sinit_and_the_link_resynchronises():
    """T is a function of the TC field, T(TC) = LFSR^TC(SINIT), which is what binds a TC label. The
    LFSRs' period is 2^32 - 1, not 2^32, so the sender starts again from SINIT when TC wraps to 0
    (stepping on would leave T(0) = LFSR(SINIT)); an SSR after the wrap is then checked like any
    other, and a receiver whose gap crosses the wrap takes T(TC) from SINIT."""
    pair = LinkPair(FIELD, initial_tc=(1 << 32) - 10)
    pair.bring_up()  # SSR before the wrap
    sent: dict[int, bytes] = {}
    lost = set()
    pair.to_b = lambda cycle, frame: [] if cycle in lost else [frame]
    events = []
    for n in range(12):
        if pair.a.tc == (1 << 32) - 1:
            lost.add(pair.cycle_no)  # the RSD at TC 2^32 - 1 is lost: the next gap (2) crosses the wrap
        sent[pair.a.tc] = b"w%d" % n
        events += pair.step(b"w%d" % n)
        assert pair.a._t == timestamp_at(CENTRE.timestamp_seed, pair.a.tc)
    got = [e for e in events if isinstance(e, DataReceived)]
    assert len(got) == 11 and all(sent[e.tc] == e.data for e in got) and downs(events) == []
    tcs = [e.tc for e in got]
    assert (1 << 32) - 1 not in tcs and tcs.index(0) > 0 and tcs[tcs.index(0) - 1] == (1 << 32) - 2
    # an outage after the wrap: the link drops and resynchronises with an SSR whose TC_R is small
    pair.to_b = lambda cycle, frame: []
    events = pair.run(6)
    assert downs(events) == ["timeout"]
    pair.to_b = lambda cycle, frame: [frame]
    events = pair.run(FIELD.resync_bound_cycles)
    assert pair.b.is_up and pair.b.stats["ssr_accepted"] == 2 and pair.b.stats["dropped_ssr_inconsistent"] == 0
    # a monitor primed at TC 0 verifies the first frame after a wrap
    mon = Endpoint(RBC, CENTRE, FIELD)
    mon.monitor_from(0)
    t0 = timestamp_at(CENTRE.timestamp_seed, 0)
    assert received(mon.receive(encode_rsd(CENTRE.address, RBC.address, 0, checkword.svc(b"z", CENTRE.sid, t0), b"z")))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(min_size=0, max_size=80), max_size=8))
def test_arbitrary_bytes_never_raise_and_never_deliver(blobs):
    ep = Endpoint(RBC, CENTRE, FIELD)
    for blob in blobs:
        assert received(ep.receive(blob)) == []
    ep.cycle(b"x")
    # also frames that decode: correct CRC16 on random content
    for blob in blobs:
        if len(blob) >= 2:
            assert received(ep.receive(with_fixed_crc16(b"\x01\x80" + blob + b"\0\0"))) == []


def test_wrong_sid_cannot_cancel_for_any_allowed_gap():
    """I ^ M^k invertible for every gap k a link can accept, both channels: an SID error d gives a
    prediction error (I ^ M^k) d != 0, so it is always seen (see Endpoint._receive_ssr)."""
    from rssp1.sid_recovery import solve_gf2
    from rssp1.timestamp import TIMESTAMP_LFSRS

    for lfsr in TIMESTAMP_LFSRS:
        for k in range(1, 64):
            mk = lfsr.power_map(k)
            solved = solve_gf2([(1 << i) ^ mk(1 << i) for i in range(32)], 0)
            assert solved is not None and solved[1] == [], k


@pytest.mark.parametrize("slow_side", ["sender", "receiver"])
def test_clock_drift_never_drops_the_link(slow_side):
    """One end's clock runs 2 % slow (it misses every 50th cycle: 200 times a crystal's 100 ppm).
    The receiver's estimate of the sender's TC is re-anchored by refresh SSE/SSR while the link stays up."""
    pair = LinkPair(FIELD)
    pair.bring_up()
    delivered = 0
    sent_before = pair.a.stats["tx_rsd"]
    for n in range(3000):
        skip = n % 50 == 49
        fa = [] if (skip and slow_side == "sender") else pair.a.cycle(b"x%d" % n)[0]
        fb = [] if (skip and slow_side == "receiver") else pair.b.cycle(b"ack")[0]
        for f in fa:
            delivered += len(received(pair.b.receive(f)))
        for f in fb:
            pair.a.receive(f)
    assert pair.b.stats["link_down"] == 0 and pair.a.stats["link_down"] == 0
    assert pair.b.stats["dropped_late"] == 0
    assert delivered == pair.a.stats["tx_rsd"] - sent_before >= 2940  # every frame sent got through
    if slow_side == "sender":
        assert pair.b.stats["ssr_refresh"] >= 20 and pair.b.stats["tx_sse_refresh"] == pair.b.stats["ssr_refresh"]


def test_refresh_ssr_that_breaks_the_timestamp_chain_is_refused():
    pair = LinkPair(FIELD)
    pair.bring_up()
    pair.b._refresh_wanted = True
    sse = [f for f in pair.b.cycle(b"ack")[0] if f[1] == 0x90]
    assert len(sse) == 1 and pair.b.stats["tx_sse_refresh"] == 1
    from rssp1.frames import decode_frame as _decode

    tc_e = _decode(sse[0]).tc_e
    forged = encode_ssr(CENTRE.address, RBC.address, pair.a.tc, tc_e, (0x1234, 0x5678))
    assert pair.b.receive(forged) and pair.b.stats["dropped_ssr_inconsistent"] == 1 and pair.b.is_up


def test_peer_restart_with_a_fresh_tc_resynchronises():
    """The sender reboots: its TC starts again from 0 (older than the last accepted); the receiver
    drops the 'old' frames as repeats, its DelayTime watchdog takes the link down, SSE/SSR resync."""
    pair = LinkPair(FIELD, initial_tc=5000)
    pair.bring_up()
    pair.run(10)
    pair.a = Endpoint(CENTRE, RBC, FIELD, initial_tc=0)
    events = []
    n = 0
    while not pair.b.is_up or not events or downs(events) == []:
        events += pair.step()
        n += 1
        assert n <= FIELD.resync_bound_cycles + 1, pair.b.stats
    assert downs(events) == ["timeout"] and pair.b.stats["dropped_repeat"] >= FIELD.delay_time - 1
    events = pair.run(5)
    assert len(received(events)) == 5 and pair.b.is_up
