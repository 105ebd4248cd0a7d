"""The protocol between `augnet up` (the loop) and its centre process: typed messages, one sans-IO codec.

    data = encode(StationData("WEST", rtcm, time.time()))   # one frame
    decoder = Decoder(FROM_CENTRE)
    for msg in decoder.receive_data(chunk):                   # may raise ProtocolError
        ...

Frame (both directions, one Unix socket pair): an 8-byte header, then the body.
    magic    2 bytes   b"AC"
    version  u8        PROTOCOL_VERSION
    type     u8        the message's code in `LAYOUTS`
    length   u32       body bytes, at most MAX_BODY_BYTES
The body is the message's fields in the order of its layout, each in the wire form of its codec (all
integers and floats little-endian: both ends run on one host):
    f64, i64           8 bytes
    bool               1 byte, 0 or 1
    str, bytes         u32 length, then the bytes (str as UTF-8)
    optional X         1 byte, 0 (absent) or 1, then X
    list / set of X    u32 count, then the items; a tuple of N X: the N items
    dict K -> V        u32 count, then key, value pairs in the dict's order
    ndarray            dtype (8 bytes, space-padded: "<f8", "<U3"; object arrays are refused), ndim u8,
                       ndim u32 sizes, then the C-order bytes
    packed bytes       u32 count, u32 lengths, then the items' bytes (a VRS group's RTCM)
    separated strs     u32 count, then a str of the items joined by NUL (a VRS group's client ids; an item
                       holding NUL is refused)
    record             a dataclass's fields by its layout (EpochReport, NetworkEpoch, BaselineEpoch, Alarm)

Loop -> centre (the loop writes the messages of one loop iteration together, in the order they happened):
    StationData     bytes of a station's stream as the caster got them (minus disabled stations)
    OpenSession     a VRS session (the client's first usable GGA)
    MoveSession     the client moved (the caster's reposition policy); opened and moved sessions are added
                    to the next epoch's plan between epochs (`centre_service.PLAN_UPDATE_S`)
    CloseSession
    StationMembership  a station joins (`xyz_m` given, not yet a member), moves (given, a member) or leaves
                    (None): the store's station table changed (`station_membership.py`)
    SessionBound    whether a session's VRS carries the correction-error bound (RTCM 4001): its mountpoint's
                    store field `correction_bound` (decision 0281); sent after OpenSession when on, and on a change
    VrsWritten      the last group of epoch t's VRS is written to the sockets: the centre may solve the network
    Stop            finish and exit (EOF on the socket does the same)
Centre -> loop:
    Ready           the engine is built
    VrsGroup        the sessions' epoch t, in groups of `centre_service.VRS_GROUP` sessions, each sent as
                    soon as it is encoded (the loop writes one group while the centre encodes the next), all
                    before the network solves t: the solve waits for VrsWritten (at most
                    `centre_service.WRITTEN_WAIT_S`), so on two cores it does not take a core from delivery
    EpochsSolved    the solved epochs' reports (their `vrs` arrays stay in the centre: `vrs_models` carries
                    what the console shows), the correction models and alarms for the bus
    CentreError     a command or an epoch failed; the centre carries on
    Alive           a heartbeat when nothing else was sent for `centre_service.HEARTBEAT_S`

Bad input (wrong magic, another version, an unknown or unexpected type, a length over the limit, a body
shorter than its fields, a malformed field, bytes left over) raises `ProtocolError`; the decoder then stays
failed: a byte stream that lost its framing cannot be trusted again.
"""

from __future__ import annotations

import dataclasses
import math
import struct
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from augnet.centre.baseline import BaselineEpoch
from augnet.centre.engine import EpochReport
from augnet.centre.integrity import Alarm
from augnet.centre.network import NetworkEpoch

