"""Open-bearer envelope: AES-256-GCM around each RSSP-I frame, with key ids and a replay window.

RSSP-I is a category-1 (closed network) protocol: its check words are linear and anyone holding two
frames can solve the SIDs and forge (rssp1.sid_recovery). Over cellular or any shared network
(EN 50159 category 3) every frame therefore travels sealed:

    version u8 (=1) | key id u16 | session u64 | sequence u64 | AES-GCM(frame) | tag (16 bytes)

all little-endian like RSSP-I. The 19-byte header is the AEAD associated data, so it cannot be altered.

- Per-session keys. The sender picks a session number when it starts (microseconds since the Unix
  epoch, so later sessions compare greater) and derives the session key with HKDF-SHA256 from the
  provisioned link key: salt = session, info = label | sender address | receiver address. The
  direction is bound into the key, so a frame reflected back to its sender does not open, and a
  (key, nonce) pair is never reused across restarts without any persisted counter. The nonce is the
  sequence number, which only grows within a session.
- Replay window (RFC 4303 section 3.4.3 style, 64 frames): a sequence number already seen or older
  than the window is rejected; a frame from a session older than the newest authenticated session is
  rejected. The window is only moved by frames that authenticate.
- Rejections are counted by reason (`short`, `version`, `unknown_key`, `auth`, `replay`,
  `old_session`) and never raise.

Key provisioning (operations):
1. Link keys are 256-bit random values, one per RSSP-I link (centre <-> RBC, onboard <-> ATP), made by
   the key management centre (an HSM or `python -c "import os; print(os.urandom(32).hex())"` on an
   offline machine) and given a 16-bit key id unique on that link.
2. They are delivered to both ends out of band, as EuroRadio KMAC keys are (ETCS SUBSET-038/-114):
   on removable media or an authenticated management channel, into a file readable only by the link
   service (`Keyring.from_mapping({"7": "<hex>"})`), never through the bearer they protect.
3. Rotation: install the new key (new id) at both ends alongside the old one; once both ends hold it,
   switch the senders' active id; remove the old key after the overlap. Receivers accept every id in
   their keyring, so nothing is lost while the ends switch at different moments.
4. Compromise: remove the key id from both keyrings; frames sealed with it stop opening at once.
A receiver that restarts accepts the newest session it authenticates; replayed frames of an older
session that slip in before the live session is seen are still subject to RSSP-I's own TC, timestamp
and SSE/SSR checks, which reject stale frames.
"""

from __future__ import annotations

import os
import struct
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Mapping

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives.ciphers.aead import AESGCM
from cryptography.hazmat.primitives.kdf.hkdf import HKDF

ENVELOPE_VERSION = 1
HEADER = struct.Struct("<BHQQ")  # version, key id, session, sequence
TAG_BYTES = 16  # AES-GCM full-length tag
KEY_BYTES = 32  # AES-256
REPLAY_WINDOW = 64  # frames; RFC 4303 default window size
HKDF_LABEL = b"augnet rssp1 envelope v1"
MAX_SEQUENCE = (1 << 64) - 1


@dataclass
class Keyring:
    """Provisioned link keys by key id, and the id senders use now."""

    keys: dict[int, bytes] = field(default_factory=dict)
    active_id: int | None = None

    def __post_init__(self) -> None:
        for kid, key in self.keys.items():
            if not 0 <= kid <= 0xFFFF:
                raise ValueError(f"key id {kid} is not 16-bit")
            if len(key) != KEY_BYTES:
                raise ValueError(f"key {kid}: {len(key)} bytes, need {KEY_BYTES}")
        if self.active_id is None and self.keys:
            self.active_id = max(self.keys)
        if self.active_id is not None and self.active_id not in self.keys:
            raise ValueError(f"active key id {self.active_id} not in the keyring")

    @classmethod
    def from_mapping(cls, m: Mapping[str, str], active_id: int | None = None) -> "Keyring":
        """From {"<key id>": "<64 hex digits>"}, as read from the provisioned key file."""
        return cls({int(k, 0): bytes.fromhex(v) for k, v in m.items()}, active_id)


def _session_key(link_key: bytes, session: int, sender: int, receiver: int) -> AESGCM:
    info = HKDF_LABEL + struct.pack("<HH", sender, receiver)
    derived = HKDF(algorithm=hashes.SHA256(), length=KEY_BYTES, salt=struct.pack("<Q", session), info=info)
    return AESGCM(derived.derive(link_key))


def _nonce(sequence: int) -> bytes:
    return struct.pack("<Q", sequence) + b"\0\0\0\0"


