"""Safety check words (SVC) and the SSE/SSR synchronisation words, per channel.

    SVC_i     = CRC32_i(data) ^ SID_i ^ T_i(TC) ^ SYS_CHK_WD_i
    SEQENQ_i  = SID_i ^ T_i                        (the SSE sender's own SID and timestamp)
    SEQINI_i  = SEQENQ_i ^ SID_i ^ DATAVER_i ^ T_i  (the data sender's own values, at TC_R)

So the SSE sender, holding its SEQENQ and the data sender's SID and DATAVER from configuration,
recovers the data sender's timestamp at TC_R from an SSR: T_i(TC_R) = SEQINI_i ^ SEQENQ_i ^ SID_i ^
DATAVER_i. It takes TC_R only if that is the data sender's SINIT advanced TC_R cycles (TC_R itself is
covered by CRC16 only), and from there predicts T_i(TC) for every later RSD (rssp1.endpoint).
"""

from __future__ import annotations

from rssp1 import crc as _crc  # looked up per call: rssp1.crc.use_backend() switches backends

SYS_CHK_WD = (0xAE390B5A, 0xC103589C)  # identical in all three vendor implementations (rssp1.md)


def svc(data: bytes, sid: tuple[int, int], t: tuple[int, int]) -> tuple[int, int]:
    c1, c2 = _crc.crc32_pair(data)
    return c1 ^ sid[0] ^ t[0] ^ SYS_CHK_WD[0], c2 ^ sid[1] ^ t[1] ^ SYS_CHK_WD[1]


def timestamp_from_svc(svc_words: tuple[int, int], data: bytes, sid: tuple[int, int]) -> tuple[int, int]:
    """The T(TC) a frame claims, given its sender's SID: what a receiver compares with its prediction."""
    c1, c2 = _crc.crc32_pair(data)
    return svc_words[0] ^ c1 ^ sid[0] ^ SYS_CHK_WD[0], svc_words[1] ^ c2 ^ sid[1] ^ SYS_CHK_WD[1]


def seqenq(sid: tuple[int, int], t: tuple[int, int]) -> tuple[int, int]:
    return sid[0] ^ t[0], sid[1] ^ t[1]


def seqini(
    enq: tuple[int, int], sid: tuple[int, int], dataver: tuple[int, int], t: tuple[int, int]
) -> tuple[int, int]:
    return enq[0] ^ sid[0] ^ dataver[0] ^ t[0], enq[1] ^ sid[1] ^ dataver[1] ^ t[1]


def timestamp_from_ssr(
    ini: tuple[int, int], enq: tuple[int, int], sid: tuple[int, int], dataver: tuple[int, int]
) -> tuple[int, int]:
    """The data sender's T(TC_R), from its SSR and the SEQENQ we sent."""
    return ini[0] ^ enq[0] ^ sid[0] ^ dataver[0], ini[1] ^ enq[1] ^ sid[1] ^ dataver[1]