MAGIC = b"AC"
PROTOCOL_VERSION = 1
# a group of 500 sessions' VRS is ~0.5 MB and a 60-station epoch report ~0.3 MB (`augnet bench protocol`);
# 64 MiB is room for an ungrouped epoch of tens of thousands of sessions while a corrupted length (up to
# 4 GiB) is refused before it is buffered
MAX_BODY_BYTES = 64 << 20
# the decoder's buffer: a VRS group (~0.5 MB) and the read behind it fit; kept while frames fit in
# KEEP_BUFFER_BYTES
RECEIVE_BUFFER_BYTES = 2 << 20
KEEP_BUFFER_BYTES = 8 << 20
MIN_READ_BYTES = 256 << 10  # room offered to a read: asyncio's own read size (selector_events.max_size)
_HEADER = struct.Struct("<2sBBI")
HEADER_BYTES = _HEADER.size


class ProtocolError(Exception):
    """Bad input on the centre-process protocol. `messages`: those decoded, in the same `receive_data`
    call, before the bad frame (the caller may still act on them)."""

    def __init__(self, message: str, messages: list | None = None):
        super().__init__(message)
        self.messages = messages if messages is not None else []


# --- the messages -----------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class StationData:
    station: str
    data: bytes
    arrival_unix_s: float  # host clock when the caster got them


@dataclass(frozen=True, slots=True)
class OpenSession:
    client_id: str
    lat_deg: float
    lon_deg: float
    h_m: float


@dataclass(frozen=True, slots=True)
class MoveSession:
    client_id: str
    lat_deg: float
    lon_deg: float
    h_m: float


@dataclass(frozen=True, slots=True)
class CloseSession:
    client_id: str


@dataclass(frozen=True, slots=True)
class StationMembership:
    station: str
    xyz_m: tuple[float, float, float] | None  # ECEF [m]; None: the station leaves


@dataclass(frozen=True, slots=True)
class SessionBound:
    client_id: str
    send: bool


@dataclass(frozen=True, slots=True)
class VrsWritten:
    t_gpst: float


@dataclass(frozen=True, slots=True)
class Stop:
    pass


@dataclass(frozen=True, slots=True)
class Ready:
    pid: int


@dataclass(frozen=True, slots=True)
class VrsGroup:
    t_gpst: float
    client_ids: list[str]
    rtcm: list[bytes]  # each client's epoch t, RTCM 3 frames
    ready_unix_s: float  # host clock when the group was encoded
    arrival: tuple[float, float] | None  # first and last station data of epoch t reached the centre (Unix s)
    cost: tuple[float, float, float, float] | None  # synthesis, encoding (wall), their CPU [s], 1.0 planned ahead
    last: bool  # the epoch's last group

    def __post_init__(self) -> None:
        if len(self.client_ids) != len(self.rtcm):
            raise ValueError(f"{len(self.client_ids)} client ids for {len(self.rtcm)} RTCM epochs")


@dataclass(frozen=True, slots=True)
class EpochsSolved:
    reports: list[EpochReport]
    outbox: list[tuple[str, bytes]]  # (bus subject, payload)
    solve_s: float  # wall time per solved epoch
    sessions: int


@dataclass(frozen=True, slots=True)
class CentreError:
    text: str


@dataclass(frozen=True, slots=True)
class Alive:
    pass


LoopMessage = (StationData | OpenSession | MoveSession | CloseSession | StationMembership | SessionBound | VrsWritten
               | Stop)
CentreMessage = Ready | VrsGroup | EpochsSolved | CentreError | Alive
Message = LoopMessage | CentreMessage
FROM_LOOP = (StationData, OpenSession, MoveSession, CloseSession, StationMembership, SessionBound, VrsWritten, Stop)
FROM_CENTRE = (Ready, VrsGroup, EpochsSolved, CentreError, Alive)


# --- field codecs: put(parts, value) appends the value's bytes, get(reader) reads it back --------------------


