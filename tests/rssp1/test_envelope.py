"""Open-bearer mode: forged, tampered, replayed, reflected and old-session envelopes are rejected."""

from __future__ import annotations

import pytest

from rssp1 import checkword
from rssp1.envelope import REPLAY_WINDOW, Keyring, Opener, SealedEndpoint, Sealer, random_link_key
from rssp1.frames import decode_frame, encode_rsd
from rssp1.sid_recovery import forge_rsd_svc, recover_sid

from .linkpair import CENTRE, RBC, LinkPair, received
from .test_faults import FIELD

KEY = bytes(range(32))


def sealed_pair(keyring_a: Keyring, keyring_b: Keyring) -> LinkPair:
    pair = LinkPair(FIELD)
    pair.a = SealedEndpoint(pair.a, keyring_a, session=1_000)
    pair.b = SealedEndpoint(pair.b, keyring_b, session=2_000)
    return pair


def test_sealed_link_carries_data_and_hides_it():
    pair = sealed_pair(Keyring({7: KEY}), Keyring({7: KEY}))
    pair.bring_up()
    events = pair.run(10, b"section 12 OK")
    assert received(events) == [b"section 12 OK"] * 10
    assert all(b"section 12 OK" not in f for f in pair.sent_to_b)
    assert pair.b.opener.stats["opened"] == len(pair.sent_to_b)


def test_masquerade_that_beats_rssp1_is_rejected_by_the_envelope():
    # Plain RSSP-I: an attacker who captured two frames forges a third that the receiver accepts.
    plain = LinkPair(FIELD)
    plain.bring_up()
    plain.run(3)
    rsds = [decode_frame(f) for f in plain.sent_to_b if f[1] == 0x80]
    (identity,) = recover_sid(rsds[-2], rsds[-1])
    forged = encode_rsd(CENTRE.address, RBC.address, rsds[-1].tc + 1, forge_rsd_svc(identity, rsds[-1].tc + 1, b"ALL CLEAR"), b"ALL CLEAR")
    assert received(plain.b.receive(forged)) == [b"ALL CLEAR"]  # the protocol's known weakness

    # Sealed: the same forged frame, bare or wrapped with a key the attacker does not hold, is refused.
    pair = sealed_pair(Keyring({7: KEY}), Keyring({7: KEY}))
    pair.bring_up()
    pair.run(3)
    tc = pair.a.endpoint.tc
    inner_svc = checkword.svc(b"ALL CLEAR", CENTRE.sid, (0, 0))  # even with the true SID
    forged_inner = encode_rsd(CENTRE.address, RBC.address, tc, inner_svc, b"ALL CLEAR")
    wrong_key = Sealer(Keyring({7: random_link_key()}), CENTRE.address, RBC.address, session=10**15)
    before = dict(pair.b.opener.stats)
    assert received(pair.b.receive(forged_inner)) == []
    assert received(pair.b.receive(wrong_key.seal(forged_inner))) == []
    assert pair.b.opener.stats["rejected_auth"] == before.get("rejected_auth", 0) + 1
    assert pair.b.opener.stats["rejected_short"] + pair.b.opener.stats["rejected_version"] >= 1
    assert pair.b.stats["dropped_envelope"] == 2 and pair.b.is_up


def test_tampering_with_any_byte_is_rejected():
    sealer = Sealer(Keyring({3: KEY}), 1, 2, session=5)
    opener = Opener(Keyring({3: KEY}), 1, 2)
    env = sealer.seal(b"\x01\x80frame bytes")
    for i in range(len(env)):
        for bit in (0x01, 0x80):
            bad = bytearray(env)
            bad[i] ^= bit
            assert opener.open(bytes(bad)) is None
    rejected = sum(v for k, v in opener.stats.items() if k.startswith("rejected_"))
    assert rejected == 2 * len(env) and opener.stats["opened"] == 0
    assert opener.open(env) == b"\x01\x80frame bytes"


def test_replay_window_and_sessions():
    keyring = Keyring({3: KEY})
    sealer = Sealer(keyring, 1, 2, session=100)
    opener = Opener(keyring, 1, 2)
    envs = [sealer.seal(b"f%d" % i) for i in range(200)]
    assert opener.open(envs[0]) == b"f0"
    assert opener.open(envs[0]) is None  # replay
    # out of order inside the window is fine, once
    assert opener.open(envs[10]) == b"f10" and opener.open(envs[5]) == b"f5" and opener.open(envs[5]) is None
    assert opener.open(envs[150]) == b"f150"
    assert opener.open(envs[150 - REPLAY_WINDOW]) is None  # fell out of the window
    assert opener.open(envs[150 - REPLAY_WINDOW + 1]) == b"f%d" % (150 - REPLAY_WINDOW + 1)
    assert opener.stats["rejected_replay"] == 3
    # sender restart: a newer session is taken, the old one is then refused
    restarted = Sealer(keyring, 1, 2, session=200)
    assert opener.open(restarted.seal(b"new")) == b"new"
    assert opener.open(envs[199]) is None and opener.stats["rejected_old_session"] == 1
    # a frame sealed for the other direction (reflection) does not open
    reflected = Sealer(keyring, 2, 1, session=300).seal(b"echo")
    assert opener.open(reflected) is None and opener.stats["rejected_auth"] == 1


def test_key_rotation_and_unknown_keys():
    old, new = random_link_key(), random_link_key()
    rx = Opener(Keyring({1: old, 2: new}), 1, 2)
    assert rx.open(Sealer(Keyring({1: old}), 1, 2, session=1).seal(b"a")) == b"a"
    assert rx.open(Sealer(Keyring({1: old, 2: new}, active_id=2), 1, 2, session=2).seal(b"b")) == b"b"
    assert rx.open(Sealer(Keyring({9: new}), 1, 2, session=3).seal(b"c")) is None
    assert rx.stats["rejected_unknown_key"] == 1
    with pytest.raises(ValueError):
        Keyring({1: b"short"})
    ring = Keyring.from_mapping({"0x10": KEY.hex()})
    assert ring.active_id == 16 and ring.keys[16] == KEY
    for junk in (b"", b"\x01", bytes(40), b"\x02" + bytes(60)):
        assert rx.open(junk) is None


def test_replayed_envelopes_on_a_live_sealed_link():
    pair = sealed_pair(Keyring({7: KEY}), Keyring({7: KEY}))
    pair.bring_up()
    pair.to_b = lambda cycle, f: [f, f]
    events = pair.run(10)
    assert len(received(events)) == 10
    assert pair.b.opener.stats["rejected_replay"] == 10
    assert pair.b.stats["dropped_repeat"] == 0  # stopped before RSSP-I even sees them
