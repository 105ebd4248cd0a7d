"""The versioned envelope every regional model travels in, and the fence an edge applies (issue 17).

Protocol core, no I/O. Layout (big-endian): magic b"AGNM", version u8, region length u8, region utf-8,
lease revision u64, epoch GPST milliseconds i64, payload length u32, payload, CRC-32 of all before it.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

MAGIC = b"AGNM"
VERSION = 1
_HEAD = struct.Struct(">4sBB")
_FIXED = struct.Struct(">QqI")
_CRC = struct.Struct(">I")
MAX_PAYLOAD_BYTES = 16 * 1024 * 1024  # a bound on one epoch's model; 60 stations are far below it


class ModelDecodeError(ValueError):
    """The bytes are not a model envelope this code can read (corrupt, truncated or another version)."""


@dataclass(frozen=True)
class Envelope:
    region: str
    lease_revision: int
    epoch_ms: int
    payload: bytes


def encode(env: Envelope) -> bytes:
    region = env.region.encode()
    if not 0 < len(region) < 256:
        raise ValueError(f"region name must be 1..255 bytes, got {len(region)}")
    body = (_HEAD.pack(MAGIC, VERSION, len(region)) + region
            + _FIXED.pack(env.lease_revision, env.epoch_ms, len(env.payload)) + env.payload)
    return body + _CRC.pack(zlib.crc32(body))


def decode(data: bytes) -> Envelope:
    if len(data) < _HEAD.size + _FIXED.size + _CRC.size:
        raise ModelDecodeError(f"too short for a model envelope: {len(data)} bytes")
    magic, version, n = _HEAD.unpack_from(data)
    if magic != MAGIC:
        raise ModelDecodeError(f"bad magic {magic!r}")
    if version != VERSION:
        raise ModelDecodeError(f"model version {version}, this code reads {VERSION}")
    off = _HEAD.size + n
    if len(data) < off + _FIXED.size + _CRC.size:
        raise ModelDecodeError("truncated header")
    rev, epoch_ms, plen = _FIXED.unpack_from(data, off)
    off += _FIXED.size
    if plen > MAX_PAYLOAD_BYTES or len(data) != off + plen + _CRC.size:
        raise ModelDecodeError(f"payload length {plen} does not match {len(data)} bytes")
    (crc,) = _CRC.unpack_from(data, off + plen)
    if crc != zlib.crc32(data[:off + plen]):
        raise ModelDecodeError("CRC mismatch")
    try:
        region = data[_HEAD.size:_HEAD.size + n].decode()
    except UnicodeDecodeError as e:
        raise ModelDecodeError("region is not utf-8") from e
    return Envelope(region, rev, epoch_ms, bytes(data[off:off + plen]))


@dataclass
class Fence:
    """Per region, accept a model only from the newest lease revision seen and only for a later epoch:
    a deposed leader's late publications never take effect (issue 17, fencing by lease revision)."""
    newest: dict[str, tuple[int, int]] = field(default_factory=dict)
    decode_errors: int = 0
    fenced: int = 0

    def admit(self, data: bytes) -> Envelope | None:
        try:
            env = decode(data)
        except ModelDecodeError:
            self.decode_errors += 1
            return None
        last = self.newest.get(env.region)
        # an older lease is a deposed leader; a repeated or earlier epoch was already served by some leader
        if last is not None and (env.lease_revision < last[0] or env.epoch_ms <= last[1]):
            self.fenced += 1
            return None
        self.newest[env.region] = (env.lease_revision, env.epoch_ms)
        return env