class _Reader:
    """A frame body being read; reading past its end is a truncated body."""

    __slots__ = ("view", "pos")

    def __init__(self, view: memoryview):
        self.view = view
        self.pos = 0

    def take(self, n: int) -> memoryview:
        end = self.pos + n
        if end > len(self.view):
            raise ProtocolError(f"truncated body: {n} bytes needed at offset {self.pos}, "
                                f"{len(self.view) - self.pos} left")
        out = self.view[self.pos:end]
        self.pos = end
        return out

    def unpack(self, s: struct.Struct) -> tuple:
        try:
            out = s.unpack_from(self.view, self.pos)
        except struct.error:
            raise ProtocolError(f"truncated body: {s.size} bytes needed at offset {self.pos}, "
                                f"{len(self.view) - self.pos} left") from None
        self.pos += s.size
        return out


_U8 = struct.Struct("<B")
_U32 = struct.Struct("<I")
_SHAPES = [struct.Struct(f"<{ndim}I") for ndim in range(256)]  # an array's sizes, by its ndim (a u8)


class _Number:
    def __init__(self, fmt: str):
        self.s = struct.Struct(fmt)

    def put(self, parts: list, v) -> None:
        parts.append(self.s.pack(v))

    def get(self, r: _Reader):
        return r.unpack(self.s)[0]


class _Bool:
    def put(self, parts: list, v) -> None:
        parts.append(b"\x01" if v else b"\x00")

    def get(self, r: _Reader) -> bool:
        b = r.unpack(_U8)[0]
        if b > 1:
            raise ProtocolError(f"malformed body: bool byte {b} at offset {r.pos - 1}")
        return bool(b)


class _Bytes:
    def put(self, parts: list, v: bytes) -> None:
        parts.append(_U32.pack(len(v)))
        parts.append(v)

    def get(self, r: _Reader) -> bytes:
        return bytes(r.take(r.unpack(_U32)[0]))


class _Str:
    def put(self, parts: list, v: str) -> None:
        b = v.encode()
        parts.append(_U32.pack(len(b)))
        parts.append(b)

    def get(self, r: _Reader) -> str:
        return str(r.take(r.unpack(_U32)[0]), "utf-8")


class _Optional:
    def __init__(self, item):
        self.item = item

    def put(self, parts: list, v) -> None:
        if v is None:
            parts.append(b"\x00")
        else:
            parts.append(b"\x01")
            self.item.put(parts, v)

    def get(self, r: _Reader):
        return self.item.get(r) if BOOL.get(r) else None


class _List:
    def __init__(self, item, kind: type = list):
        self.item = item
        self.kind = kind

    def put(self, parts: list, v) -> None:
        parts.append(_U32.pack(len(v)))
        for x in v:
            self.item.put(parts, x)

    def get(self, r: _Reader):
        n = r.unpack(_U32)[0]
        return self.kind(self.item.get(r) for _ in range(n))


class _Tuple:
    def __init__(self, item, n: int):
        self.item = item
        self.n = n

    def put(self, parts: list, v) -> None:
        if len(v) != self.n:
            raise ValueError(f"{len(v)} items, not {self.n}")
        for x in v:
            self.item.put(parts, x)

    def get(self, r: _Reader) -> tuple:
        return tuple(self.item.get(r) for _ in range(self.n))


class _Dict:
    def __init__(self, key, value):
        self.key = key
        self.value = value

    def put(self, parts: list, v: dict) -> None:
        parts.append(_U32.pack(len(v)))
        for k, x in v.items():
            self.key.put(parts, k)
            self.value.put(parts, x)

    def get(self, r: _Reader) -> dict:
        out = {}
        for _ in range(r.unpack(_U32)[0]):
            k = self.key.get(r)
            out[k] = self.value.get(r)
        return out


