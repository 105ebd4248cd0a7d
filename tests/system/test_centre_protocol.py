"""The parent <-> centre-process protocol: every message survives the codec, the way a stream is cut
never matters, every kind of bad input is a ProtocolError with a clear message, and a bad frame on the
socket ends that centre process (reported and replaced) without harm to the parent."""

from __future__ import annotations

import asyncio
import dataclasses
import math
import random
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from augnet.centre.baseline import BaselineEpoch
from augnet.centre.engine import EpochReport
from augnet.centre.integrity import Alarm
from augnet.centre.network import NetworkEpoch
from augnet.system import centre_protocol as cp
from augnet.system.centre_protocol import (
    FROM_CENTRE, FROM_LOOP, HEADER_BYTES, LAYOUTS, MAGIC, MAX_BODY_BYTES, PROTOCOL_VERSION, Alive, CentreError,
    CloseSession, Decoder, EpochsSolved, MoveSession, OpenSession, ProtocolError, Ready, StationData,
    SessionBound, StationMembership, Stop, VrsGroup, VrsWritten, encode)
from tests.system.test_centre_service import _until

T = 1457143239.0


def same(a, b) -> bool:
    """Equal in value and type, arrays by dtype, shape and content (NaN equal to NaN)."""
    if type(a) is not type(b):
        return isinstance(a, str) and isinstance(b, str) and str(a) == str(b)  # numpy str_ keys arrive as str
    if dataclasses.is_dataclass(a):
        return all(same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, np.ndarray):
        return (a.dtype == b.dtype and a.shape == b.shape
                and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return list(a) == list(b) and all(same(a[k], b[k]) for k in a)
    return a == b


def baseline_epoch(n: int = 5, float_parts: bool = True) -> BaselineEpoch:
    rng = np.random.default_rng(n)
    sats = np.array([f"G{k + 1:02d}" for k in range(n)])
    fixed = rng.random(n) > 0.3
    dd_n = np.where(fixed[:, None], rng.integers(-50, 50, (n, 2)).astype(float), np.nan)
    return BaselineEpoch(
        T, {np.str_("G"): np.str_("G01")}, sats, rng.uniform(10, 90, n), rng.uniform(10, 90, n), fixed, dd_n,
        rng.normal(0, 0.1, n), rng.normal(0, 0.01, n), np.tile([1575.42e6, 1227.6e6], (n, 1)), ["G03"],
        (0.01, -0.002), 4.5, fixed | True if float_parts else None,
        rng.normal(0, 0.1, n) if float_parts else None, rng.uniform(0, 1e-4, n) if float_parts else None)


def epoch_report(stations: int = 3, sats: int = 5) -> EpochReport:
    names = [f"S{k:02d}" for k in range(stations)]
    rng = np.random.default_rng(stations)
    iono = rng.normal(0, 0.1, (stations, sats))
    iono[0, 1] = np.nan
    ne = NetworkEpoch(
        T, names[0], names, rng.normal(0, 3e4, (stations, 2)), rng.normal(0, 6e6, (stations, 3)),
        {"G": "G01", "E": "E11"}, np.array([f"G{k + 1:02d}" for k in range(sats)]), iono,
        rng.normal(0, 0.01, (stations, sats)),
        {f"{a}-{b}": (baseline_epoch(sats, float_parts=k % 2 == 0) if k else None)
         for k, (a, b) in enumerate(zip(names, names[1:]))},
        misclosures=2, present=names[:-1], clocks={n: 1e-7 * k for k, n in enumerate(names)}, excluded={"G04"},
        alarms=[Alarm("satellite-fault", "G04", "warning", "G04: residual 0.3 m", T),
                Alarm("station-down", "S02", "critical", "S02 silent", T, cleared=True)])
    return EpochReport(T, ne, None, 7, names[:-1], (T - 18.2, T - 17.9), {"iono-model": 40, "nearest": 3})


def one_of_each() -> list:
    """A message of every type the protocol has (the test below checks none is missing)."""
    return [
        StationData("WEST", b"\xd3\x00\x13" + bytes(range(19)) + b"\x01\x02\x03", 1.7e9 + 0.25),
        OpenSession("VRS/1", 39.9, 116.4, 52.5),
        MoveSession("VRS/1", 39.91, 116.41, 51.0),
        CloseSession("VRS/1"),
        StationMembership("STA5", (4.8e6, 1.8e5, 4.2e6)),
        StationMembership("STA5", None),
        SessionBound("VRS/1", True),
        SessionBound("VRS/1", False),
        VrsWritten(T),
        Stop(),
        Ready(4242),
        VrsGroup(T, ["VRS/1", "VRS/\u00e9", "VRS/3"], [b"\xd3" * 700, b"", bytes(range(256))], 1.7e9,
                 (1.7e9 - 0.3, 1.7e9 - 0.2), (0.01, 0.02, 0.03, 1.0), False),
        VrsGroup(T, ["VRS/1", "VRS/2"], [b"\xd3\x00", b"\xd3\x01"], 1.7e9, None, None, True),
        VrsGroup(T, [], [], 1.7e9, None, None, True),
        EpochsSolved([epoch_report(), epoch_report(4, 7)],
                     [("augnet.corrections.line", b'{"t_gpst":1}'), ("augnet.alarms.line", b"{}")], 0.041, 7),
        EpochsSolved([], [], 0.0, 0),
        CentreError("epoch failed: Traceback ... ValueError"),
        Alive(),
    ]


def decode_all(data: bytes, expect=FROM_LOOP + FROM_CENTRE) -> list:
    return Decoder(expect).receive_data(data)


# --- round trips ----------------------------------------------------------------------------------------------


def test_every_message_type_round_trips():
    msgs = one_of_each()
    assert {type(m) for m in msgs} == {rec.kind for rec in LAYOUTS.values()}  # none left out
    for m in msgs:
        frame = encode(m)
        assert frame[:2] == MAGIC and frame[2] == PROTOCOL_VERSION
        assert struct.unpack_from("<I", frame, 4)[0] == len(frame) - HEADER_BYTES
        got = decode_all(frame)
        assert len(got) == 1 and same(got[0], m), type(m).__name__


def test_a_decoded_epoch_report_is_the_report_the_console_reads():
    r = epoch_report(5, 9)
    got = decode_all(encode(EpochsSolved([r], [], 0.05, 3)))[0].reports[0]
    assert got.vrs is None and same(got, r)
    assert got.network.fixed_fraction() == r.network.fixed_fraction()
    assert isinstance(got.network.excluded, set) and got.network.sats.flags.writeable


def test_a_report_with_its_vrs_leaves_them_in_the_centre():
    r = dataclasses.replace(epoch_report(), vrs=object())  # whatever it holds, it does not cross
    got = decode_all(encode(EpochsSolved([r], [], 0.05, 3)))[0].reports[0]
    assert got.vrs is None and same(got.network, r.network)


floats = st.floats(allow_nan=True, allow_infinity=True)
texts = st.text(max_size=40)
# a client id holds no NUL (nor surrogates, which UTF-8 cannot carry)
ids = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\0"), max_size=40)


@settings(max_examples=150, deadline=None)
@given(st.one_of(
    st.builds(StationData, texts, st.binary(max_size=2000), floats),
    st.builds(OpenSession, texts, floats, floats, floats),
    st.builds(MoveSession, texts, floats, floats, floats),
    st.builds(CloseSession, texts),
    st.builds(StationMembership, texts, st.none() | st.tuples(floats, floats, floats)),
    st.builds(VrsWritten, floats),
    st.builds(Ready, st.integers(-2**63, 2**63 - 1)),
    st.builds(lambda t, pairs, *rest: VrsGroup(t, [c for c, _ in pairs], [b for _, b in pairs], *rest),
              floats, st.lists(st.tuples(ids, st.binary(max_size=300)), max_size=20), floats,
              st.none() | st.tuples(floats, floats), st.none() | st.tuples(floats, floats, floats, floats),
              st.booleans()),
    st.builds(CentreError, st.text(max_size=500)),
))
def test_any_field_values_round_trip(msg):
    assert same(decode_all(encode(msg))[0], msg)


# --- how the stream is cut ------------------------------------------------------------------------------------


def _stream() -> tuple[bytes, list]:
    msgs = [m for m in one_of_each() if not isinstance(m, EpochsSolved)]
    msgs.insert(3, EpochsSolved([epoch_report(2, 3)], [("a", b"b")], 0.01, 1))
    return b"".join(map(encode, msgs)), msgs


def _feed(pieces) -> list:
    dec = Decoder()
    out = []
    for p in pieces:
        out += dec.receive_data(p)
    return out


def test_byte_by_byte_gives_the_same_messages():
    data, msgs = _stream()
    got = _feed(data[i:i + 1] for i in range(len(data)))
    assert len(got) == len(msgs) and all(same(a, b) for a, b in zip(got, msgs))


def test_every_split_in_two_gives_the_same_messages():
    data, msgs = _stream()
    for cut in range(len(data) + 1):
        got = _feed([data[:cut], data[cut:]])
        assert len(got) == len(msgs) and all(same(a, b) for a, b in zip(got, msgs)), cut


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 10**6), max_size=30))
def test_random_splits_give_the_same_messages(cuts):
    data, msgs = _stream()
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    got = _feed(data[a:b] for a, b in zip(points, points[1:]))
    assert len(got) == len(msgs) and all(same(a, b) for a, b in zip(got, msgs))


