"""Batch MSM encoder: the same MSM type for many receivers at once (the VRS of every train, one epoch).

Input arrays carry a leading receiver axis: observables (nrx, nsat, nsig), station ids and epochs
(nrx,). Output: one framed RTCM message per receiver, byte-identical to what ``observables_to_msm``
+ ``encode_msm`` + ``frame`` give for that receiver alone.

How, without a Python loop per receiver:
  1. field integers for every receiver come from the same vectorised ``observables_to_fields``;
  2. receivers whose cell masks are identical share one bit layout (usually all of them, since
     trains on one line see the same satellites); we loop over the distinct layouts only;
  3. per layout, each field (<= 32 bits) lands in one or two 64-bit big-endian words: a gather,
     two shifts and a segmented sum (``np.add.reduceat``; the bits never overlap, so sum == or)
     pack all receivers' payloads at once;
  4. CRC-24Q is linear over GF(2) (initial value 0, no final XOR), so a frame's CRC is the XOR of
     per-position contributions ``T[position][byte]``; one gather and one XOR-reduce frame them all.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from augnet.gnss.rtcm.errors import EncodeError
from augnet.gnss.rtcm.fields import FIELDS, Kind
from augnet.gnss.rtcm.layouts import LAYOUTS, MSM_MAX_CELLS, Repeat, cell_fields, msm_type, sat_fields
from augnet.gnss.rtcm.observables import cell_presence, observables_to_fields, wavelengths
from augwire.crc24q import crc24q_rows
from augwire.rtcm_framing import FRAME_OVERHEAD_BYTES, PREAMBLE

# Receivers encoded per block. Each step streams (fields x receivers) arrays; in blocks of a few
# hundred receivers a 12 x 2 MSM7's largest array (~260 x 512 x 8 B = 1 MB) stays in cache
# (docs/decisions/0008-rtcm-batch-block-size.md).
RECEIVERS_PER_BLOCK = 512


@dataclass(frozen=True)
class EncodedBatch:
    """All frames of a batch in one buffer: frame i is ``data[offsets[i]:offsets[i + 1]]``."""

    data: bytes
    offsets: np.ndarray  # (nrx + 1,)

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __getitem__(self, i: int) -> bytes:
        return self.data[self.offsets[i] : self.offsets[i + 1]]

    def frames(self) -> list[bytes]:
        return [self[i] for i in range(len(self))]


@dataclass(frozen=True)
class _Packing:
    nbytes: int  # payload bytes
    part_field: np.ndarray  # (nparts,) column feeding each part
    part_lshift: np.ndarray  # (nparts,) uint64
    part_rshift: np.ndarray  # (nparts,) uint64
    word_starts: np.ndarray  # (nwords,) first part of each 64-bit word


def _split(value_width: int) -> list[int]:
    """Widths of the <= 32-bit columns a wide field (64-bit masks) is cut into."""
    out = []
    while value_width > 32:
        out.append(32)
        value_width -= 32
    if value_width:
        out.append(value_width)
    return out


@lru_cache(maxsize=1024)
def _packing(widths: tuple[int, ...]) -> _Packing:
    starts = np.concatenate([[0], np.cumsum(widths)])
    total = int(starts[-1])
    nbytes = (total + 7) // 8
    pf, ls, rs, word = [], [], [], []
    for i, w in enumerate(widths):
        if w == 0:
            continue
        o, e = int(starts[i]), int(starts[i]) + w
        k = o // 64
        word_end = 64 * (k + 1)
        if e <= word_end:  # the whole field in word k
            pf.append(i); ls.append(word_end - e); rs.append(0); word.append(k)
        else:  # high bits end word k, low bits start word k + 1
            pf.append(i); ls.append(0); rs.append(e - word_end); word.append(k)
            pf.append(i); ls.append(64 * (k + 2) - e); rs.append(0); word.append(k + 1)
    word = np.array(word)
    nwords = (total + 63) // 64
    word_starts = np.searchsorted(word, np.arange(nwords))
    return _Packing(nbytes, np.array(pf), np.array(ls, dtype=np.uint64),
                    np.array(rs, dtype=np.uint64), word_starts)


def _pack_columns(values: np.ndarray, widths: tuple[int, ...]) -> np.ndarray:
    """(nfields, n) field bits (non-negative, < 2^width) -> (n, nbytes) big-endian packed payloads.

    Receivers run along the contiguous axis while packing, so every step is a whole-row numpy
    operation; the (few) 64-bit words are then transposed and byte-swapped in one copy.
    """
    p = _packing(widths)
    v = values.view(np.uint64)  # every value is already its field's bits (see encode_msm_batch)
    parts = v[p.part_field]
    parts <<= p.part_lshift[:, None]
    parts >>= p.part_rshift[:, None]
    words = np.add.reduceat(parts, p.word_starts, axis=0)  # (nwords, n) native uint64
    rows = words.T.astype(">u8", order="C")  # (n, nwords), most significant byte first
    return rows.view(np.uint8)[:, : p.nbytes]


def _frame_rows(payload: np.ndarray) -> np.ndarray:
    """(n, nbytes) payloads -> (n, nbytes + 6) frames: preamble, length, payload, CRC-24Q."""
    n, nbytes = payload.shape
    frames = np.empty((n, nbytes + FRAME_OVERHEAD_BYTES), dtype=np.uint8)
    frames[:, 0] = PREAMBLE
    frames[:, 1] = nbytes >> 8
    frames[:, 2] = nbytes & 0xFF
    frames[:, 3 : 3 + nbytes] = payload
    crc = crc24q_rows(frames[:, : 3 + nbytes])
    frames[:, -3] = crc >> 16
    frames[:, -2] = (crc >> 8) & 0xFF
    frames[:, -1] = crc & 0xFF
    return frames


def encode_fixed_batch(msg_type: int, fields: dict[str, object], nrx: int | None = None) -> EncodedBatch:
    """One framed fixed-layout message per receiver, e.g. the 1006 of every train's VRS.

    ``fields`` maps pyrtcm's names to a scalar (same for all) or an (nrx,) array of values, as
    ``RtcmMessage`` takes them; byte-identical to ``encode_frame(RtcmMessage(...))`` per receiver.
    Layouts with repeated groups (1033) are not batched: their length varies with the strings.
    """
    try:
        layout = LAYOUTS[msg_type]
    except KeyError:
        raise EncodeError(f"message type {msg_type} has no fixed layout") from None
    if any(isinstance(item, Repeat) for item in layout):
        raise EncodeError(f"message {msg_type} has variable-length groups; encode it per receiver")
    fields = {"DF002": msg_type, **fields}
    if nrx is None:
        nrx = max((np.size(v) for v in fields.values() if np.ndim(v) > 0), default=1)
    if nrx == 0:
        return EncodedBatch(b"", np.zeros(1, dtype=np.int64))
    cols: list[np.ndarray] = []
    widths: list[int] = []
    for name in layout:
        f = FIELDS[name]
        if name not in fields and not name.startswith("DF001"):
            raise EncodeError(f"message {msg_type}: field {name} ({f.what}) missing")
        v = np.broadcast_to(np.asarray(fields.get(name, 0)), (nrx,))
        if f.scale is None:
            if v.dtype.kind == "f" and not np.all(v == np.rint(v)):
                raise EncodeError(f"message {msg_type}: {name} expects integers")
            raw = v.astype(np.int64)
        else:
            raw = np.rint(v.astype(np.float64) / f.scale)
            if not np.all(np.isfinite(raw)):
                raise EncodeError(f"message {msg_type}: {name} is not finite")
            raw = raw.astype(np.int64)
        if raw.min() < f.raw_min or raw.max() > f.raw_max:
            raise EncodeError(f"message {msg_type}: {name} ({f.what}) outside [{f.raw_min}, {f.raw_max}] steps")
        if f.kind is Kind.SIGN_MAG:
            raw = np.where(raw < 0, (1 << (f.width - 1)) | -raw, raw)
        raw = raw & ((1 << f.width) - 1)  # two's complement bits as sent
        shift = f.width
        for w in _split(f.width):  # a 38-bit coordinate goes as 32 + 6 bits
            shift -= w
            cols.append((raw >> shift) & ((1 << w) - 1))
            widths.append(w)
    frames = _frame_rows(_pack_columns(np.stack(cols), tuple(widths)))
    offsets = np.arange(nrx + 1, dtype=np.int64) * frames.shape[1]
    return EncodedBatch(frames.tobytes(), offsets)


def encode_msm_batch(
    system: str,
    level: int,
    sat_ids,
    sig_ids,
    station_ids,
    epochs,
    pseudorange_m,
    phase_cycles,
    doppler_hz=None,
    cnr_dbhz=None,
    lock_ms=None,
    half_cycle=None,
    *,
    multiple: int = 0,
    iods: int = 0,
    clock_steering: int = 0,
    external_clock: int = 0,
    smoothing: int = 0,
    smoothing_interval: int = 0,
) -> EncodedBatch:
    """Framed MSM (level 4..7) for each receiver: observables (nrx, nsat, nsig), ids/epochs (nrx,).

    ``epochs`` is the MSM epoch field: time of week [ms] in the system's own time scale (BDT, i.e.
    GPST - 14 s, for BeiDou), or (day << 27) | tk for GLONASS.

    Satellites and signals without a cell are left out of each receiver's masks, exactly as in
    ``observables_to_msm``. Raises ``EncodeError`` when a receiver has more than 64 cells (split the
    satellites over several calls with ``multiple=1`` on all but the last).
    """
    mt = msm_type(system, level)
    sat_ids = np.asarray(sat_ids, dtype=np.int64)
    sig_ids = np.asarray(sig_ids, dtype=np.int64)
    pr = np.asarray(pseudorange_m, dtype=np.float64)
    if pr.ndim != 3 or pr.shape[1:] != (len(sat_ids), len(sig_ids)):
        raise EncodeError(f"observables must be (nrx, {len(sat_ids)}, {len(sig_ids)}), got {pr.shape}")
    nrx = pr.shape[0]
    if nrx == 0:
        return EncodedBatch(b"", np.zeros(1, dtype=np.int64))
    station_ids = np.broadcast_to(np.asarray(station_ids, dtype=np.int64), (nrx,))
    epochs = np.broadcast_to(np.asarray(epochs, dtype=np.int64), (nrx,))
    if nrx > RECEIVERS_PER_BLOCK:
        # Blocks keep each step's working set (a few hundred kB) in cache; see RECEIVERS_PER_BLOCK.
        header = dict(multiple=multiple, iods=iods, clock_steering=clock_steering, external_clock=external_clock,
                      smoothing=smoothing, smoothing_interval=smoothing_interval)
        per_rx = [pr, phase_cycles, doppler_hz, cnr_dbhz, lock_ms, half_cycle]
        per_rx = [None if a is None else np.broadcast_to(a, pr.shape) for a in per_rx]
        blocks = []
        for i in range(0, nrx, RECEIVERS_PER_BLOCK):
            sl = slice(i, i + RECEIVERS_PER_BLOCK)
            blocks.append(encode_msm_batch(system, level, sat_ids, sig_ids, station_ids[sl], epochs[sl],
                                           *[None if a is None else a[sl] for a in per_rx], **header))
        offsets = np.zeros(nrx + 1, dtype=np.int64)
        np.cumsum(np.concatenate([np.diff(b.offsets) for b in blocks]), out=offsets[1:])
        return EncodedBatch(b"".join(b.data for b in blocks), offsets)
    for name, arr, df in (("station id", station_ids, "DF003"), ("epoch", epochs, "DF004")):
        f = FIELDS[df]
        if nrx and (arr.min() < f.raw_min or arr.max() > f.raw_max):
            raise EncodeError(f"{name} outside [{f.raw_min}, {f.raw_max}]")
    header_const = []
    for df, v in (("DF393", multiple), ("DF409", iods), ("DF001_7", 0), ("DF411", clock_steering),
                  ("DF412", external_clock), ("DF417", smoothing), ("DF418", smoothing_interval)):
        f = FIELDS[df]
        if not f.raw_min <= v <= f.raw_max:
            raise EncodeError(f"{df} ({f.what}) = {v} outside [{f.raw_min}, {f.raw_max}]")
        header_const.append((v, f.width))

    fields = observables_to_fields(level, wavelengths(system, sig_ids), pr, phase_cycles, doppler_hz, cnr_dbhz,
                                   lock_ms, half_cycle)
    present = cell_presence(pr, np.asarray(phase_cycles, dtype=np.float64))
    flat = present.reshape(nrx, -1)
    keys = np.packbits(flat, axis=1) if flat.shape[1] else np.zeros((nrx, 1), dtype=np.uint8)
    if (keys == keys[0]).all():  # the usual case: one layout for every receiver
        uniq, group_of = keys[:1], np.zeros(nrx, dtype=np.int64)
    else:
        uniq, group_of = np.unique(keys, axis=0, return_inverse=True)
        group_of = np.asarray(group_of).reshape(-1)

    sat_roles = sat_fields(system, level)
    cell_roles = cell_fields(level)
    frame_len = np.empty(nrx, dtype=np.int64)
    packed: list[tuple[np.ndarray, np.ndarray]] = []
    for g in range(len(uniq)):
        rx = np.flatnonzero(group_of == g)
        mask_full = present[rx[0]]
        keep_sat = mask_full.any(axis=1)
        keep_sig = mask_full.any(axis=0)
        mask = mask_full[np.ix_(keep_sat, keep_sig)]
        nsat, nsig = mask.shape
        if nsat * nsig > MSM_MAX_CELLS:
            raise EncodeError(
                f"{nsat} satellites x {nsig} signals = {nsat * nsig} cells exceed the MSM limit of "
                f"{MSM_MAX_CELLS}; encode the satellites in groups with multiple=1 on all but the last"
            )
        n = len(rx)
        sat_mask = sum(1 << (64 - int(s)) for s in sat_ids[keep_sat])
        sig_mask = sum(1 << (32 - int(s)) for s in sig_ids[keep_sig])
        cell_bits = 0
        for b in mask.ravel().tolist():
            cell_bits = (cell_bits << 1) | b
        # Constant header columns: message number, DF393..DF418, satellite/signal/cell masks
        cols: list[np.ndarray] = []
        widths: list[int] = []

        def const(value: int, width: int) -> None:
            shift = width
            for w in _split(width):
                shift -= w
                cols.append(np.full((1, n), (value >> shift) & ((1 << w) - 1), dtype=np.int64))
                widths.append(w)

        const(mt, 12)
        cols.append(station_ids[None, rx]); widths.append(12)
        cols.append(epochs[None, rx]); widths.append(30)
        for v, w in header_const:
            const(v, w)
        const(sat_mask, 64)
        const(sig_mask, 32)
        const(cell_bits, nsat * nsig)
        all_rx = n == nrx  # one layout for the whole batch: no receiver selection needed
        sat_sel = np.flatnonzero(keep_sat)
        cell_sel = np.flatnonzero(mask_full.ravel())  # cell order: satellite major, then signal
        nhead = len(widths)
        values = np.empty((nhead + len(sat_roles) * nsat + len(cell_roles) * len(cell_sel), n), dtype=np.int64)
        values[:nhead] = np.concatenate(cols, axis=0)
        row = nhead
        # Field values -> their bits: two's complement fields are masked to their width (the
        # ranges were enforced by observables_to_fields), unsigned ones are copied.
        for roles, sel, count in ((sat_roles, sat_sel, nsat), (cell_roles, cell_sel, len(cell_sel))):
            for role, df in roles:
                f = FIELDS[df]
                dst = values[row : row + count]
                arr = fields.get(role)
                if arr is None:
                    dst[...] = 0
                else:
                    src = (arr if all_rx else arr[rx]).reshape(n, -1).T
                    if len(sel) != src.shape[0]:  # some satellites / cells absent: select rows
                        src = src[sel]
                    if f.kind.value == "i":
                        np.bitwise_and(src, (1 << f.width) - 1, out=dst)
                    else:
                        dst[...] = src
                widths.extend([f.width] * count)
                row += count
        frames = _frame_rows(_pack_columns(values, tuple(widths)))
        frame_len[rx] = frames.shape[1]
        packed.append((rx, frames))

    offsets = np.zeros(nrx + 1, dtype=np.int64)
    np.cumsum(frame_len, out=offsets[1:])
    if len(packed) == 1:  # common case: every receiver has the same layout, frames already in order
        return EncodedBatch(packed[0][1].tobytes(), offsets)
    out = np.empty(int(offsets[-1]), dtype=np.uint8)
    for rx, frames in packed:
        out[offsets[rx][:, None] + np.arange(frames.shape[1])] = frames
    return EncodedBatch(out.tobytes(), offsets)