class _Array:
    """A numpy array as dtype, shape and its C-order bytes (decoded into an array of its own, writable)."""

    HEAD = struct.Struct("<8sB")  # dtype string (space-padded: "<f8", "<U3", "|b1"), ndim

    def __init__(self):
        self._dtypes: dict[bytes, np.dtype] = {}  # dtype strings seen, parsed once

    def put(self, parts: list, v: np.ndarray) -> None:
        a = np.ascontiguousarray(v)
        code = a.dtype.str.encode()
        if a.dtype.hasobject or a.dtype.kind == "V" or len(code) > 8:
            raise ValueError(f"dtype {a.dtype} has no byte form of its own")
        parts.append(self.HEAD.pack(code.ljust(8), a.ndim))
        parts.append(_SHAPES[a.ndim].pack(*a.shape))
        parts.append(a.tobytes())

    def get(self, r: _Reader) -> np.ndarray:
        code, ndim = r.unpack(self.HEAD)
        dtype = self._dtypes.get(code)
        if dtype is None:
            dtype = self._dtype(code)
        shape = r.unpack(_SHAPES[ndim])
        count = math.prod(shape)
        data = r.take(count * dtype.itemsize)
        if dtype.itemsize == 0:
            return np.zeros(shape, dtype)
        return np.frombuffer(data, dtype, count).reshape(shape).copy()

    def _dtype(self, code: bytes) -> np.dtype:
        text = code.rstrip(b" ")
        try:
            dtype = np.dtype(text.decode("ascii"))
        except Exception as exc:  # noqa: BLE001 - numpy's parser raises TypeError, ValueError, SyntaxError...
            raise ProtocolError(f"malformed body: dtype {text!r}: {exc}") from None
        if dtype.hasobject or dtype.kind == "V" or dtype.subdtype is not None:
            raise ProtocolError(f"malformed body: dtype {text!r} refused (objects and records do not cross)")
        if len(self._dtypes) < 64:  # garbage must not grow it
            self._dtypes[code] = dtype
        return dtype


class _PackedBytes:
    """A list of bytes in two pieces, their lengths then their contents: a VRS group's 500 sessions cost
    one length array instead of 500 reads."""

    def put(self, parts: list, v: list[bytes]) -> None:
        parts.append(_U32.pack(len(v)))
        parts.append(np.fromiter(map(len, v), "<u4", len(v)).tobytes())
        parts.extend(v)

    def get(self, r: _Reader) -> list[bytes]:
        n = r.unpack(_U32)[0]
        lengths = np.frombuffer(r.take(4 * n), "<u4")  # read before anything is allocated for n items
        off = np.zeros(n + 1, np.int64)
        np.cumsum(lengths, out=off[1:])
        bounds = off.tolist()
        view = r.take(bounds[-1])
        # each item copied once, straight from the frame (an intermediate copy of the whole group is a
        # fresh 0.5 MB allocation per group, whose page faults cost more than the copying)
        return [view[a:b].tobytes() for a, b in zip(bounds, bounds[1:])]


class _SeparatedStrs:
    """A list of str holding no NUL: the count, then their UTF-8 joined by NUL (split in one call)."""

    def put(self, parts: list, v: list[str]) -> None:
        text = "\0".join(v)
        if text.count("\0") != max(len(v) - 1, 0):
            raise ValueError("a str of a packed list holds NUL")
        parts.append(_U32.pack(len(v)))
        STR.put(parts, text)

    def get(self, r: _Reader) -> list[str]:
        n = r.unpack(_U32)[0]
        text = STR.get(r)
        items = text.split("\0") if n or text else []
        if len(items) != n:
            raise ProtocolError(f"malformed body: {len(items)} strs where the count says {n}")
        return items


class _Pair:
    def __init__(self, first, second):
        self.first = first
        self.second = second

    def put(self, parts: list, v: tuple) -> None:
        a, b = v
        self.first.put(parts, a)
        self.second.put(parts, b)

    def get(self, r: _Reader) -> tuple:
        return self.first.get(r), self.second.get(r)