def _read_into(dec: Decoder, pieces) -> list:
    """As a socket read into the decoder's buffer: each piece written where `get_buffer` points."""
    out = []
    for p in pieces:
        with dec.get_buffer(len(p)) as room:
            room[:len(p)] = p
        out += dec.buffer_updated(len(p))
    return out


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, 10**6), max_size=30))
def test_reads_into_the_buffer_give_the_same_messages(cuts):
    data, msgs = _stream()
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    got = _read_into(Decoder(), [data[a:b] for a, b in zip(points, points[1:])])
    assert len(got) == len(msgs) and all(same(a, b) for a, b in zip(got, msgs))


def test_the_buffer_offered_to_a_read_has_room_for_it(monkeypatch):
    monkeypatch.setattr(cp, "RECEIVE_BUFFER_BYTES", 64)
    monkeypatch.setattr(cp, "MIN_READ_BYTES", 16)
    dec = Decoder()
    with dec.get_buffer(-1) as room:
        assert len(room) == 16  # a read of the usual size
    frame = encode(CentreError("x" * 100))
    assert _read_into(dec, [frame[:50]]) == []
    with dec.get_buffer(500) as room:
        assert len(room) == 500  # the partial frame kept, room made behind it
    assert _read_into(dec, [frame[50:]]) == [CentreError("x" * 100)]


