"""Application messages: round trips, exact lengths, and bad input counted, never raised."""

from __future__ import annotations

import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from rssp1.messages import (
    Alarm,
    AlarmCode,
    CorrectionAge,
    Exclusions,
    IntegrityStatus,
    MessageType,
    RbcAck,
    SectionIntegrity,
    SectionStatus,
    Severity,
    VirtualBaliseTelegram,
    decode_payload,
    encode_message,
    encode_payload,
)

SAMPLE = [
    IntegrityStatus(1_400_000_000_000, 42, (SectionIntegrity(1, SectionStatus.OK, 12), SectionIntegrity(2, SectionStatus.DEGRADED),
                                          SectionIntegrity(3, SectionStatus.DO_NOT_USE, 250))),
    Exclusions(1_400_000_000_000, ("G05", "C19", "E11"), (7, 12)),
    CorrectionAge(1_400_000_000_000, 1500, 10_000),
    Alarm(1_400_000_000_000, 9, AlarmCode.SECTION_DO_NOT_USE, Severity.CRITICAL, 3, "section 3: ionosphere gradient"),
    RbcAck(42, (9, 10)),
    VirtualBaliseTelegram(1_400_000_000_500, 1001, 70_012, 3, 12_345_678, False, 850, 44_000, SectionStatus.OK, 17),
]


def test_round_trip_of_every_message_type():
    payload = encode_payload(SAMPLE)
    result = decode_payload(payload)
    assert result.messages == SAMPLE and not result.errors
    assert {type(m) for m in SAMPLE} == {type(m) for m in result.messages}
    assert len(encode_message(SAMPLE[0])) == 4 + 14 + 3 * 5  # header + fixed + 3 sections


def test_bad_messages_are_counted_and_skipped_the_rest_decodes():
    good = encode_message(SAMPLE[2])
    wrong_version = b"\x02" + good[1:]
    unknown_type = struct.pack("<BBH", 1, 0x7E, 3) + b"abc"
    short_body = struct.pack("<BBH", 1, MessageType.CORRECTION_AGE, 3) + b"abc"
    long_list = bytearray(encode_message(SAMPLE[0]))
    long_list[4 + 12] = 9  # n_sections claims 9, body holds 3
    bad_status = bytearray(encode_message(SAMPLE[0]))
    bad_status[4 + 14 + 2] = 7  # a section status that does not exist
    payload = b"".join([wrong_version, good, unknown_type, short_body, bytes(long_list), bytes(bad_status), good])
    result = decode_payload(payload + b"\x01\x01")  # and a truncated header at the end
    assert result.messages == [SAMPLE[2], SAMPLE[2]]
    assert dict(result.errors) == {"version": 1, "unknown_type": 1, "length": 2, "value": 1, "truncated": 1}
    claims_too_much = struct.pack("<BBH", 1, 1, 500) + b"x" * 10
    assert dict(decode_payload(claims_too_much).errors) == {"truncated": 1}


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=120))
def test_decoder_never_raises(data):
    result = decode_payload(data)
    for m in result.messages:  # whatever decodes re-encodes to a message that decodes the same
        assert decode_payload(encode_message(m)).messages == [m]


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.tuples(st.integers(0, 0xFFFE), st.sampled_from(list(SectionStatus)), st.integers(0, 0xFFFF)), max_size=60),
    st.integers(0, 2**64 - 1), st.integers(0, 2**32 - 1),
)
def test_integrity_status_round_trips(sections, epoch, seq):
    msg = IntegrityStatus(epoch, seq, tuple(SectionIntegrity(*s) for s in sections))
    assert decode_payload(encode_message(msg)).messages == [msg]