class _Record:
    """A dataclass by its layout; `left_behind` names fields that do not cross (given on decoding)."""

    def __init__(self, kind: type, layout: tuple, left_behind: dict[str, Any] | None = None):
        self.kind = kind
        self.layout = layout
        self.left_behind = left_behind or {}
        self._names = tuple(name for name, _ in layout)
        self._getters = tuple(codec.get for _, codec in layout)
        fields = [f.name for f in dataclasses.fields(kind)]
        if set(self._names) | set(self.left_behind) != set(fields):  # a new field must get a wire form here
            raise TypeError(f"{kind.__name__}: layout {sorted(self._names)} is not its fields {sorted(fields)}")
        self._positional = list(self._names) == fields

    def put(self, parts: list, v) -> None:
        for name, codec in self.layout:
            codec.put(parts, getattr(v, name))

    def get(self, r: _Reader):
        values = [get(r) for get in self._getters]
        if self._positional:
            return self.kind(*values)
        return self.kind(**dict(zip(self._names, values)), **self.left_behind)


F64 = _Number("<d")
I64 = _Number("<q")
BOOL = _Bool()
BYTES = _Bytes()
STR = _Str()
ARRAY = _Array()
SEPARATED_STRS = _SeparatedStrs()
PACKED_BYTES = _PackedBytes()
STRS = _List(STR)

ALARM = _Record(Alarm, (("kind", STR), ("subject", STR), ("severity", STR), ("message", STR),
                        ("t_gpst", F64), ("cleared", BOOL)))
BASELINE_EPOCH = _Record(BaselineEpoch, (
    ("t_gpst", F64), ("refs", _Dict(STR, STR)), ("sats", ARRAY), ("elevation_a_deg", ARRAY),
    ("elevation_b_deg", ARRAY), ("fixed", ARRAY), ("dd_n", ARRAY), ("dd_iono_m", ARRAY), ("dd_trop_m", ARRAY),
    ("freq_hz", ARRAY), ("slips", STRS), ("zwd_m", _Tuple(F64, 2)), ("ratio", F64),
    ("eligible", _Optional(ARRAY)), ("iono_float_m", _Optional(ARRAY)), ("iono_float_var_m2", _Optional(ARRAY))))
NETWORK_EPOCH = _Record(NetworkEpoch, (
    ("t_gpst", F64), ("master", STR), ("stations", STRS), ("station_en_m", ARRAY), ("station_xyz_m", ARRAY),
    ("refs", _Dict(STR, STR)), ("sats", ARRAY), ("dd_iono_m", ARRAY), ("dd_trop_m", ARRAY),
    ("baselines", _Dict(STR, _Optional(BASELINE_EPOCH))), ("misclosures", I64), ("present", STRS),
    ("clocks", _Dict(STR, F64)), ("excluded", _List(STR, set)), ("alarms", _List(ALARM))),
    # the stations' antenna corrections, the chained DD integers and the stations left out of VRS synthesis serve
    # the centre's own synthesis (the service hears of an exclusion by its station-coordinates alarm, in the outbox)
    left_behind={"antenna_m": {}, "dd_n": None, "vrs_excluded": set()})
# `vrs` (every session's synthesised observations) stays in the centre; `vrs_models` is what the console
# shows of it
EPOCH_REPORT = _Record(EpochReport, (
    ("t_gpst", F64), ("network", NETWORK_EPOCH), ("sessions", I64), ("stations", STRS),
    ("arrival", _Optional(_Tuple(F64, 2))), ("vrs_models", _Dict(STR, I64))), left_behind={"vrs": None})

