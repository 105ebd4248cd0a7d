"""Encode and decode any supported RTCM 3 message, driven by the layouts in ``layouts.py``.

``decode(payload)`` returns an ``RtcmMessage`` (fixed-layout messages: a dict of field values exactly
as pyrtcm reports them), an ``MsmMessage`` (arrays, see ``msm.py``) or an ``UnknownMessage`` (type
and payload kept, so a stream can be passed through unchanged). ``encode(message)`` is the inverse
and returns the payload; ``encode_frame`` adds the frame and CRC.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from augnet.gnss.rtcm.errors import DecodeError, EncodeError
from augnet.gnss.rtcm.fields import FIELDS, decode_raw, encode_raw, from_value, to_value
from augnet.gnss.rtcm.layouts import LAYOUTS, Repeat, msm_kind
from augnet.gnss.rtcm.msm import MsmMessage, decode_msm, encode_msm, msm_from_fields
from augwire.rtcm_framing import Frame, RtcmStreamReader, frame, message_type


@dataclass
class RtcmMessage:
    """A fixed-layout message: ``fields`` maps pyrtcm's attribute names to values (scaled)."""

    msg_type: int
    fields: dict[str, object] = field(default_factory=dict)

    def __getitem__(self, name: str):
        return self.fields[name]

    def text(self, item: str) -> str:
        """The characters of a repeated character field joined, e.g. ``text("DF228")`` for 1033."""
        out = []
        i = 1
        while (key := f"{item}_{i:02d}") in self.fields:
            out.append(self.fields[key])
            i += 1
        return "".join(out)


@dataclass
class UnknownMessage:
    """A message type this codec does not interpret; the payload is kept verbatim."""

    msg_type: int
    payload: bytes


Message = RtcmMessage | MsmMessage | UnknownMessage


def decode_fixed(payload: bytes, msg_type: int) -> RtcmMessage:
    layout = LAYOUTS[msg_type]
    nbits = len(payload) * 8
    value = int.from_bytes(payload, "big")
    pos = 0
    out: dict[str, object] = {}

    def take(name: str, key: str) -> int:
        nonlocal pos
        f = FIELDS[name]
        if pos + f.width > nbits:
            raise DecodeError(f"message {msg_type}: payload of {len(payload)} bytes ends inside {key}")
        raw = decode_raw(f, (value >> (nbits - pos - f.width)) & ((1 << f.width) - 1))
        pos += f.width
        out[key] = to_value(f, raw)
        return raw

    for item in layout:
        if isinstance(item, Repeat):
            for i in range(int(out[item.counter])):
                take(item.item, f"{item.item}_{i + 1:02d}")
        else:
            take(item, item)
    return RtcmMessage(msg_type, out)


def encode_fixed(msg: RtcmMessage) -> bytes:
    try:
        layout = LAYOUTS[msg.msg_type]
    except KeyError:
        raise EncodeError(f"message type {msg.msg_type} has no fixed layout") from None
    fields = dict(msg.fields)
    fields.setdefault("DF002", msg.msg_type)
    if fields["DF002"] != msg.msg_type:
        raise EncodeError(f"DF002 = {fields['DF002']} but the message is a {msg.msg_type}")
    acc = 0
    nbits = 0

    def put(name: str, key: str) -> None:
        nonlocal acc, nbits
        f = FIELDS[name]
        try:
            v = fields[key]
        except KeyError:
            if name.startswith("DF001"):  # reserved bits default to zero
                v = 0
            else:
                raise EncodeError(f"message {msg.msg_type}: field {key} ({f.what}) missing") from None
        try:
            raw = encode_raw(f, from_value(f, v))
        except (ValueError, TypeError) as err:
            raise EncodeError(f"message {msg.msg_type}: {key}: {err}") from None
        acc = (acc << f.width) | raw
        nbits += f.width

    for item in layout:
        if isinstance(item, Repeat):
            count = int(fields.get(item.counter, 0))
            for i in range(count):
                put(item.item, f"{item.item}_{i + 1:02d}")
        else:
            put(item, item)
    pad = -nbits % 8
    return (acc << pad).to_bytes((nbits + pad) // 8, "big")


def text_fields(item: str, counter: str, text: str) -> dict[str, object]:
    """Fields for a 1033 string: ``text_fields("DF228", "DF227", "TRIMBLE NETR9")``."""
    raw = text.encode("latin-1")
    if len(raw) > 255:
        raise EncodeError(f"{counter}: at most 255 characters, got {len(raw)}")
    out: dict[str, object] = {counter: len(raw)}
    for i, ch in enumerate(text):
        out[f"{item}_{i + 1:02d}"] = ch
    return out


def decode(data: bytes | Frame) -> Message:
    """Decode one message from its payload (or a ``Frame``). Raises ``DecodeError`` when malformed."""
    payload = data.payload if isinstance(data, Frame) else data
    mt = message_type(payload)
    if len(payload) < 2:
        raise DecodeError(f"payload of {len(payload)} bytes is too short for a message number")
    try:
        if mt in LAYOUTS:
            return decode_fixed(payload, mt)
        if msm_kind(mt) is not None:
            return decode_msm(payload)
    except DecodeError:
        raise
    except (ValueError, IndexError) as err:
        raise DecodeError(f"message {mt}: {err}") from err
    return UnknownMessage(mt, bytes(payload))


def encode(msg: Message) -> bytes:
    """The payload of a message (no frame)."""
    if isinstance(msg, RtcmMessage):
        if msm_kind(msg.msg_type) is not None:  # an MSM given as pyrtcm-style fields
            return encode_msm(msm_from_fields({"DF002": msg.msg_type, **msg.fields}))
        return encode_fixed(msg)
    if isinstance(msg, MsmMessage):
        return encode_msm(msg)
    if isinstance(msg, UnknownMessage):
        return msg.payload
    raise EncodeError(f"cannot encode {type(msg).__name__}")


def encode_frame(msg: Message) -> bytes:
    """The framed message (preamble, length, payload, CRC-24Q)."""
    return frame(encode(msg))


class MessageReader:
    """Sans-IO bytes -> decoded messages: frames from ``RtcmStreamReader``, then ``decode``.

    Never raises on input: a CRC-valid frame whose payload does not hold its message is counted in
    ``decode_errors`` (with the last error kept for the operator) and skipped.
    """

    def __init__(self) -> None:
        self.frames = RtcmStreamReader()
        self.decode_errors = 0
        self.last_error: str | None = None

    def feed(self, data: bytes) -> list[Message]:
        return self._decode_all(self.frames.feed(data))

    def close(self) -> list[Message]:
        return self._decode_all(self.frames.close())

    def _decode_all(self, frames: list[Frame]) -> list[Message]:
        out: list[Message] = []
        for fr in frames:
            try:
                out.append(decode(fr.payload))
            except DecodeError as err:
                self.decode_errors += 1
                self.last_error = str(err)
        return out


__all__ = [
    "MessageReader",
    "DecodeError", "EncodeError", "Message", "MsmMessage", "RtcmMessage", "UnknownMessage",
    "decode", "decode_fixed", "encode", "encode_fixed", "encode_frame", "text_fields",
]
