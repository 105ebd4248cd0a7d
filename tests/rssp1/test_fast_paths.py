"""The fast paths against the references: compiled CRCs (rssp1._compiled) against the pure-Python
tables and the bitwise textbook CRC, the per-frame codec under both CRC backends, and the batch
kernels (rssp1.batch) against its loop over the per-frame functions, frame for frame."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rssp1 import batch, checkword, crc
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.frames import MAX_RSD_DATA_BYTES, RSD_TYPES, TYPE_RSD_A, TYPE_RSD_B, decode_frame, encode_rsd
from rssp1.timestamp import TIMESTAMP_CH1, TIMESTAMP_CH2, advance_pair, step_pair, timestamp_at

from .test_codes import SID_0029, VECTOR, bitwise_crc

needs_numba = pytest.mark.skipif(
    "numba" not in crc.BACKENDS, reason=f"compiled backend unavailable: {crc.unavailable.get('numba')}"
)
needs_batch_kernels = pytest.mark.skipif(batch.BACKEND != "numba", reason=f"batch kernels unavailable: {batch.UNAVAILABLE}")

u32 = st.integers(0, 0xFFFFFFFF)
pairs = st.tuples(u32, u32)


@contextmanager
def crc_backend(name):
    previous = crc.use_backend(name)
    try:
        yield
    finally:
        crc.use_backend(previous)


@contextmanager
def batch_loop():
    """rssp1.batch with its per-frame reference loop instead of the kernels."""
    kernels = batch._kernels
    batch._kernels = None
    try:
        yield
    finally:
        batch._kernels = kernels


def test_default_backend_is_compiled_when_numba_imports():
    try:
        import numba  # noqa: F401
    except ImportError:
        pytest.skip("numba not installed")
    import os

    if os.environ.get("RSSP1_BACKEND", "").lower() == "python":
        pytest.skip("RSSP1_BACKEND=python")
    assert crc.backend == "numba" and batch.BACKEND == "numba"


@needs_numba
def test_compiled_check_values_and_buffer_types():
    k16, kpair = crc.BACKENDS["numba"]
    for make in (bytes, bytearray, lambda b: memoryview(bytes(b)), lambda b: memoryview(bytearray(b))):
        assert k16(make(b"123456789")) == crc.CRC16_CHECK
        assert kpair(make(b"123456789")) == (crc.CRC32_CH1_CHECK, crc.CRC32_CH2_CHECK)
        assert k16(make(b"")) == 0 and kpair(make(b"")) == (0, 0)
    assert type(k16(b"1")) is int and all(type(x) is int for x in kpair(b"1"))
    import array

    with pytest.raises(TypeError):  # a buffer of 32-bit items is refused, not read item by item
        k16(memoryview(array.array("I", [1, 2])))


@needs_numba
@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=1500), st.integers(0, 40))
def test_compiled_crcs_equal_reference_and_bitwise(data, cut):
    k16, kpair = crc.BACKENDS["numba"]
    assert k16(data) == crc.crc16_py(data)
    assert kpair(data) == crc.crc32_pair_py(data)
    assert k16(memoryview(data)[cut:]) == crc.crc16_py(data[cut:])
    assert kpair(bytearray(data[cut:])) == crc.crc32_pair_py(data[cut:])
    if len(data) <= 64:  # the textbook bit-serial CRC is slow
        assert k16(data) == bitwise_crc(data, 0x0811, 16, reverse_input_bytes=False)
        assert kpair(data) == (
            bitwise_crc(data, 0x100D4E63, 32, reverse_input_bytes=True),
            bitwise_crc(data, 0x8CE56011, 32, reverse_input_bytes=True),
        )


@settings(max_examples=200, deadline=None)
@given(pairs, st.integers(0, 3000))
def test_step_pair_and_advance_pair_equal_the_channel_lfsrs(t, n):
    assert step_pair(t) == (TIMESTAMP_CH1.cycle(t[0]), TIMESTAMP_CH2.cycle(t[1]))
    assert advance_pair(t, n) == (TIMESTAMP_CH1.advance(t[0], n), TIMESTAMP_CH2.advance(t[1], n))


@needs_numba
@settings(max_examples=200, deadline=None)
@given(
    data=st.binary(max_size=MAX_RSD_DATA_BYTES),
    source=st.integers(0, 0xFFFF),
    destination=st.integers(0, 0xFFFF),
    tc=u32,
    sid=pairs,
    t=pairs,
    msg_type=st.sampled_from(RSD_TYPES),
    category=st.integers(0, 255),
)
def test_per_frame_codec_identical_under_both_backends(data, source, destination, tc, sid, t, msg_type, category):
    out = {}
    for name in ("python", "numba"):
        with crc_backend(name):
            frame = encode_rsd(source, destination, tc, checkword.svc(data, sid, t), data,
                               msg_type=msg_type, category=category)
            rsd = decode_frame(frame)
            out[name] = (frame, rsd, checkword.timestamp_from_svc(rsd.svc, rsd.data, sid))
    assert out["python"] == out["numba"]
    assert out["numba"][2] == t and out["numba"][1].data == data


def test_vector_round_trips_under_every_backend():
    t = timestamp_at(SID_0029, 7705)
    for name in crc.BACKENDS:
        with crc_backend(name):
            assert encode_rsd(0x29, 1, 7705, checkword.svc(b"\x07", SID_0029, t), b"\x07") == VECTOR
            assert checkword.timestamp_from_svc(decode_frame(VECTOR).svc, b"\x07", SID_0029) == t
    frames = batch.encode_rsds([b"\x07"], source=0x29, destination=1, tc=7705, sid=SID_0029, t=t)
    assert frames == [VECTOR]
    result = batch.verify_rsds(frames, sid=SID_0029, t=t)
    assert result.reasons() == ["ok"] and tuple(result.fields[0]) == (1, 0x80, 0x29, 1, 7705, *t)


def test_use_backend_switches_frames_and_checkword():
    for name in crc.BACKENDS:
        with crc_backend(name):
            assert crc.backend == name and crc.crc16 is crc.BACKENDS[name][0]
    with pytest.raises(ValueError):
        crc.use_backend("fortran")


# ------------------------------------------------------------------------------------------ batch
frames_spec = st.lists(
    st.tuples(
        st.binary(max_size=120),  # data
        st.integers(0, 0xFFFF),  # source
        u32,  # tc
        pairs,  # t
        st.sampled_from(RSD_TYPES),
        st.integers(0, 255),  # category
    ),
    max_size=40,
)


def _mutate(frame: bytes, how: int, at: int, value: int) -> bytes:
    """Damage of every kind a verifier must sort: bit flips (data, header, SDS, type), cuts, growth."""
    if how == 0:
        return frame
    if how == 1:  # one bit
        i = at % len(frame)
        return frame[:i] + bytes([frame[i] ^ (1 << (value % 8))]) + frame[i + 1 :]
    if how == 2:  # truncated
        return frame[: at % len(frame)]
    if how == 3:  # type byte replaced (SSE, SSR, other)
        return frame[:1] + bytes([(0x90, 0x91, 0x81, value & 0xFF)[at % 4]]) + frame[2:]
    if how == 4:  # SDS replaced
        return frame[:10] + (value & 0xFFFF).to_bytes(2, "little") + frame[12:]
    if how == 5:  # bytes appended (up to past the largest frame)
        return frame + bytes(value % 1500)
    return bytes(value % 64)  # garbage


@needs_batch_kernels
@settings(max_examples=150, deadline=None)
@given(spec=frames_spec, sid=pairs, damage=st.lists(st.tuples(st.integers(0, 6), u32, u32), max_size=40),
       per_frame_sid=st.booleans())
def test_batch_kernels_equal_the_per_frame_loop(spec, sid, damage, per_frame_sid):
    n = len(spec)
    datas = [s[0] for s in spec]
    kw = dict(
        source=[s[1] for s in spec], destination=0x0029, tc=[s[2] for s in spec],
        sid=[((sid[0] + i) & 0xFFFFFFFF, sid[1]) for i in range(n)] if per_frame_sid and n else sid,
        t=np.array([s[3] for s in spec], dtype=np.int64).reshape(n, 2),
        msg_type=[s[4] for s in spec], category=[s[5] for s in spec],
    )
    frames = batch.encode_rsds(datas, **kw)
    with batch_loop():
        assert batch.encode_rsds(datas, **kw) == frames
    for i, (data, source, tc, t, msg_type, category) in enumerate(spec):  # and the plain per-frame API
        sid_i = kw["sid"][i] if isinstance(kw["sid"], list) else sid
        assert frames[i] == encode_rsd(source, 0x29, tc, checkword.svc(data, sid_i, t), data,
                                       msg_type=msg_type, category=category)
    damaged = [_mutate(f, *damage[i]) if i < len(damage) else f for i, f in enumerate(frames)]
    # expected timestamps: the true ones, but every third off by one bit
    expected = kw["t"].copy()
    expected[::3, 1] ^= 1
    for t_arg in (expected, None):
        got = batch.verify_rsds(damaged, sid=kw["sid"], t=t_arg)
        with batch_loop():
            ref = batch.verify_rsds(damaged, sid=kw["sid"], t=t_arg)
        assert got.reasons() == ref.reasons()
        assert (got.fields == ref.fields).all()
    intact = [i for i in range(n) if i >= len(damage) or damage[i][0] == 0]
    assert all(got.codes[i] == batch.OK for i in intact)  # t=None: the claimed timestamps
    assert (got.timestamps[intact] == kw["t"][intact]).all()


@needs_batch_kernels
@settings(max_examples=50, deadline=None)
@given(pairs, st.integers(0, 500))
def test_batch_timestamp_run_equals_stepping(t, n):
    run = batch.timestamp_run(t, n)
    with batch_loop():
        assert (batch.timestamp_run(t, n) == run).all()
    if n:
        assert tuple(run[0]) == t and tuple(run[-1]) == advance_pair(t, n - 1)


def test_batch_argument_checks():
    with pytest.raises(ValueError):
        batch.encode_rsds([b"a", b"b"], source=[1, 2, 3], destination=1, tc=0, sid=(1, 2), t=(3, 4))
    with pytest.raises(ValueError):
        batch.encode_rsds([b"a"], source=1, destination=1, tc=0, sid=(1, 2), t=(3, 4), msg_type=0x90)
    with pytest.raises(ValueError):
        batch.encode_rsds([bytes(MAX_RSD_DATA_BYTES + 1)], source=1, destination=1, tc=0, sid=(1, 2), t=(3, 4))
    with pytest.raises(ValueError):
        batch.encode_rsds([b"a"], source=1, destination=1, tc=-1, sid=(1, 2), t=(3, 4))
    with pytest.raises(ValueError):
        batch.verify_rsds([b"a"], sid=(1, 2, 3))
    with pytest.raises(ValueError):
        batch.timestamp_run((1 << 32, 0), 3)
    with pytest.raises(ValueError):
        batch.verify_rsds([b"a"], sid=(-1, 2))
    assert batch.encode_rsds([], source=1, destination=1, tc=0, sid=(1, 2), t=(3, 4)) == []
    assert batch.verify_rsds([], sid=(1, 2)).reasons() == []


@pytest.mark.shared_data
def test_captured_frames_through_every_path(shared_data):
    """The 970 captured RSDs: every one passes CRC16 in the batch verifier, 0x0029's 221 pass both
    check words against T(TC) from its SID, and the capture report is the same under both CRC
    backends."""
    from rssp1.inspect import inspect_captures
    from rssp1.pcapng import udp_datagrams

    paths = sorted((shared_data / "rssp1").glob("*.pcapng"))
    frames = [d.payload for p in paths for d in udp_datagrams(p) if d.dst_port in (50000, 50001)]
    assert len(frames) == 970
    result = batch.verify_rsds(frames, sid=SID_0029)
    assert result.ok.all()  # CRC16 and layout (no t given: nothing compared yet)
    mine = result.fields[:, 2] == 0x29
    assert mine.sum() == 221
    tcs = result.tc[mine].tolist()
    expected = [timestamp_at(SID_0029, tc) for tc in tcs]
    checked = batch.verify_rsds([f for f, m in zip(frames, mine) if m], sid=SID_0029, t=expected)
    assert checked.ok.all()
    with batch_loop():
        assert batch.verify_rsds(frames, sid=SID_0029).reasons() == result.reasons()
    reports = {}
    for name in crc.BACKENDS:
        with crc_backend(name):
            report = inspect_captures(paths, [DeviceConfig(0x29, SID_0029)], timing=LinkTiming(0.25, 3, 4, 3))
            reports[name] = (report.sources, report.paths, report.undecodable)
    assert len({repr(r) for r in reports.values()}) == 1
    assert reports[crc.backend][0][0x29].svc_passed == 221