# type code -> message and its layout: the one table the encoder, the decoder and the tests walk
LAYOUTS: dict[int, _Record] = {
    1: _Record(StationData, (("station", STR), ("data", BYTES), ("arrival_unix_s", F64))),
    2: _Record(OpenSession, (("client_id", STR), ("lat_deg", F64), ("lon_deg", F64), ("h_m", F64))),
    3: _Record(MoveSession, (("client_id", STR), ("lat_deg", F64), ("lon_deg", F64), ("h_m", F64))),
    4: _Record(CloseSession, (("client_id", STR),)),
    5: _Record(VrsWritten, (("t_gpst", F64),)),
    6: _Record(Stop, ()),
    7: _Record(StationMembership, (("station", STR), ("xyz_m", _Optional(_Tuple(F64, 3))))),
    8: _Record(SessionBound, (("client_id", STR), ("send", BOOL))),
    16: _Record(Ready, (("pid", I64),)),
    17: _Record(VrsGroup, (("t_gpst", F64), ("client_ids", SEPARATED_STRS), ("rtcm", PACKED_BYTES),
                           ("ready_unix_s", F64), ("arrival", _Optional(_Tuple(F64, 2))),
                           ("cost", _Optional(_Tuple(F64, 4))), ("last", BOOL))),
    18: _Record(EpochsSolved, (("reports", _List(EPOCH_REPORT)), ("outbox", _List(_Pair(STR, BYTES))),
                               ("solve_s", F64), ("sessions", I64))),
    19: _Record(CentreError, (("text", STR),)),
    20: _Record(Alive, ()),
}
_CODE = {rec.kind: code for code, rec in LAYOUTS.items()}


# --- the codec --------------------------------------------------------------------------------------------


def encode(msg: Message) -> bytes:
    """One frame holding `msg`. A value its field cannot carry raises ProtocolError (nothing is sent)."""
    code = _CODE.get(type(msg))
    if code is None:
        raise ProtocolError(f"not a centre-protocol message: {type(msg).__name__}")
    parts: list = [b""]  # the header's place: the body is joined once, behind it
    name = None
    try:
        for name, codec in LAYOUTS[code].layout:
            codec.put(parts, getattr(msg, name))
        name = None
        size = sum(map(len, parts))
        if size > MAX_BODY_BYTES:
            raise ProtocolError(f"{type(msg).__name__} body of {size} bytes over the {MAX_BODY_BYTES}-byte limit")
        parts[0] = _HEADER.pack(MAGIC, PROTOCOL_VERSION, code, size)
        return b"".join(parts)
    except (struct.error, TypeError, ValueError, AttributeError, OverflowError, UnicodeError) as exc:
        where = type(msg).__name__ + (f".{name}" if name else "")
        raise ProtocolError(f"cannot encode {where}: {exc}") from None


def _decode_body(code: int, body: memoryview) -> Message:
    rec = LAYOUTS[code]
    r = _Reader(body)
    try:
        msg = rec.get(r)
    except ProtocolError as exc:
        raise ProtocolError(f"{rec.kind.__name__}: {exc}") from None
    except (ValueError, TypeError, UnicodeDecodeError, struct.error, OverflowError, MemoryError) as exc:
        raise ProtocolError(f"{rec.kind.__name__}: malformed body: {exc}") from None
    if r.pos != len(body):
        raise ProtocolError(f"{rec.kind.__name__}: malformed body: {len(body) - r.pos} bytes left over "
                            f"after its fields")
    return msg


