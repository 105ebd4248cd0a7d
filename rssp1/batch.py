"""Many RSDs encoded or verified in one call: for whoever holds many frames at once.

A control centre building one report per RBC link each cycle, a capture inspector, a replay: the
per-frame API (rssp1.frames, rssp1.checkword) costs a few microseconds of interpreter per frame,
these cost a fraction of one (figures: augnet/bench/rssp1.py).

    t = timestamp_run(seed_at_tc0, n)                   # T(tc0), T(tc0 + 1), ... both channels
    frames = encode_rsds(datas, source=..., destination=..., tc=tcs, sid=sid, t=t)
    result = verify_rsds(frames, sid=peer_sid, t=expected)      # result.ok, result.reasons(), ...

Every per-frame argument is either one value for all frames or one per frame (pairs: shape (2,) or
(n, 2)). Frames are checked as RSDs in this order: size ("short", "long"), type ("not_rsd": SSE, SSR
and anything else), SDS ("length"), CRC16 ("crc16"), then the timestamps both check words claim
under the sender's SID, compared with `t` when given ("svc"). Those are the reasons decode_frame and
the endpoint use, except that a batch of RSDs counts a well-formed SSE or SSR as "not_rsd".

Needs numpy (a dependency of augnet, not of rssp1's core: nothing else in rssp1 imports this). The
work is done by compiled kernels (rssp1._compiled) when numba imports, else by a loop over the
per-frame reference functions with the same results (`BACKEND` says which; RSSP1_BACKEND=python
forces the loop). tests/rssp1/test_fast_paths.py checks kernels against the loop frame for frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rssp1 import checkword
from rssp1.frames import (
    CATEGORY_ACTIVE,
    MAX_FRAME_BYTES,
    MAX_RSD_DATA_BYTES,
    RSD_OVERHEAD_BYTES,
    RSD_TYPES,
    SSE_BYTES,
    TYPE_RSD_A,
    FrameError,
    Rsd,
    decode_frame,
    encode_rsd,
)
from rssp1.timestamp import TIMESTAMP_LFSRS, step_pair

REASONS = ("ok", "short", "long", "not_rsd", "length", "crc16", "svc")  # index = code
OK = 0
_CODE = {reason: code for code, reason in enumerate(REASONS)}
FIELDS = ("category", "msg_type", "source", "destination", "tc", "t1", "t2")  # RsdBatch.fields columns

try:
    if os.environ.get("RSSP1_BACKEND", "").strip().lower() == "python":
        raise ImportError("RSSP1_BACKEND=python")
    from rssp1 import _compiled as _kernels
except Exception as exc:  # no numba, or not wanted: the per-frame loop below does the same work
    if os.environ.get("RSSP1_BACKEND", "").strip().lower() == "numba":
        raise
    _kernels = None
    UNAVAILABLE = f"{type(exc).__name__}: {exc}"
else:
    UNAVAILABLE = ""
BACKEND = "python" if _kernels is None else "numba"

_LFSR_TABLES = np.array([lfsr.cycle.tables for lfsr in TIMESTAMP_LFSRS], dtype=np.uint32)  # (2, 4, 256)


@dataclass
class RsdBatch:
    """What verify_rsds found, one row per frame."""

    codes: np.ndarray  # uint8, index into REASONS
    fields: np.ndarray  # int64 (n, 7), columns FIELDS, filled as far as each frame got

    @property
    def ok(self) -> np.ndarray:
        return self.codes == OK

    @property
    def tc(self) -> np.ndarray:
        return self.fields[:, 4]

    @property
    def timestamps(self) -> np.ndarray:
        """(n, 2): the T(TC) each frame's check words claim under the given SID (past CRC16 only)."""
        return self.fields[:, 5:7]

    def reasons(self) -> list[str]:
        return [REASONS[c] for c in self.codes.tolist()]


def _per_frame(value, n: int, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.int64)
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] != n):
        raise ValueError(f"{name}: one value or one per frame ({n}), got shape {a.shape}")
    return np.broadcast_to(a, (n,)).copy()  # contiguous and writable: the types the kernels take


def _pairs(value, n: int, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.int64)
    if a.shape not in ((2,), (n, 2)):
        raise ValueError(f"{name}: one pair or one pair per frame ({n}, 2), got shape {a.shape}")
    if ((a < 0) | (a > 0xFFFFFFFF)).any():
        raise ValueError(f"{name}: 32-bit words expected")
    return np.broadcast_to(a, (n, 2)).copy()


def _offsets(lengths: Sequence[int], extra: int) -> np.ndarray:
    off = np.zeros(len(lengths) + 1, dtype=np.int64)
    np.cumsum(np.fromiter(lengths, dtype=np.int64, count=len(lengths)) + extra, out=off[1:])
    return off


def timestamp_run(t: tuple[int, int], n: int) -> np.ndarray:
    """(n, 2) int64: both channels' T(k), T(k + 1), ..., T(k + n - 1) from T(k) = t."""
    if not all(0 <= int(x) <= 0xFFFFFFFF for x in t) or len(t) != 2:
        raise ValueError("t: a pair of 32-bit words expected")
    out = np.empty((n, 2), dtype=np.int64)
    if _kernels is not None:
        _kernels.timestamp_run(_LFSR_TABLES, int(t[0]), int(t[1]), out)
        return out
    for k in range(n):
        out[k] = t
        t = step_pair(t)
    return out


