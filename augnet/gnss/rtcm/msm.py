"""MSM (Multiple Signal Messages, RTCM 10403.3 section 3.5.12) as numpy arrays over satellites and cells.

``MsmMessage`` holds the header and the raw (signed, unscaled) integer of every field: satellite
data as arrays over satellites, signal data as arrays over cells in transmission order (satellite
major, then signal, only where the cell mask is set). ``to_fields()`` gives pyrtcm's view (scaled
values, ``DF405_01`` ...), for comparison and display.

Decoding is the hot path of the centre (every station, every epoch), so ``decode_msm`` reads the
header with integer shifts and then all satellite and cell fields in one numpy gather: the bit
offsets of every field depend only on (type, Nsat, Nsig, Ncell), and are cached per mask set
(a station's masks repeat from epoch to epoch): one gather instead of a big-integer shift per field
(docs/decisions/0009-msm-decode-numpy-gather.md). ``encode_msm`` is a plain bit writer,
independent of ``batch.py``'s vectorised packer for many receivers (tests compare the two).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from augnet.gnss.rtcm.errors import DecodeError, EncodeError
from augnet.gnss.rtcm.fields import FIELDS, to_value
from augnet.gnss.rtcm.layouts import (
    MSM_EPOCH_FIELDS,
    MSM_HEADER_TAIL,
    MSM_MAX_CELLS,
    cell_fields,
    msm_kind,
    msm_type,
    sat_fields,
)
from augwire.rtcm_framing import message_type

# MSM header fields (Table 3.5-78) and the MsmMessage attribute each one fills. The epoch field
# is 30 bits for every system (one DF, or GLONASS's DF416 + DF034; see layouts.MSM_EPOCH_FIELDS).
MSM_EPOCH_BITS = 30
_HEADER_ATTRS = (("DF002", "msg_type"), ("DF003", "station_id"), ("epoch", "epoch"), ("DF393", "multiple"),
                 ("DF409", "iods"), ("DF001_7", "reserved"), ("DF411", "clock_steering"),
                 ("DF412", "external_clock"), ("DF417", "smoothing"), ("DF418", "smoothing_interval"),
                 ("DF394", "sat_mask"), ("DF395", "sig_mask"))
assert tuple(df for df, _ in _HEADER_ATTRS[3:]) == MSM_HEADER_TAIL[:-1]  # same order as the layout table


def _header_positions() -> tuple[dict[str, tuple[int, int]], int]:
    out, pos = {}, 0
    for df, attr in _HEADER_ATTRS:
        width = MSM_EPOCH_BITS if df == "epoch" else FIELDS[df].width
        out[attr] = (pos, width)
        pos += width
    return out, pos


# attribute -> (bit offset, width); the cell mask (DF396, Nsat x Nsig bits) follows at 169
HEADER_POSITIONS, HEADER_BITS_BEFORE_CELL_MASK = _header_positions()
_HEAD_READ_BYTES = (HEADER_BITS_BEFORE_CELL_MASK + MSM_MAX_CELLS + 7) // 8  # header with a 64-bit cell mask

# "No valid value" markers (RTCM 10403.3 DF397, DF399, DF400, DF401, DF404, DF405, DF406)
INVALID_ROUGH_MS = 255
INVALID = {
    "DF399": -8192,
    "DF400": -16384,
    "DF401": -2097152,
    "DF404": -16384,
    "DF405": -524288,
    "DF406": -8388608,
}


@dataclass(eq=False)
class MsmMessage:
    """One MSM: header values and raw field integers (satellite arrays and cell arrays)."""

    msg_type: int
    station_id: int
    epoch: int  # the 30-bit epoch field: TOW [ms]; GLONASS: (day of week << 27) | tk [ms]
    sat_ids: np.ndarray  # (nsat,) 1..64, ascending (satellite mask bit positions, MSB = 1)
    sig_ids: np.ndarray  # (nsig,) 1..32, ascending
    cell_mask: np.ndarray  # (nsat, nsig) bool
    rough_ms: np.ndarray  # (nsat,) DF397
    rough_mod: np.ndarray  # (nsat,) DF398 raw, units of 2^-10 ms
    fine_pr: np.ndarray  # (ncell,) DF400 / DF405 raw
    fine_ph: np.ndarray  # (ncell,) DF401 / DF406 raw
    lock: np.ndarray  # (ncell,) DF402 / DF407 indicator
    half_cycle: np.ndarray  # (ncell,) DF420
    cnr: np.ndarray  # (ncell,) DF403 / DF408 raw
    ext_info: np.ndarray | None = None  # (nsat,) MSM5/7 only
    rough_rate: np.ndarray | None = None  # (nsat,) DF399, MSM5/7 only
    fine_rate: np.ndarray | None = None  # (ncell,) DF404, MSM5/7 only
    multiple: int = 0  # DF393
    iods: int = 0  # DF409
    reserved: int = 0  # DF001_7
    clock_steering: int = 0  # DF411
    external_clock: int = 0  # DF412
    smoothing: int = 0  # DF417
    smoothing_interval: int = 0  # DF418
    _kind: tuple[str, int] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        kind = msm_kind(self.msg_type)
        if kind is None:
            raise EncodeError(f"{self.msg_type} is not a supported MSM type")
        self._kind = kind

    @property
    def system(self) -> str:
        return self._kind[0]

    @property
    def level(self) -> int:
        return self._kind[1]

    @property
    def nsat(self) -> int:
        return len(self.sat_ids)

    @property
    def nsig(self) -> int:
        return len(self.sig_ids)

    @property
    def ncell(self) -> int:
        return int(np.count_nonzero(self.cell_mask))

    @property
    def sat_mask(self) -> int:
        return sum(1 << (64 - int(s)) for s in self.sat_ids)

    @property
    def sig_mask(self) -> int:
        return sum(1 << (32 - int(s)) for s in self.sig_ids)

    @property
    def cell_mask_bits(self) -> int:
        bits = 0
        for b in np.asarray(self.cell_mask, dtype=bool).ravel().tolist():
            bits = (bits << 1) | b
        return bits

    @property
    def cell_sat_index(self) -> np.ndarray:
        """Index into ``sat_ids`` of each cell."""
        return np.nonzero(self.cell_mask)[0]

    @property
    def cell_sig_index(self) -> np.ndarray:
        """Index into ``sig_ids`` of each cell."""
        return np.nonzero(self.cell_mask)[1]

    def epoch_fields(self) -> dict[str, int]:
        names = MSM_EPOCH_FIELDS[self.system]
        if len(names) == 1:
            return {names[0]: self.epoch}
        return {names[0]: self.epoch >> 27, names[1]: self.epoch & ((1 << 27) - 1)}

    def to_fields(self) -> dict[str, object]:
        """pyrtcm's attributes: scaled values, repeated fields suffixed _01, _02 ..."""
        out: dict[str, object] = {"DF002": self.msg_type, "DF003": self.station_id}
        out.update(self.epoch_fields())
        out.update(
            DF393=self.multiple, DF409=self.iods, DF001_7=self.reserved, DF411=self.clock_steering,
            DF412=self.external_clock, DF417=self.smoothing, DF418=self.smoothing_interval,
            DF394=self.sat_mask, DF395=self.sig_mask, DF396=self.cell_mask_bits,
        )
        for role, df in sat_fields(self.system, self.level):
            _scaled(out, df, getattr(self, role))
        for role, df in cell_fields(self.level):
            _scaled(out, df, getattr(self, role))
        return out