def test_a_small_buffer_moves_grows_and_shrinks_with_the_same_messages(monkeypatch):
    """The decoder's reused buffer, made tiny: unread bytes moved to its front, grown for a frame larger
    than it, back to its size after one larger than it keeps."""
    monkeypatch.setattr(cp, "RECEIVE_BUFFER_BYTES", 64)
    monkeypatch.setattr(cp, "KEEP_BUFFER_BYTES", 256)
    data, msgs = _stream()
    rng = random.Random(7)
    for _ in range(20):
        cuts = sorted(rng.sample(range(1, len(data)), 40))
        dec = Decoder()
        got, largest = [], 0
        for a, b in zip([0] + cuts, cuts + [len(data)]):
            got += dec.receive_data(data[a:b])
            largest = max(largest, len(dec._buf))
        assert len(got) == len(msgs) and all(same(x, y) for x, y in zip(got, msgs))
        assert largest > 256 and len(dec._buf) <= 256


def test_a_partial_frame_waits_for_the_rest():
    frame = encode(CentreError("x" * 100))
    dec = Decoder()
    assert dec.receive_data(frame[:HEADER_BYTES - 1]) == []
    assert dec.receive_data(frame[HEADER_BYTES - 1:50]) == []
    assert dec.receive_data(frame[50:]) == [CentreError("x" * 100)]


# --- bad input --------------------------------------------------------------------------------------------------


def _header(code: int, size: int, magic: bytes = MAGIC, version: int = PROTOCOL_VERSION) -> bytes:
    return struct.pack("<2sBBI", magic, version, code, size)


def _code(kind: type) -> int:
    return next(c for c, rec in LAYOUTS.items() if rec.kind is kind)


def _with_body(kind: type, body: bytes) -> bytes:
    return _header(_code(kind), len(body)) + body


def _error(data: bytes, expect=FROM_LOOP + FROM_CENTRE, **kw) -> ProtocolError:
    dec = Decoder(expect, **kw)
    with pytest.raises(ProtocolError) as info:
        dec.receive_data(data)
    with pytest.raises(ProtocolError, match="already failed"):  # a stream that lost its framing stays lost
        dec.receive_data(encode(Alive()))
    return info.value