def encode_rsds(
    datas: Sequence[bytes],
    *,
    source,
    destination,
    tc,
    sid,
    t,
    msg_type=TYPE_RSD_A,
    category=CATEGORY_ACTIVE,
) -> list[bytes]:
    """RSD i carries datas[i], TC tc[i], check words from sid[i] and the sender's timestamps t[i].

    The same frames as `encode_rsd(..., checkword.svc(data, sid, t), data, ...)` one by one.
    """
    n = len(datas)
    lengths = list(map(len, datas))
    if n and max(lengths) > MAX_RSD_DATA_BYTES:
        raise ValueError(f"RSD data {max(lengths)} bytes > {MAX_RSD_DATA_BYTES}")
    cols = {
        "category": _per_frame(category, n, "category"),
        "msg_type": _per_frame(msg_type, n, "msg_type"),
        "source": _per_frame(source, n, "source"),
        "destination": _per_frame(destination, n, "destination"),
        "tc": _per_frame(tc, n, "tc"),
    }
    for name, limit in (("category", 0xFF), ("source", 0xFFFF), ("destination", 0xFFFF), ("tc", 0xFFFFFFFF)):
        if n and (cols[name].min() < 0 or cols[name].max() > limit):
            raise ValueError(f"{name} out of range")
    if n and not np.isin(cols["msg_type"], RSD_TYPES).all():
        raise ValueError("msg_type: RSD types only (0x80, 0x81)")
    sid_a, t_a = _pairs(sid, n, "sid"), _pairs(t, n, "t")
    if _kernels is None:
        return [
            encode_rsd(
                int(cols["source"][i]), int(cols["destination"][i]), int(cols["tc"][i]),
                checkword.svc(datas[i], (int(sid_a[i, 0]), int(sid_a[i, 1])), (int(t_a[i, 0]), int(t_a[i, 1]))),
                datas[i], msg_type=int(cols["msg_type"][i]), category=int(cols["category"][i]),
            )
            for i in range(n)
        ]
    data = np.frombuffer(b"".join(datas), dtype=np.uint8)
    out_off = _offsets(lengths, RSD_OVERHEAD_BYTES)
    out = np.empty(int(out_off[-1]), dtype=np.uint8)
    _kernels.encode_rsds(
        data, _offsets(lengths, 0), cols["category"], cols["msg_type"], cols["source"], cols["destination"],
        cols["tc"], sid_a, t_a, out, out_off,
    )
    buf = out.tobytes()
    bounds = out_off.tolist()
    return [buf[a:b] for a, b in zip(bounds, bounds[1:])]


def verify_rsds(frames: Sequence[bytes | bytearray], *, sid, t=None) -> RsdBatch:
    """Check each frame as an RSD from a sender with SIDs `sid` (one pair, or one per frame).

    With `t` (the timestamps the receiver predicts for each frame's TC), a frame whose check words
    claim other timestamps gets "svc"; without it, read what they claim from RsdBatch.timestamps.
    """
    n = len(frames)
    sid_a = _pairs(sid, n, "sid")
    compare = t is not None
    t_a = _pairs(t, n, "t") if compare else np.zeros((n, 2), dtype=np.int64)
    codes = np.zeros(n, dtype=np.uint8)
    fields = np.zeros((n, len(FIELDS)), dtype=np.int64)
    if _kernels is not None:
        buf = np.frombuffer(b"".join(frames), dtype=np.uint8)
        _kernels.verify_rsds(buf, _offsets(list(map(len, frames)), 0), sid_a, t_a, compare, codes, fields)
        return RsdBatch(codes, fields)
    for i, frame in enumerate(frames):
        codes[i] = _verify_one(frame, sid_a[i], t_a[i] if compare else None, fields[i])
    return RsdBatch(codes, fields)


def _verify_one(frame, sid, t, row) -> int:
    """The reference for one frame: the per-frame decoder and check-word functions."""
    n = len(frame)
    if n < SSE_BYTES:
        return _CODE["short"]
    if n > MAX_FRAME_BYTES:
        return _CODE["long"]
    row[0], row[1] = frame[0], frame[1]
    if frame[1] not in RSD_TYPES:
        return _CODE["not_rsd"]
    row[2:5] = (int.from_bytes(frame[2:4], "little"), int.from_bytes(frame[4:6], "little"),
                int.from_bytes(frame[6:10], "little"))
    try:
        rsd = decode_frame(frame)
    except FrameError as exc:
        return _CODE[exc.reason]
    assert isinstance(rsd, Rsd)
    claimed = checkword.timestamp_from_svc(rsd.svc, rsd.data, (int(sid[0]), int(sid[1])))
    row[5:7] = claimed
    if t is not None and claimed != (int(t[0]), int(t[1])):
        return _CODE["svc"]
    return OK
