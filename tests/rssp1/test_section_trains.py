"""SECTION_TRAINS (0x06): the section register's queues to the RBC over RSSP-I, state sent in turn."""

from __future__ import annotations

import pytest

from rssp1.frames import MAX_RSD_DATA_BYTES
from rssp1.messages import (MessageType, SectionStatus, SectionTrain, SectionTrains, TrainIntegrity, decode_payload,
                            encode_message)
from rssp1.rbc import SECTION_TRAINS_RESERVE_BYTES

from .test_rbc_atp import rbc_pair


def train(tid, km, **kw):
    return SectionTrain(tid, "L1-1", int(km * 1e6), 83_333, 2090, TrainIntegrity.UNKNOWN, **kw)


def test_round_trip_and_layout():
    msg = SectionTrains(1_000_500, 2, 1, 7, (train("G303", 120.5, correction_age_ms=800, along_pl_cm=41,
                                                   cross_pl_cm=22, hpl_cm=35, report_ms=1_000_000),
                                             train("G101", 80.0)))
    data = encode_message(msg)
    assert data[1] == MessageType.SECTION_TRAINS and len(data) == 4 + 16 + 2 * 69
    out = decode_payload(data)
    assert out.messages == [msg] and not out.errors


@pytest.mark.parametrize("damage, reason", [
    (lambda b: b[:-3], "truncated"),  # the header promises more than is there
    (lambda b: b[:14] + bytes([2]) + b[15:], "value"),  # direction 2 (header 4, epoch 8, section 2)
    (lambda b: b[:20 + 50] + bytes([9]) + b[20 + 51:], "value"),  # integrity 9 (after id, track, km, speed, length)
    (lambda b: b[:4 + 16] + bytes(20) + b[4 + 16 + 20:], "value"),  # empty train id
])
def test_bad_telegrams_are_counted_not_decoded(damage, reason):
    data = bytearray(encode_message(SectionTrains(1, 2, 0, 1, (train("G101", 80.0),))))
    out = decode_payload(bytes(damage(data)))
    assert not out.messages and out.errors[reason] == 1


def test_rbc_holds_every_section_picture_in_order():
    centre, rbc, net = rbc_pair()
    centre.set_section(1, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    pictures = {(sid, d): SectionTrains(5_000, sid, d, sid + d, tuple(train(f"T{sid}{d}{i}", 10.0 * sid + i)
                                                                     for i in range(4)))
                for sid in range(1, 9) for d in (0, 1)}
    for m in pictures.values():
        centre.set_section_trains(m)
    net.step(12)  # 16 pictures of ~300 bytes, ~4 per RSD: all delivered within a few cycles
    assert rbc.view.section_trains == pictures
    # a new picture replaces the old one at the RBC; an older one (a late frame) never does
    newer = SectionTrains(6_000, 3, 0, 9, (train("T300", 31.0), train("T301", 30.5)))
    centre.set_section_trains(newer)
    net.step(6)
    assert [t.train_id for t in rbc.view.section_trains[(3, 0)].trains] == ["T300", "T301"]
    rbc._apply(encode_message(pictures[(3, 0)]))
    assert rbc.view.section_trains[(3, 0)] == newer


def test_a_section_too_full_for_one_rsd_is_refused():
    centre, _rbc, _net = rbc_pair()
    n = (MAX_RSD_DATA_BYTES - SECTION_TRAINS_RESERVE_BYTES) // 69 + 1
    with pytest.raises(ValueError):
        centre.set_section_trains(SectionTrains(1, 1, 0, 1, tuple(train(f"T{i}", i) for i in range(n))))


def test_a_changed_picture_goes_first_when_a_round_takes_many_cycles():
    """21 sections x 2 directions x 10 trains: one picture (710 bytes) per RSD, a round of 42 cycles; a
    change still reaches the RBC in the next cycle."""
    centre, rbc, net = rbc_pair()
    centre.set_section(1, SectionStatus.OK)
    centre.corrections_updated(1_000, produced_at_s=net.now)
    for sid in range(1, 22):
        for d in (0, 1):
            trains = tuple(train(f"T{sid}{d}{i}", i) for i in range(10))
            centre.set_section_trains(SectionTrains(5_000, sid, d, 1, trains))
    net.step(60)
    assert len(rbc.view.section_trains) == 42
    changed = SectionTrains(6_000, 17, 1, 2, (train("G9", 170.0),))
    centre.set_section_trains(changed)
    net.step(1)  # the next cycle carries it (the round would reach it 15 cycles later)
    assert rbc.view.section_trains[(17, 1)] == changed