class Decoder:
    """Frames in, messages out; partial frames are kept until the rest arrives.

    `expect`: the message classes this end accepts (FROM_LOOP in the centre, FROM_CENTRE in the loop).
    Bytes are gathered in one buffer that is reused, not reallocated (a VRS group is ~0.5 MB, and fresh
    memory for each costs a page fault per 4 kB); a reader may receive straight into it (`get_buffer`,
    then `buffer_updated`: asyncio's BufferedProtocol, `socket.recv_into`) or hand over bytes it read
    (`receive_data`)."""

    __slots__ = ("_buf", "_start", "_end", "_codes", "max_body_bytes", "failed")

    def __init__(self, expect: Iterable[type] = FROM_LOOP + FROM_CENTRE, max_body_bytes: int = MAX_BODY_BYTES):
        self._buf = bytearray(RECEIVE_BUFFER_BYTES)
        self._start = 0  # the unread bytes are _buf[_start:_end]
        self._end = 0
        self._codes = frozenset(_CODE[k] for k in expect)
        self.max_body_bytes = max_body_bytes
        self.failed: ProtocolError | None = None

    def receive_data(self, data: bytes) -> list[Message]:
        """Feed bytes from the peer; returns the messages they complete. Raises ProtocolError on bad input
        (and on every call after it)."""
        self._check_failed()
        n = len(data)
        self._make_room(n)
        self._buf[self._end:self._end + n] = data  # same length: a copy into the buffer, no resize
        self._end += n
        return self._messages()

    def get_buffer(self, size_hint: int = -1) -> memoryview:
        """Room for one read at the buffer's free end: `size_hint` bytes, `MIN_READ_BYTES` when it asks
        for less (a read as large as asyncio's own). Release it before the next call."""
        n = max(size_hint, MIN_READ_BYTES)
        self._make_room(n)
        with memoryview(self._buf) as whole:
            return whole[self._end:self._end + n]

    def buffer_updated(self, nbytes: int) -> list[Message]:
        """`nbytes` were read into the buffer from `get_buffer`: the messages they complete (as
        `receive_data`)."""
        self._check_failed()
        self._end += nbytes
        return self._messages()

    def _check_failed(self) -> None:
        if self.failed is not None:
            raise ProtocolError(f"stream already failed: {self.failed}")

    def _make_room(self, n: int) -> None:
        if self._end + n <= len(self._buf):
            return
        unread = self._end - self._start  # move the unread bytes to the front, then grow if need be
        if self._start:
            self._buf[:unread] = self._buf[self._start:self._end]
            self._start, self._end = 0, unread
        if unread + n > len(self._buf):
            self._buf.extend(bytes(unread + n - len(self._buf)))

    def _messages(self) -> list[Message]:
        out: list = []
        pos, end = self._start, self._end
        try:
            with memoryview(self._buf) as view:
                while end - pos >= HEADER_BYTES:
                    code, size = self._check_header(view, pos)
                    start = pos + HEADER_BYTES
                    if end - start < size:
                        break
                    with view[start:start + size] as body:
                        out.append(_decode_body(code, body))
                    pos = start + size
        except ProtocolError as exc:
            self.failed = exc
            self._buf = bytearray()
            self._start = self._end = 0
            raise ProtocolError(str(exc), out) from None
        self._start = pos
        if pos == end:
            self._start = self._end = 0
            if len(self._buf) > KEEP_BUFFER_BYTES:  # after an exceptional frame: back to the usual size
                self._buf = bytearray(RECEIVE_BUFFER_BYTES)
        return out

    def _check_header(self, view: memoryview, pos: int) -> tuple[int, int]:
        magic, version, code, size = _HEADER.unpack_from(view, pos)
        if magic != MAGIC:
            raise ProtocolError(f"bad magic {magic!r} (expected {MAGIC!r}): not a frame boundary")
        if version != PROTOCOL_VERSION:
            raise ProtocolError(f"unsupported protocol version {version} (this end speaks {PROTOCOL_VERSION})")
        if code not in self._codes:
            what = LAYOUTS[code].kind.__name__ if code in LAYOUTS else "unknown"
            raise ProtocolError(f"message type {code} ({what}) not expected from the other side")
        if size > self.max_body_bytes:
            raise ProtocolError(f"frame body of {size} bytes over the {self.max_body_bytes}-byte limit")
        return code, size


__all__ = [
    "MAGIC", "PROTOCOL_VERSION", "MAX_BODY_BYTES", "HEADER_BYTES", "LAYOUTS", "ProtocolError", "encode", "Decoder",
    "StationData", "OpenSession", "MoveSession", "CloseSession", "SessionBound", "VrsWritten", "Stop", "Ready", "VrsGroup",
    "EpochsSolved", "CentreError", "Alive", "LoopMessage", "CentreMessage", "Message", "FROM_LOOP", "FROM_CENTRE",
]