def _s(text: str) -> bytes:
    b = text.encode()
    return struct.pack("<I", len(b)) + b


BAD_INPUT = {
    "bad magic": (b"XY" + encode(Alive())[2:], "bad magic b'XY'"),
    "unknown version": (_header(_code(Alive), 0, version=PROTOCOL_VERSION + 1),
                        f"unsupported protocol version {PROTOCOL_VERSION + 1}"),
    "unknown type": (_header(99, 0), "message type 99 (unknown)"),
    "oversize": (_header(_code(StationData), MAX_BODY_BYTES + 1), "over the 67108864-byte limit"),
    "truncated body": (_with_body(StationData, _s("WEST") + struct.pack("<I", 100) + b"abc"),
                       "StationData: truncated body: 100 bytes needed"),
    "truncated number": (_with_body(VrsWritten, b"\x00" * 7), "VrsWritten: truncated body: 8 bytes needed"),
    "bytes left over": (_with_body(Alive, b"\x00"), "Alive: malformed body: 1 bytes left over"),
    "invalid UTF-8": (_with_body(CloseSession, _s("x")[:4] + b"\xff"), "CloseSession: malformed body"),
    "bool not 0 or 1": (_with_body(VrsGroup, struct.pack("<d", T) + b"\x00" * 20 + b"\x00\x00\x07"),
                        "bool byte 7"),
}


@pytest.mark.parametrize("kind", list(BAD_INPUT))
def test_each_kind_of_bad_input_is_a_protocol_error_that_says_what(kind):
    data, words = BAD_INPUT[kind]
    assert words in str(_error(data))


def test_an_oversize_length_is_refused_before_its_body_is_buffered():
    assert "over the 1000-byte limit" in str(_error(_header(_code(StationData), 1001), max_body_bytes=1000))


def test_an_array_of_objects_or_a_garbled_dtype_is_malformed():
    r = epoch_report()
    ok = encode(EpochsSolved([r], [], 0.0, 1))
    body = ok[HEADER_BYTES:]
    dtype_at = body.index(b"<f8")  # the first array's dtype
    for bad, words in ((b"|O8", "refused"), (b"<zz", "dtype b'<zz'")):
        data = _with_body(EpochsSolved, body[:dtype_at] + bad + body[dtype_at + 3:])
        assert words in str(_error(data))


def test_a_message_from_the_wrong_side_is_refused():
    assert "type 1 (StationData) not expected" in str(_error(encode(StationData("A", b"", 0.0)), FROM_CENTRE))
    assert "(VrsGroup) not expected" in str(_error(encode(VrsGroup(T, [], [], 0.0, None, None, True)), FROM_LOOP))


def test_the_messages_before_a_bad_frame_come_with_the_error():
    good = [Ready(1), Alive()]
    err = _error(b"".join(map(encode, good)) + b"garbage!")
    assert err.messages == good and "bad magic" in str(err)


def test_encode_refuses_what_the_protocol_cannot_carry():
    with pytest.raises(ProtocolError, match="not a centre-protocol message: tuple"):
        encode(("data", "WEST", b"", 0.0))
    with pytest.raises(ProtocolError, match=r"cannot encode OpenSession.lat_deg"):
        encode(OpenSession("bad", "not a latitude", None, None))
    with pytest.raises(ProtocolError, match=r"cannot encode VrsGroup.client_ids: a str of a packed list holds NUL"):
        encode(VrsGroup(T, ["a\0b"], [b""], 0.0, None, None, True))
    with pytest.raises(ProtocolError, match=r"cannot encode VrsGroup.cost: 3 items, not 4"):
        encode(VrsGroup(T, [], [], 0.0, None, (1.0, 2.0, 3.0), True))
    r = epoch_report()
    r.network.sats = np.array([object()] * len(r.network.sats))
    with pytest.raises(ProtocolError, match="cannot encode EpochsSolved.reports: dtype object"):
        encode(EpochsSolved([r], [], 0.0, 1))
    with pytest.raises(ProtocolError, match="over the 67108864-byte limit"):
        encode(StationData("big", bytes(MAX_BODY_BYTES), 0.0))