def _scaled(out: dict, df: str, raw: np.ndarray) -> None:
    f = FIELDS[df]
    for i, r in enumerate(np.asarray(raw).tolist()):
        out[f"{df}_{i + 1:02d}"] = to_value(f, r)


# ----------------------------------------------------------------------------------------------
# Decoding


@dataclass(frozen=True)
class _Layout:
    """Everything about an MSM's body that depends only on its masks (cached)."""

    sat_ids: np.ndarray
    sig_ids: np.ndarray
    cell_mask: np.ndarray
    nbytes_needed: int
    byte_index: np.ndarray  # (nfields, 4) bytes holding each field (reads a 32-bit window)
    lshift: np.ndarray  # (nfields,) uint32: drop the bits before the field
    rshift: np.ndarray  # (nfields,) uint32: 32 - width
    sign_bit: np.ndarray  # (nfields,) int64: 1 << (width-1) for two's complement fields, else 0
    slices: tuple[tuple[str, int, int], ...]  # (role, start, stop) into the flat field array


_LAYOUT_CACHE: dict[tuple[int, int, int, int], _Layout] = {}
_LAYOUT_CACHE_MAX = 4096  # distinct mask sets kept; a network has a few per station at a time


def _mask_ids(mask: int, nbits: int) -> np.ndarray:
    return np.array([i + 1 for i in range(nbits) if (mask >> (nbits - 1 - i)) & 1], dtype=np.int64)


