"""RSSP-I frames: RSD (from machine A or B), SSE and SSR; layouts declared once, encode and decode.

Layout (rssp1.md "Frame"; all multi-byte fields little-endian):

    header  category u8 | type u8 | source u16 | destination u16 | TC u32            10 bytes
    RSD     header | SDS u16 (= len(data) + 8) | SVC_1 u32 | SVC_2 u32 | data | CRC16   22 + len(data)
    SSE     header (TC = TC_E) | SEQENQ_1 u32 | SEQENQ_2 u32 | CRC16                    20
    SSR     header (TC = TC_R) | TC_E u32 | SEQINI_1 u32 | SEQINI_2 u32 | NUM_DATAVER u8 | CRC16  25

Decoding never trusts a length: the frame size must match the type (and SDS for RSD) exactly, and
CRC16 must match, else `FrameError` with a short reason the receiver counts.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from rssp1 import crc as _crc  # looked up per call: rssp1.crc.use_backend() switches backends

# Protocol interaction category (byte 0). 0x01 is "active"; standby is 0x02 at one vendor and 0x00 at
# another (rssp1.md), so decoding accepts any value and reports it.
CATEGORY_ACTIVE = 0x01
CATEGORY_STANDBY = 0x02

TYPE_RSD_A = 0x80
TYPE_RSD_B = 0x81
TYPE_SSE = 0x90
TYPE_SSR = 0x91
RSD_TYPES = (TYPE_RSD_A, TYPE_RSD_B)

HEADER = struct.Struct("<BBHHI")
RSD_PREFIX = struct.Struct("<BBHHIHII")  # header + SDS + SVC_1 + SVC_2
SSE_BODY = struct.Struct("<BBHHIII")  # header + SEQENQ_1 + SEQENQ_2
SSR_BODY = struct.Struct("<BBHHIIIIB")  # header + TC_E + SEQINI_1 + SEQINI_2 + NUM_DATAVER
CRC16_FIELD = struct.Struct("<H")

CRC16_BYTES = 2
RSD_OVERHEAD_BYTES = RSD_PREFIX.size + CRC16_BYTES  # 22
SDS_EXTRA_BYTES = 8  # SDS = len(data) + 8: SDS counts the two SVCs as well as the data
SSE_BYTES = SSE_BODY.size + CRC16_BYTES  # 20
SSR_BYTES = SSR_BODY.size + CRC16_BYTES  # 25
NUM_DATAVER = 0x01  # the only value seen in the field (rssp1.md)

# Largest frame we build or accept: a UDP payload in one Ethernet frame (1500 MTU - 20 IPv4 - 8 UDP),
# the larger of the two vendor caps in rssp1.md (the other is 545 bytes).
MAX_FRAME_BYTES = 1472
MAX_RSD_DATA_BYTES = MAX_FRAME_BYTES - RSD_OVERHEAD_BYTES


class FrameError(ValueError):
    """A frame that cannot be decoded; `reason` is a short counter key."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


@dataclass(slots=True)  # not frozen: a frozen __init__ costs a microsecond per frame
class Rsd:
    category: int
    msg_type: int  # TYPE_RSD_A or TYPE_RSD_B
    source: int
    destination: int
    tc: int
    svc: tuple[int, int]
    data: bytes

    @property
    def machine(self) -> str:
        return "A" if self.msg_type == TYPE_RSD_A else "B"


@dataclass(slots=True)  # not frozen: a frozen __init__ costs a microsecond per frame
class Sse:
    category: int
    source: int
    destination: int
    tc_e: int
    seqenq: tuple[int, int]


@dataclass(slots=True)  # not frozen: a frozen __init__ costs a microsecond per frame
class Ssr:
    category: int
    source: int
    destination: int
    tc_r: int
    tc_e: int
    seqini: tuple[int, int]
    num_dataver: int


Frame = Rsd | Sse | Ssr


def _with_crc16(body: bytes) -> bytes:
    return body + CRC16_FIELD.pack(_crc.crc16(body))


def encode_rsd(
    source: int,
    destination: int,
    tc: int,
    svc: tuple[int, int],
    data: bytes,
    *,
    msg_type: int = TYPE_RSD_A,
    category: int = CATEGORY_ACTIVE,
) -> bytes:
    if msg_type not in RSD_TYPES:
        raise ValueError(f"not an RSD type: {msg_type:#x}")
    n = len(data)
    if n > MAX_RSD_DATA_BYTES:
        raise ValueError(f"RSD data {n} bytes > {MAX_RSD_DATA_BYTES}")
    body = RSD_PREFIX.pack(category, msg_type, source, destination, tc, n + SDS_EXTRA_BYTES, svc[0], svc[1]) + data
    return body + CRC16_FIELD.pack(_crc.crc16(body))  # _with_crc16, inlined: one call less per frame