def test_a_vrs_group_has_one_rtcm_epoch_per_client():
    with pytest.raises(ValueError, match="2 client ids for 1 RTCM epochs"):
        VrsGroup(T, ["a", "b"], [b""], 0.0, None, None, True)
    body = encode(VrsGroup(T, ["a", "b"], [b"1", b"2"], 0.0, None, None, True))[HEADER_BYTES:]
    ids_end = 8 + 4 + 4 + 3  # t_gpst, count, "a\0b" as a str
    one_rtcm = body[:ids_end] + struct.pack("<II", 1, 1) + b"1" + body[ids_end + 4 + 8 + 2:]
    assert "malformed body: 2 client ids for 1 RTCM epochs" in str(_error(_with_body(VrsGroup, one_rtcm)))
    three_ids = body[:8] + struct.pack("<I", 3) + body[12:]
    assert "malformed body: 2 strs where the count says 3" in str(_error(_with_body(VrsGroup, three_ids)))


def test_a_layout_must_name_every_field_of_its_record():
    @dataclasses.dataclass
    class Grown:
        a: float
        b: float

    with pytest.raises(TypeError, match="is not its fields"):
        cp._Record(Grown, (("a", cp.F64),))


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300), st.integers(0, 400))
def test_garbage_only_ever_raises_protocol_error(noise, at):
    """Random bytes, alone or spliced into a good stream: messages or ProtocolError, nothing else."""
    data, _ = _stream()
    for stream in (noise, data[:at] + noise + data[at:], _header(_code(EpochsSolved), len(noise)) + noise):
        try:
            Decoder().receive_data(stream)
        except ProtocolError:
            pass


@settings(max_examples=400, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), min_size=1, max_size=4))
def test_a_good_frame_with_bytes_changed_only_ever_raises_protocol_error(changes):
    """Every field's reader meets bad values: an epoch report's frame with a few bytes changed (lengths,
    dtypes, shapes, counts, flags) decodes or raises ProtocolError, nothing else."""
    frame = bytearray(encode(EpochsSolved([epoch_report(2, 3)], [("a", b"b")], 0.01, 1)))
    for at, value in changes:
        frame[HEADER_BYTES + at % (len(frame) - HEADER_BYTES)] = value
    try:
        Decoder().receive_data(bytes(frame))
    except ProtocolError:
        pass


# --- on the socket: a bad frame ends that centre process, never the parent -------------------------------------


STATIONS = {"A": (-2148744.0, 4426641.0, 4044655.0), "B": (-2170000.0, 4410000.0, 4050000.0),
            "C": (-2130000.0, 4440000.0, 4040000.0)}


def _service():
    from augnet.system.centre_service import CentreService, CentreSpec

    alarms: list = []
    svc = CentreService(CentreSpec(STATIONS, T, "test"), asyncio.get_running_loop(),
                        on_alarm=lambda *a: alarms.append(a))
    return svc, alarms


def test_a_bad_frame_from_the_centre_is_counted_and_the_centre_replaced():
    async def main():
        svc, alarms = _service()
        await svc.start()
        await _until(lambda: svc.alive)
        first = svc._proc
        data = encode(Alive()) + b"\x00garbage from a confused centre"
        with svc._channel.get_buffer(-1) as room:  # as the loop's socket reads it
            room[:len(data)] = data
        svc._channel.buffer_updated(len(data))
        assert svc.protocol_errors == 1
        await _until(lambda: alarms)
        assert alarms[0][0] == "centre-process" and alarms[0][4] is False and "died" in alarms[0][3]
        await _until(lambda: svc.alive and svc._proc is not first)
        assert not first.is_alive() and svc.restarts == 1
        await svc.stop()

    asyncio.run(main())


def test_a_bad_frame_from_the_loop_ends_the_centre_which_is_replaced():
    from augnet.system.centre_service import EXIT_PROTOCOL_ERROR

    async def main():
        svc, alarms = _service()
        await svc.start()
        await _until(lambda: svc.alive)
        first = svc._proc
        svc._channel.transport.write(encode(VrsWritten(T)) + b"\x00not a frame at all")
        await _until(lambda: alarms and not first.is_alive())
        assert first.exitcode == EXIT_PROTOCOL_ERROR and "died" in alarms[0][3]
        assert svc.errors >= 2 and svc.protocol_errors == 0  # its CentreError, then its death
        await _until(lambda: svc.alive and svc._proc is not first)
        await svc.stop()

    asyncio.run(main())