class Sealer:
    """The sending half: seal(frame) -> envelope."""

    def __init__(self, keyring: Keyring, sender: int, receiver: int, *, session: int | None = None) -> None:
        if keyring.active_id is None:
            raise ValueError("no active key to seal with")
        self.keyring = keyring
        self.sender, self.receiver = sender, receiver
        self.session = session if session is not None else time.time_ns() // 1000
        self.sequence = 0
        self._ciphers: dict[int, AESGCM] = {}

    def seal(self, frame: bytes) -> bytes:
        kid = self.keyring.active_id
        assert kid is not None
        cipher = self._ciphers.get(kid)
        if cipher is None:
            cipher = self._ciphers[kid] = _session_key(self.keyring.keys[kid], self.session, self.sender, self.receiver)
        if self.sequence >= MAX_SEQUENCE:
            raise RuntimeError("sequence space exhausted: start a new session")
        self.sequence += 1
        header = HEADER.pack(ENVELOPE_VERSION, kid, self.session, self.sequence)
        return header + cipher.encrypt(_nonce(self.sequence), bytes(frame), header)


class Opener:
    """The receiving half: open(envelope) -> frame, or None (counted in `stats`)."""

    def __init__(self, keyring: Keyring, sender: int, receiver: int) -> None:
        self.keyring = keyring
        self.sender, self.receiver = sender, receiver
        self.stats: Counter[str] = Counter()
        self.session = -1
        self.highest = 0
        self.window = 0  # bit i set: sequence (highest - i) seen
        self._ciphers: dict[tuple[int, int], AESGCM] = {}

    def _reject(self, reason: str) -> None:
        self.stats[f"rejected_{reason}"] += 1
        return None

    def open(self, envelope: bytes | bytearray | memoryview) -> bytes | None:
        envelope = bytes(envelope)
        if len(envelope) < HEADER.size + TAG_BYTES:
            return self._reject("short")
        version, kid, session, sequence = HEADER.unpack_from(envelope, 0)
        if version != ENVELOPE_VERSION:
            return self._reject("version")
        key = self.keyring.keys.get(kid)
        if key is None:
            return self._reject("unknown_key")
        if session < self.session:
            return self._reject("old_session")
        if session == self.session and not self._fresh(sequence):
            return self._reject("replay")
        cipher = self._ciphers.get((kid, session))
        if cipher is None:
            if len(self._ciphers) > 8:  # old sessions / retired keys: keep the cache small
                self._ciphers.clear()
            cipher = self._ciphers[(kid, session)] = _session_key(key, session, self.sender, self.receiver)
        try:
            frame = cipher.decrypt(_nonce(sequence), envelope[HEADER.size :], envelope[: HEADER.size])
        except InvalidTag:
            return self._reject("auth")
        if session > self.session:  # authenticated frame of a newer session: the sender restarted
            self.session, self.highest, self.window = session, 0, 0
            self.stats["sessions"] += 1
        self._mark(sequence)
        self.stats["opened"] += 1
        return frame

    def _fresh(self, sequence: int) -> bool:
        if sequence > self.highest:
            return True
        offset = self.highest - sequence
        return offset < REPLAY_WINDOW and not (self.window >> offset) & 1

    def _mark(self, sequence: int) -> None:
        if sequence > self.highest:
            shift = sequence - self.highest
            self.window = ((self.window << shift) | 1) & ((1 << REPLAY_WINDOW) - 1) if shift < REPLAY_WINDOW else 1
            self.highest = sequence
        else:
            self.window |= 1 << (self.highest - sequence)


def random_link_key() -> bytes:
    """A fresh 256-bit link key (for tests and for the key management centre's tooling)."""
    return os.urandom(KEY_BYTES)


class SealedEndpoint:
    """An rssp1.endpoint.Endpoint whose frames travel in envelopes: same cycle/receive interface."""

    def __init__(self, endpoint, keyring: Keyring, *, session: int | None = None) -> None:
        from rssp1.endpoint import FrameDropped  # local: keep this module importable on its own

        self._dropped = FrameDropped
        self.endpoint = endpoint
        local, peer = endpoint.local.address, endpoint.peer.address
        self.sealer = Sealer(keyring, local, peer, session=session)
        self.opener = Opener(keyring, peer, local)

    def receive(self, envelope: bytes | bytearray | memoryview) -> list:
        """Open, then hand the frame to RSSP-I; an envelope that does not open is counted and dropped
        (the reason is in `opener.stats`)."""
        frame = self.opener.open(envelope)
        if frame is None:
            self.endpoint.stats["dropped_envelope"] += 1
            return [self._dropped("envelope")]
        return self.endpoint.receive(frame)

    def cycle(self, data: bytes | None = None) -> tuple[list[bytes], list]:
        frames, events = self.endpoint.cycle(data)
        return [self.sealer.seal(f) for f in frames], events

    @property
    def is_up(self) -> bool:
        return self.endpoint.is_up

    @property
    def timing(self):
        return self.endpoint.timing

    @property
    def state(self):
        return self.endpoint.state

    @property
    def stats(self):
        return self.endpoint.stats