def encode_sse(
    source: int, destination: int, tc_e: int, seqenq: tuple[int, int], *, category: int = CATEGORY_ACTIVE
) -> bytes:
    return _with_crc16(SSE_BODY.pack(category, TYPE_SSE, source, destination, tc_e, seqenq[0], seqenq[1]))


def encode_ssr(
    source: int,
    destination: int,
    tc_r: int,
    tc_e: int,
    seqini: tuple[int, int],
    *,
    num_dataver: int = NUM_DATAVER,
    category: int = CATEGORY_ACTIVE,
) -> bytes:
    return _with_crc16(
        SSR_BODY.pack(category, TYPE_SSR, source, destination, tc_r, tc_e, seqini[0], seqini[1], num_dataver)
    )


def encode_frame(frame: Frame) -> bytes:
    if isinstance(frame, Rsd):
        return encode_rsd(
            frame.source, frame.destination, frame.tc, frame.svc, frame.data,
            msg_type=frame.msg_type, category=frame.category,
        )
    if isinstance(frame, Sse):
        return encode_sse(frame.source, frame.destination, frame.tc_e, frame.seqenq, category=frame.category)
    return encode_ssr(
        frame.source, frame.destination, frame.tc_r, frame.tc_e, frame.seqini,
        num_dataver=frame.num_dataver, category=frame.category,
    )


def check_crc16(frame: bytes | memoryview) -> bool:
    """True when the frame's last two bytes are the CRC16 of the rest (the explicit comparison)."""
    if len(frame) < CRC16_BYTES + 1:
        return False
    return _crc.crc16(frame[:-CRC16_BYTES]) == CRC16_FIELD.unpack_from(frame, len(frame) - CRC16_BYTES)[0]


def expected_length(prefix: bytes | memoryview) -> int | None:
    """The whole frame's length from its first bytes, or None when not yet known / not a frame type.

    RSSP-I frames are self-delimiting (type, and SDS for RSD), which the stream decoder and the
    capture inspector use to find frames without trusting anything else.
    """
    if len(prefix) < 2:
        return None
    msg_type = prefix[1]
    if msg_type == TYPE_SSE:
        return SSE_BYTES
    if msg_type == TYPE_SSR:
        return SSR_BYTES
    if msg_type in RSD_TYPES:
        if len(prefix) < RSD_PREFIX.size - 8:
            return None
        sds = struct.unpack_from("<H", prefix, HEADER.size)[0]
        return HEADER.size + 2 + sds + CRC16_BYTES
    return None


def decode_frame(frame: bytes | bytearray | memoryview) -> Frame:
    """Decode one whole frame, checking its size and CRC16. Raises FrameError."""
    n = len(frame)
    if n < SSE_BYTES:
        raise FrameError("short", f"{n} bytes")
    if n > MAX_FRAME_BYTES:
        raise FrameError("long", f"{n} bytes > {MAX_FRAME_BYTES}")
    msg_type = frame[1]
    if msg_type in RSD_TYPES:
        category, msg_type, source, destination, tc, sds, svc1, svc2 = RSD_PREFIX.unpack_from(frame, 0)
        if sds < SDS_EXTRA_BYTES or n != HEADER.size + 2 + sds + CRC16_BYTES:
            raise FrameError("length", f"SDS {sds} does not fit a {n}-byte RSD")
    elif msg_type == TYPE_SSE:
        if n != SSE_BYTES:
            raise FrameError("length", f"SSE of {n} bytes")
    elif msg_type == TYPE_SSR:
        if n != SSR_BYTES:
            raise FrameError("length", f"SSR of {n} bytes")
    else:
        raise FrameError("type", f"message type {msg_type:#04x}")
    body_end = n - CRC16_BYTES
    # A reflected CRC with init 0 and no final XOR, stored low byte first, leaves a zero residue when
    # run over the frame including its CRC: one pass, no slice (tests check it equals the
    # compare-with-stored-field form on every captured frame).
    if _crc.crc16(frame) != 0:
        raise FrameError("crc16")
    if msg_type in RSD_TYPES:
        data = frame[RSD_PREFIX.size : body_end]
        return Rsd(category, msg_type, source, destination, tc, (svc1, svc2), data if type(data) is bytes else bytes(data))
    if msg_type == TYPE_SSE:
        category, _t, source, destination, tc_e, q1, q2 = SSE_BODY.unpack_from(frame, 0)
        return Sse(category, source, destination, tc_e, (q1, q2))
    category, _t, source, destination, tc_r, tc_e, s1, s2, ndv = SSR_BODY.unpack_from(frame, 0)
    return Ssr(category, source, destination, tc_r, tc_e, (s1, s2), ndv)
