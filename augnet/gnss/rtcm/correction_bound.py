"""RTCM 3 proprietary message 4001: the centre's overbound sigma of its correction error, per satellite.

Layout and scaling: docs/correction-bound-message.md. The payload sits in an ordinary RTCM 3 frame
(`augwire.rtcm_framing.frame`, CRC-24Q), so every framer passes it and pyrtcm parses it generically
(identity "4001", no fields); `augnet.gnss.rtcm.decode` keeps returning it as an `UnknownMessage`, so a
client that does not know 4001 ignores it. Only `decode_correction_bound` reads it.

A sigma is rounded UP to the resolution (an overbound must not shrink in transit); a sigma beyond the
range, or none (NaN), is sent as `SIGMA_NOT_AVAILABLE` and decoded as NaN: the rover must then treat that
satellite's corrections as unbounded, never as exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from augnet.gnss.rtcm.errors import DecodeError, EncodeError
from augwire.rtcm_framing import frame, message_type

# Proprietary range 4001-4095 (RTCM 10403.3 Table 3.5-1); 4001 is not among the allocations pyrtcm 1.2.1
# lists (4048-4095); a production deployment must obtain an allocation from RTCM SC-104.
CORRECTION_BOUND_MESSAGE = 4001
SUBTYPE_SIGMA = 1  # version 1 of the layout: per-satellite overbound sigma
SIGMA_RESOLUTION_M = 1e-4  # 0.1 mm: well below the few-mm sigma of a short baseline
SIGMA_BITS = 14
SIGMA_NOT_AVAILABLE = (1 << SIGMA_BITS) - 1  # 16383: no bound for this satellite
SIGMA_MAX_M = (SIGMA_NOT_AVAILABLE - 1) * SIGMA_RESOLUTION_M  # 1.6382 m
# Systems by RINEX letter -> 3-bit id (the order of RINEX 3.04 section 3.5)
SYSTEM_IDS = {"G": 0, "R": 1, "E": 2, "C": 3, "J": 4, "I": 5, "S": 6}
_SYSTEM_LETTERS = {v: k for k, v in SYSTEM_IDS.items()}
MAX_SATELLITES = 63  # 6-bit count
EPOCH_MS_MODULUS = 604_800_000  # GNSS time of week [ms], 30 bits like DF004
# (name, bits) of the header, then per satellite: system 3, PRN 6, sigma 14 bits
_HEADER = (("msg", 12), ("subtype", 4), ("station", 12), ("epoch_ms", 30), ("train", 16),
           ("ionosphere_cppm", 10), ("count", 6))
_PER_SAT = (("system", 3), ("prn", 6), ("sigma", SIGMA_BITS))
IONOSPHERE_RESOLUTION_PPM = 0.01  # the epoch's ionosphere level, 0.01 ppm, max 10.22 ppm
IONOSPHERE_NOT_AVAILABLE = (1 << 10) - 1


@dataclass
class CorrectionBoundMessage:
    station_id: int  # the VRS's reference station id (DF003 of its 1006)
    epoch_ms: int  # GNSS time of week [ms] of the epoch the bound is for
    train_id: int  # 16-bit id of the client the VRS is for
    sats: list[str]  # "G05", "E11", ...
    sigma_m: np.ndarray  # overbound sigma [m] per satellite, NaN = no bound
    ionosphere_level_ppm: float = math.nan  # the epoch's ionosphere level the bound was scaled by


def _sigma_raw(sigma_m: np.ndarray) -> np.ndarray:
    s = np.asarray(sigma_m, dtype=float)
    if np.any(s[np.isfinite(s)] < 0):
        raise EncodeError("a correction-bound sigma is negative")
    raw = np.full(s.shape, SIGMA_NOT_AVAILABLE, dtype=np.int64)
    ok = np.isfinite(s) & (s <= SIGMA_MAX_M)
    # ceil with a small tolerance so that an exact multiple survives float noise without growing a step
    raw[ok] = np.ceil(s[ok] / SIGMA_RESOLUTION_M - 1e-9).astype(np.int64)
    return raw


def encode_correction_bound(msg: CorrectionBoundMessage) -> bytes:
    """The 4001 payload (no frame)."""
    sats = [str(s) for s in msg.sats]
    sigma = np.asarray(msg.sigma_m, dtype=float).ravel()
    if sigma.size != len(sats):
        raise EncodeError(f"4001: {len(sats)} satellites but {sigma.size} sigmas")
    if len(sats) > MAX_SATELLITES:
        raise EncodeError(f"4001: at most {MAX_SATELLITES} satellites, got {len(sats)}")
    if not 0 <= msg.station_id < 4096 or not 0 <= msg.train_id < 65536:
        raise EncodeError(f"4001: station id {msg.station_id} (12 bits) or train id {msg.train_id} (16 bits) "
                          "out of range")
    iono = msg.ionosphere_level_ppm
    iono_raw = IONOSPHERE_NOT_AVAILABLE if not np.isfinite(iono) or iono < 0 else \
        min(int(round(iono / IONOSPHERE_RESOLUTION_PPM)), IONOSPHERE_NOT_AVAILABLE - 1)
    values = {"msg": CORRECTION_BOUND_MESSAGE, "subtype": SUBTYPE_SIGMA, "station": msg.station_id,
              "epoch_ms": int(msg.epoch_ms) % EPOCH_MS_MODULUS, "train": msg.train_id,
              "ionosphere_cppm": iono_raw, "count": len(sats)}
    acc, nbits = 0, 0
    for name, width in _HEADER:
        acc, nbits = (acc << width) | values[name], nbits + width
    raw = _sigma_raw(sigma)
    for sat, r in zip(sats, raw):
        try:
            sys_id, prn = SYSTEM_IDS[sat[0]], int(sat[1:])
        except (KeyError, ValueError, IndexError):
            raise EncodeError(f"4001: satellite {sat!r} is not a RINEX satellite name") from None
        if not 1 <= prn <= 63:
            raise EncodeError(f"4001: PRN of {sat!r} outside 1..63")
        for v, (_, width) in zip((sys_id, prn, int(r)), _PER_SAT):
            acc, nbits = (acc << width) | v, nbits + width
    pad = -nbits % 8
    return (acc << pad).to_bytes((nbits + pad) // 8, "big")


def encode_correction_bound_frame(msg: CorrectionBoundMessage) -> bytes:
    """The framed 4001 (preamble, length, payload, CRC-24Q)."""
    return frame(encode_correction_bound(msg))


def decode_correction_bound(payload: bytes) -> CorrectionBoundMessage:
    """Read a 4001 payload; `DecodeError` when it is not one or is truncated."""
    payload = bytes(payload)
    if message_type(payload) != CORRECTION_BOUND_MESSAGE:
        raise DecodeError(f"not a {CORRECTION_BOUND_MESSAGE} message (type {message_type(payload)})")
    nbits = len(payload) * 8
    value = int.from_bytes(payload, "big")
    pos = 0

    def take(width: int, what: str) -> int:
        nonlocal pos
        if pos + width > nbits:
            raise DecodeError(f"4001: payload of {len(payload)} bytes ends inside {what}")
        out = (value >> (nbits - pos - width)) & ((1 << width) - 1)
        pos += width
        return out

    head = {name: take(width, name) for name, width in _HEADER}
    if head["subtype"] != SUBTYPE_SIGMA:
        raise DecodeError(f"4001: sub-type {head['subtype']} unknown (this decoder reads {SUBTYPE_SIGMA})")
    sats, raw = [], []
    for _ in range(head["count"]):
        sys_id, prn, r = (take(width, name) for name, width in _PER_SAT)
        if sys_id not in _SYSTEM_LETTERS:
            raise DecodeError(f"4001: system id {sys_id} unknown")
        sats.append(f"{_SYSTEM_LETTERS[sys_id]}{prn:02d}")
        raw.append(r)
    raw = np.array(raw, dtype=np.int64)
    sigma = np.where(raw == SIGMA_NOT_AVAILABLE, np.nan, raw * SIGMA_RESOLUTION_M)
    iono = math.nan if head["ionosphere_cppm"] == IONOSPHERE_NOT_AVAILABLE else \
        head["ionosphere_cppm"] * IONOSPHERE_RESOLUTION_PPM
    return CorrectionBoundMessage(head["station"], head["epoch_ms"], head["train"], sats, sigma, iono)


__all__ = [
    "CORRECTION_BOUND_MESSAGE", "CorrectionBoundMessage", "SIGMA_MAX_M", "SIGMA_NOT_AVAILABLE",
    "SIGMA_RESOLUTION_M", "decode_correction_bound", "encode_correction_bound",
    "encode_correction_bound_frame",
]