def _build_layout(msg_type: int, sat_mask: int, sig_mask: int, cell_bits: int) -> _Layout:
    system, level = msm_kind(msg_type)  # type: ignore[misc]
    sat_ids = _mask_ids(sat_mask, 64)
    sig_ids = _mask_ids(sig_mask, 32)
    nsat, nsig = len(sat_ids), len(sig_ids)
    ncellbits = nsat * nsig
    cell_mask = np.array(
        [(cell_bits >> (ncellbits - 1 - i)) & 1 for i in range(ncellbits)], dtype=bool
    ).reshape(nsat, nsig)
    ncell = int(cell_mask.sum())
    starts: list[int] = []
    widths: list[int] = []
    signed: list[bool] = []
    slices: list[tuple[str, int, int]] = []
    pos = HEADER_BITS_BEFORE_CELL_MASK + ncellbits
    for group, count in ((sat_fields(system, level), nsat), (cell_fields(level), ncell)):
        for role, df in group:
            f = FIELDS[df]
            first = len(starts)
            for _ in range(count):
                starts.append(pos)
                widths.append(f.width)
                signed.append(f.kind.value == "i")
                pos += f.width
            slices.append((role, first, len(starts)))
    for shared in (sat_ids, sig_ids, cell_mask):  # handed to every message decoded with this layout
        shared.setflags(write=False)
    st = np.array(starts, dtype=np.int64)
    w = np.array(widths, dtype=np.int64)
    return _Layout(
        sat_ids=sat_ids,
        sig_ids=sig_ids,
        cell_mask=cell_mask,
        nbytes_needed=(pos + 7) // 8,
        byte_index=(st // 8)[:, None] + np.arange(4),
        lshift=(st % 8).astype(np.uint32),
        rshift=(32 - w).astype(np.uint32),
        sign_bit=np.where(np.array(signed, dtype=bool), 1 << (w - 1), 0).astype(np.int64),
        slices=tuple(slices),
    )


# header values passed to MsmMessage as they are (the masks become ids and the cell mask instead)
_HEADER_SCALARS = tuple((a, p) for a, p in HEADER_POSITIONS.items() if a not in ("sat_mask", "sig_mask"))


def decode_msm(payload: bytes) -> MsmMessage:
    """Decode an MSM payload into arrays. Raises ``DecodeError`` when the payload is too short."""
    n = len(payload)
    mt = message_type(payload)
    kind = msm_kind(mt)
    if kind is None:
        raise DecodeError(f"message {mt} is not a supported MSM")
    if n * 8 < HEADER_BITS_BEFORE_CELL_MASK:
        raise DecodeError(f"MSM {mt}: payload of {n} bytes is shorter than the MSM header")
    head = payload[:_HEAD_READ_BYTES]
    h = int.from_bytes(head, "big") << (8 * (_HEAD_READ_BYTES - len(head)))
    top = 8 * _HEAD_READ_BYTES

    def bits(pos: int, width: int) -> int:
        return (h >> (top - pos - width)) & ((1 << width) - 1)

    sat_mask = bits(*HEADER_POSITIONS["sat_mask"])
    sig_mask = bits(*HEADER_POSITIONS["sig_mask"])
    ncellbits = sat_mask.bit_count() * sig_mask.bit_count()
    if ncellbits > MSM_MAX_CELLS:
        raise DecodeError(f"MSM {mt}: {ncellbits} cells exceed the standard's limit of {MSM_MAX_CELLS}")
    cell_bits = bits(HEADER_BITS_BEFORE_CELL_MASK, ncellbits)
    key = (mt, sat_mask, sig_mask, cell_bits)
    layout = _LAYOUT_CACHE.get(key)
    if layout is None:
        if len(_LAYOUT_CACHE) >= _LAYOUT_CACHE_MAX:
            _LAYOUT_CACHE.clear()
        layout = _LAYOUT_CACHE[key] = _build_layout(mt, sat_mask, sig_mask, cell_bits)
    if n < layout.nbytes_needed:
        raise DecodeError(f"MSM {mt}: payload of {n} bytes, its masks need {layout.nbytes_needed}")

    buf = np.frombuffer(payload + b"\0\0\0", dtype=np.uint8)
    win = buf[layout.byte_index].view(">u4")[:, 0].astype(np.uint32)
    raw = ((win << layout.lshift) >> layout.rshift).astype(np.int64)
    sb = layout.sign_bit
    vals = raw - ((raw & sb) << 1)  # two's complement: subtract 2^width when the sign bit is set
    roles = {role: vals[a:b] for role, a, b in layout.slices}
    head_values = {attr: bits(pos, width) for attr, (pos, width) in _HEADER_SCALARS}
    return MsmMessage(sat_ids=layout.sat_ids, sig_ids=layout.sig_ids, cell_mask=layout.cell_mask,
                      **head_values, **roles)


# ----------------------------------------------------------------------------------------------
# Encoding (one message; plain bit writer)


def check_msm(msg: MsmMessage) -> tuple[np.ndarray, np.ndarray]:
    """Raise ``EncodeError`` unless the message's arrays are consistent and every value fits.

    Returns the body's field values in transmission order and their widths (see ``_body_values``).
    """
    sat = np.asarray(msg.sat_ids)
    sig = np.asarray(msg.sig_ids)
    if sat.ndim != 1 or sig.ndim != 1:
        raise EncodeError("satellite and signal ids must be 1-d arrays")
    # An empty MSM (no satellite or no signal) is legal: receivers send one for a system they track
    # nothing of, e.g. to close a multiple-message epoch.
    for ids, top, what in ((sat.tolist(), 64, "satellite"), (sig.tolist(), 32, "signal")):
        if ids and not (ids[0] >= 1 and ids[-1] <= top and all(a < b for a, b in zip(ids, ids[1:]))):
            raise EncodeError(f"{what} ids must be ascending, unique and in 1..{top}: {ids}")
    if len(sat) * len(sig) > MSM_MAX_CELLS:
        raise EncodeError(
            f"{len(sat)} satellites x {len(sig)} signals = {len(sat) * len(sig)} cells exceed the "
            f"MSM limit of {MSM_MAX_CELLS} (RTCM 10403.3 3.5.12.3); split with observables_to_msm_list"
        )
    if np.shape(msg.cell_mask) != (len(sat), len(sig)):
        raise EncodeError(f"cell mask shape {np.shape(msg.cell_mask)} != ({len(sat)}, {len(sig)})")
    ncell = msg.ncell
    header = (("DF003", msg.station_id), ("DF393", msg.multiple), ("DF409", msg.iods),
              ("DF001_7", msg.reserved), ("DF411", msg.clock_steering), ("DF412", msg.external_clock),
              ("DF417", msg.smoothing), ("DF418", msg.smoothing_interval))
    for df, v in header:
        f = FIELDS[df]
        if not f.raw_min <= v <= f.raw_max:
            raise EncodeError(f"{df} ({f.what}) = {v} outside [{f.raw_min}, {f.raw_max}]")
    if not 0 <= msg.epoch < (1 << 30):
        raise EncodeError(f"MSM epoch field {msg.epoch} does not fit 30 bits")
    return _body_values(msg, len(sat), ncell)  # raises on a missing, misshapen or out-of-range field


_SHIFTS_32 = np.arange(31, -1, -1, dtype=np.int64)  # MSM body fields are at most 24 bits wide


def _body_values(msg: MsmMessage, nsat: int, ncell: int) -> tuple[np.ndarray, np.ndarray]:
    """All satellite then cell field values in transmission order, and each one's width."""
    arrays, widths, los, his, counts, names = [], [], [], [], [], []
    for group, count in ((sat_fields(msg.system, msg.level), nsat), (cell_fields(msg.level), ncell)):
        for role, df in group:
            f = FIELDS[df]
            arr = getattr(msg, role)
            if arr is None:
                if role != "ext_info":
                    raise EncodeError(f"MSM{msg.level} needs {role} ({df})")
                arr = np.zeros(count, dtype=np.int64)  # reserved: zeros
            arr = np.asarray(arr)
            if arr.shape != (count,):
                raise EncodeError(f"{role} ({df}) has shape {arr.shape}, expected ({count},)")
            arrays.append(arr)
            widths.append(f.width)
            los.append(f.raw_min)
            his.append(f.raw_max)
            counts.append(count)
            names.append((role, f))
    values = np.concatenate(arrays).astype(np.int64)
    bad = (values < np.repeat(los, counts)) | (values > np.repeat(his, counts))
    if bad.any():
        k = int(np.searchsorted(np.cumsum(counts), int(np.argmax(bad)), side="right"))
        role, f = names[k]
        raise EncodeError(f"{role} ({f.name}, {f.what}) outside [{f.raw_min}, {f.raw_max}]")
    return values, np.repeat(widths, counts)


def encode_msm(msg: MsmMessage) -> bytes:
    """The payload of one MSM (raises ``EncodeError`` on inconsistent or out-of-range values).

    A straightforward bit writer, independent of the batch packer (which tests compare it with):
    the header as one Python integer, then every field value spread to 32 bits of which the low
    ``width`` are kept, in transmission order.
    """
    values, widths = check_msm(msg)
    nsat, nsig = msg.nsat, msg.nsig
    acc = 0
    for attr, (_, width) in HEADER_POSITIONS.items():
        acc = (acc << width) | getattr(msg, attr)
    acc = (acc << (nsat * nsig)) | msg.cell_mask_bits
    nhead = HEADER_BITS_BEFORE_CELL_MASK + nsat * nsig
    head = np.unpackbits(np.frombuffer(acc.to_bytes((nhead + 7) // 8, "big"), dtype=np.uint8))
    spread = (values[:, None] >> _SHIFTS_32) & 1  # arithmetic shift: two's complement bits of negatives
    keep = _SHIFTS_32 < widths[:, None]
    bits = np.concatenate([head[len(head) - nhead :], spread[keep].astype(np.uint8)])
    return np.packbits(bits).tobytes()


def msm_from_fields(fields: dict[str, object]) -> MsmMessage:
    """The inverse of ``MsmMessage.to_fields``: pyrtcm-style values (scaled, ``DF405_01`` ...) -> message.

    Derived pyrtcm attributes (PRN_xx, CELLPRN_xx, NSat ...) are ignored if present.
    """
    from augnet.gnss.rtcm.fields import from_value

    try:
        mt = int(fields["DF002"])  # type: ignore[arg-type]
        kind = msm_kind(mt)
        if kind is None:
            raise EncodeError(f"{mt} is not a supported MSM type")
        system, level = kind
        names = MSM_EPOCH_FIELDS[system]
        epoch = int(fields[names[0]]) if len(names) == 1 else (int(fields[names[0]]) << 27) | int(fields[names[1]])
        sat_ids = _mask_ids(int(fields["DF394"]), 64)
        sig_ids = _mask_ids(int(fields["DF395"]), 32)
        nsat, nsig = len(sat_ids), len(sig_ids)
        cell_bits = int(fields["DF396"])
        cell_mask = np.array([(cell_bits >> (nsat * nsig - 1 - i)) & 1 for i in range(nsat * nsig)],
                             dtype=bool).reshape(nsat, nsig)
        ncell = int(cell_mask.sum())
        roles = {}
        for group, count in ((sat_fields(system, level), nsat), (cell_fields(level), ncell)):
            for role, df in group:
                f = FIELDS[df]
                roles[role] = np.array([from_value(f, fields[f"{df}_{i + 1:02d}"]) for i in range(count)],
                                       dtype=np.int64)
        return MsmMessage(
            msg_type=mt, station_id=int(fields["DF003"]), epoch=epoch, sat_ids=sat_ids, sig_ids=sig_ids,
            cell_mask=cell_mask, multiple=int(fields.get("DF393", 0)), iods=int(fields.get("DF409", 0)),
            reserved=int(fields.get("DF001_7", 0)), clock_steering=int(fields.get("DF411", 0)),
            external_clock=int(fields.get("DF412", 0)), smoothing=int(fields.get("DF417", 0)),
            smoothing_interval=int(fields.get("DF418", 0)), **roles,
        )
    except KeyError as err:
        raise EncodeError(f"MSM field {err} missing") from None


def make_msm(system: str, level: int, **kwargs) -> MsmMessage:
    """An ``MsmMessage`` for a system letter and level, e.g. ``make_msm("G", 7, station_id=..., ...)``."""
    return MsmMessage(msg_type=msm_type(system, level), **kwargs)
