import pytest

from augnet.cluster.envelope import Envelope, Fence, ModelDecodeError, decode, encode


def _env(rev=3, epoch=1000, payload=b"\x00model\xff"):
    return Envelope("north", rev, epoch, payload)


def test_round_trip_keeps_every_field():
    e = _env()
    assert decode(encode(e)) == e


@pytest.mark.parametrize("mutate, msg", [
    (lambda b: b[:10], "too short"),
    (lambda b: b"XXXX" + b[4:], "magic"),
    (lambda b: b[:4] + b"\x02" + b[5:], "version 2"),
    (lambda b: b[:-6] + bytes([b[-6] ^ 1]) + b[-5:], "CRC"),
    (lambda b: b + b"\x00", "length"),
])
def test_corrupt_or_wrong_version_is_a_clear_error(mutate, msg):
    with pytest.raises(ModelDecodeError, match=msg):
        decode(mutate(encode(_env())))


def test_fence_counts_and_skips_bad_input_without_raising():
    f = Fence()
    assert f.admit(b"garbage") is None
    assert f.decode_errors == 1
    assert f.admit(encode(_env())) == _env()


def test_fence_drops_deposed_leader_and_repeated_epochs():
    f = Fence()
    assert f.admit(encode(_env(rev=3, epoch=1000))) is not None
    assert f.admit(encode(_env(rev=4, epoch=2000))) is not None   # new leader takes over
    assert f.admit(encode(_env(rev=3, epoch=3000))) is None       # old leader resumed after a pause
    assert f.admit(encode(_env(rev=4, epoch=2000))) is None       # same epoch twice
    assert f.admit(encode(_env(rev=4, epoch=3000))) is not None
    assert f.fenced == 2
    assert f.newest == {"north": (4, 3000)}


def test_regions_are_fenced_independently():
    f = Fence()
    assert f.admit(encode(Envelope("north", 9, 1000, b""))) is not None
    assert f.admit(encode(Envelope("south", 1, 1000, b""))) is not None
