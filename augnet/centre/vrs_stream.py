"""RTCM 3 streams of virtual reference stations: one per client (train), encoded for all of them at once.

Per epoch and client, in this order (what RTKLIB and commercial rovers expect of a VRS, network-rtk.md):
  * 1006 (antenna reference point of the VRS, height 0) when the point is new or moved, and every
    `STATION_INTERVAL_S`; 1033 (descriptors) every `STATION_INTERVAL_S`;
  * broadcast ephemerides (1019 / 1046 / 1042) of the satellites in the VRS every `EPHEMERIS_INTERVAL_S`
    and whenever a satellite's set changes;
  * MSM7 (or MSM4) per system, the multiple-message bit set on all but the epoch's last;
  * only when the stream is built with `send_correction_bound=True` (default off: opt-in, see
    docs/correction-bound-message.md) and the epoch comes with a bound: the proprietary 4001 with the
    centre's overbound sigma of the correction error per satellite sent (`augnet.centre.correction_bound`),
    after the MSM; clients that do not know 4001 skip it like any unknown message type.

The MSM of one system is encoded for every client in one batch (`encode_msm_batch`). Lock times and
whole-cycle phase offsets (MSM holds the phase within +-1171 m of the code) are kept per client, satellite
and signal; a change of master station changes the VRS ambiguities, so it restarts every lock, and a
satellite switching between network-corrected and uncorrected data restarts its own. The 1006 flags the
station as non-physical (DF141 = 1, RTCM 10403.3: a computed reference station).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from augnet.centre.vrs import VrsEpoch
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.rtcm import encode_frame
from augnet.gnss.rtcm.batch import encode_msm_batch
from augnet.gnss.rtcm.correction_bound import MAX_SATELLITES, CorrectionBoundMessage, encode_correction_bound_frame
from augnet.gnss.rtcm.ephemeris import ephemeris_message
from augnet.gnss.rtcm.layouts import MSM_MAX_CELLS
from augnet.gnss.rtcm.observables import phase_offset_cycles
from augnet.gnss.rtcm.station import arp_message, descriptor_message, msm_epoch_ms
from augnet.gnss.signals import by_rinex

STATION_INTERVAL_S = 10.0
EPHEMERIS_INTERVAL_S = 60.0
SYSTEM_ORDER = ("G", "E", "C")
VRS_ANTENNA = "ADVNULLANTENNA"  # a VRS has no antenna: RTKLIB and IGS use this name for "no calibration"
VRS_RECEIVER = "AUGNET VRS"
FIRMWARE = "1"


def _capacity(have: int, need: int, least: int) -> int:
    """An array axis's new length: unchanged while it holds `need`, else doubled (amortised growth).
    Each axis grows on its own: doubling the other one too multiplies the cells, and the copy at each
    doubling stalls the centre (docs/decisions/0014-vrs-stream-arrays-grow-per-axis.md)."""
    return have if need <= have else max(need, 2 * have, least)


@dataclass
class Client:
    """What the stream remembers about one client."""

    station_id: int
    point: np.ndarray
    row: int  # this client's row in the lock-state arrays
    master: str = ""
    last_arp: float = -np.inf
    last_eph: float = -np.inf
    moved: bool = True
    send_bound: bool | None = None  # 4001 for this client: None = the encoder's `send_correction_bound`
    station_frames: bytes = b""  # framed 1006 + 1033, encoded when the point is set (resent from here)
    descriptor_frame: bytes = b""  # framed 1033 (the station id's: encoded once)


@dataclass
class _EpochContext:
    sats: np.ndarray
    codes: np.ndarray
    nav: NavigationData
    t: float
    eph_rows: np.ndarray = None
    gsat: np.ndarray = None
    sendable: np.ndarray = None
    systems: list = field(default_factory=list)
    msm: dict = field(default_factory=dict)  # system -> (columns, PRNs, codes, MSM signal ids, cells)


class VrsStreamEncoder:
    def __init__(self, msm_level: int = 7, send_correction_bound: bool = False):
        self.level = msm_level
        self.send_correction_bound = send_correction_bound  # 4001 after the MSM: opt-in, default off
        self.clients: dict[str, Client] = {}
        self._eph_frames: dict[int, bytes] = {}  # ephemeris row -> its framed message (encoded once)
        self._sat_ids: dict[str, int] = {}
        self._eph_sent = np.full((0, 0), -1, dtype=np.int64)  # (client row, satellite) -> ephemeris row sent
        self._free_rows: list[int] = []
        # lock state, dense over (client row, satellite-signal key): start time (NaN = not locked) and the
        # whole-cycle phase offset taken at lock start
        self._keys: dict[tuple[str, str], int] = {}
        self._lock_t0 = np.full((0, 0), np.nan)
        self._offset = np.zeros((0, 0))
        # whether the signal was network-corrected at the last epoch (NaN: not sent): a change of
        # correction source (network <-> the master's plain shift) steps the VRS phase by the residual
        # atmosphere, cm, without a slip at the master, so the lock restarts and the rover knows
        self._corrected = np.full((0, 0), np.nan)
        self._ctx: _EpochContext | None = None

    def _grow(self, rows: int, keys: int) -> None:
        r0, k0 = self._lock_t0.shape
        if rows <= r0 and keys <= k0:
            return
        r1, k1 = _capacity(r0, rows, 16), _capacity(k0, keys, 64)
        t0 = np.full((r1, k1), np.nan)
        off = np.zeros((r1, k1))
        corr = np.full((r1, k1), np.nan)
        t0[:r0, :k0] = self._lock_t0
        off[:r0, :k0] = self._offset
        corr[:r0, :k0] = self._corrected
        self._lock_t0, self._offset, self._corrected = t0, off, corr

    def add(self, client_id: str, station_id: int, point_ecef) -> None:
        row = self._free_rows.pop() if self._free_rows else len(self.clients)
        self._grow(row + 1, len(self._keys))
        self._lock_t0[row] = np.nan
        self._corrected[row] = np.nan
        self._grow_eph(row + 1, len(self._sat_ids))
        self._eph_sent[row] = -1
        c = self.clients[client_id] = Client(station_id, np.asarray(point_ecef, float), row)
        c.descriptor_frame = encode_frame(descriptor_message(station_id, f"VRS{station_id}", VRS_ANTENNA,
                                                             VRS_RECEIVER, FIRMWARE))
        self._station_frames(c)

    def sends_bound(self) -> bool:
        """Any client's streams carry the 4001 bound."""
        if self.send_correction_bound:
            return any(c.send_bound is not False for c in self.clients.values())
        return any(c.send_bound for c in self.clients.values())

    def set_send_bound(self, client_id: str, send: bool | None) -> None:
        """This client's streams carry the 4001 bound (True), do not (False), or follow the encoder (None):
        its mountpoint's opt-in (decision 0281)."""
        self.clients[client_id].send_bound = send

    def move(self, client_id: str, point_ecef) -> None:
        c = self.clients[client_id]
        c.point = np.asarray(point_ecef, float)
        c.moved = True
        self._station_frames(c)

    @staticmethod
    def _station_frames(c: Client) -> None:
        """The client's 1006 + 1033, encoded when its point is set (a hundred microseconds, between epochs
        when the centre runs on its own: off the correction age's path) and resent from here."""
        c.station_frames = encode_frame(arp_message(c.station_id, c.point, antenna_height_m=0.0,
                                                    non_physical=True)) + c.descriptor_frame

    def remove(self, client_id: str) -> None:
        c = self.clients.pop(client_id, None)
        if c is not None:
            self._free_rows.append(c.row)

    def _sat_index(self, sat: str) -> int:
        k = self._sat_ids.get(sat)
        if k is None:
            k = self._sat_ids[sat] = len(self._sat_ids)
        return k

    def _grow_eph(self, rows: int, sats: int) -> None:
        r0, k0 = self._eph_sent.shape
        if rows <= r0 and sats <= k0:
            return
        grown = np.full((_capacity(r0, rows, 16), _capacity(k0, sats, 64)), -1, dtype=np.int64)
        grown[:r0, :k0] = self._eph_sent
        self._eph_sent = grown

    def _eph_frame(self, row: int, nav: NavigationData) -> bytes:
        frame = self._eph_frames.get(row)
        if frame is None:
            try:
                frame = encode_frame(ephemeris_message(nav.table.records[row]))
            except (ValueError, KeyError):
                frame = b""
            self._eph_frames[row] = frame
        return frame

    def _key(self, sat: str, code: str) -> int:
        k = self._keys.get((sat, code))
        if k is None:
            k = self._keys[(sat, code)] = len(self._keys)
        return k

    def encode(self, ids: list[str], vrs: VrsEpoch, nav: NavigationData, bound_sigma_m: np.ndarray | None = None,
               ionosphere_level_ppm: float = float("nan")) -> dict[str, bytes]:
        """The epoch's RTCM bytes for each client in `ids` (rows of `vrs` in the same order). With
        `send_correction_bound` and `bound_sigma_m` (clients x `vrs.sats` overbound sigma [m], NaN = none), each
        client's bytes end with a 4001 for the satellites its MSM carry."""
        t = vrs.t_gpst
        ctx = self._context(vrs, nav)
        out = {cid: bytearray() for cid in ids}
        # station and ephemeris messages: per client, only when due (a few per client per minute)
        eph_rows = ctx.eph_rows
        if len(self._eph_frames) > 4096:  # a long run: forget frames of old sets
            self._eph_frames.clear()
        have_all = np.isfinite(vrs.code_m).any(axis=2)  # (T, S)
        gsat = ctx.gsat
        rows_c = np.array([self.clients[c].row for c in ids], dtype=int)
        self._grow_eph(rows_c.max(initial=0) + 1, len(self._sat_ids))
        sent = self._eph_sent[np.ix_(rows_c, gsat)]  # (T, S) ephemeris row each client last had
        last_eph = np.array([self.clients[c].last_eph for c in ids])
        periodic = (t - last_eph) >= EPHEMERIS_INTERVAL_S
        due = have_all & ctx.sendable[None, :] & (periodic[:, None] | (sent != eph_rows[None, :]))
        self._eph_sent[np.ix_(rows_c, gsat)] = np.where(due, eph_rows[None, :], sent)
        for i, cid in enumerate(ids):
            c = self.clients[cid]
            if c.master and c.master != vrs.master[i] and not (vrs.handed_over is not None and vrs.handed_over[i]):
                self._lock_t0[c.row] = np.nan  # new master, new ambiguities: every lock restarts
            c.master = vrs.master[i]
            if c.moved or t - c.last_arp >= STATION_INTERVAL_S:
                out[cid] += c.station_frames
                c.last_arp = t
                c.moved = False
            if periodic[i]:
                c.last_eph = t
        # clients due the same ephemerides (those of one master, at the periodic resend) share one blob
        blobs: dict[bytes, bytes] = {}
        for i in np.flatnonzero(due.any(axis=1)):
            key = np.packbits(due[i]).tobytes()
            blob = blobs.get(key)
            if blob is None:
                blob = blobs[key] = b"".join(self._eph_frame(int(eph_rows[k]), nav) for k in np.flatnonzero(due[i]))
            out[ids[i]] += blob
        # MSM per system, batched over clients
        batches = []
        for j, system in enumerate(ctx.systems):
            batches += self._msm(ctx.msm[system], system, ids, vrs, final=j == len(ctx.systems) - 1)
        # each batch holds one frame per client back to back: slice them out by offsets
        views = [(memoryview(b.data), b.offsets) for b in batches]
        for i, cid in enumerate(ids):
            buf = out[cid]
            for data, off in views:
                buf += data[off[i]:off[i + 1]]
        if bound_sigma_m is not None:
            on = [self.send_correction_bound if self.clients[c].send_bound is None else self.clients[c].send_bound
                  for c in ids]
            if any(on):
                self._bound_frames(ids, vrs, ctx, np.asarray(bound_sigma_m, float), ionosphere_level_ppm, out, on)
        return {cid: bytes(b) for cid, b in out.items()}

    def _bound_frames(self, ids, vrs: VrsEpoch, ctx: "_EpochContext", sigma: np.ndarray, level: float,
                      out: dict, on: list[bool]) -> None:
        """Append each client's 4001 (several when it carries more than MAX_SATELLITES satellites)."""
        if sigma.shape != (len(ids), len(vrs.sats)):
            raise ValueError(f"bound sigma of shape {sigma.shape}, expected {(len(ids), len(vrs.sats))}")
        sent = np.isfinite(vrs.code_m).any(axis=2) & np.isin(
            np.array([str(x)[0] for x in vrs.sats]), list(ctx.systems))[None, :]
        epoch = msm_epoch_ms("G", vrs.t_gpst)
        for i, cid in enumerate(ids):
            if not on[i]:
                continue
            cols = np.flatnonzero(sent[i])
            c = self.clients[cid]
            for a in range(0, len(cols), MAX_SATELLITES):
                part = cols[a:a + MAX_SATELLITES]
                out[cid] += encode_correction_bound_frame(CorrectionBoundMessage(
                    c.station_id, epoch, c.station_id, [str(s) for s in vrs.sats[part]], sigma[i, part], level))

    def _context(self, vrs: VrsEpoch, nav: NavigationData) -> "_EpochContext":
        """What the epoch's encoding needs that does not depend on the clients: worked out once for all the
        groups of clients an epoch is encoded in (`VrsEpoch.rows` of one epoch share `sats` and `codes`)."""
        ctx = self._ctx
        if ctx is not None and ctx.sats is vrs.sats and ctx.codes is vrs.codes and ctx.nav is nav \
                and ctx.t == vrs.t_gpst:
            return ctx
        ctx = _EpochContext(vrs.sats, vrs.codes, nav, vrs.t_gpst)
        ctx.eph_rows = nav.select(list(vrs.sats), vrs.t_gpst)
        ctx.gsat = np.array([self._sat_index(str(x)) for x in vrs.sats], dtype=int)
        ctx.sendable = (ctx.eph_rows >= 0) & np.isin(np.array([str(x)[0] for x in vrs.sats]), list("GEC"))
        ctx.systems = [s for s in SYSTEM_ORDER if any(str(x).startswith(s) for x in vrs.sats)]
        for system in ctx.systems:
            cols = np.flatnonzero(np.char.startswith(vrs.sats.astype(str), system))
            sats = vrs.sats[cols]
            codes = [c for c in dict.fromkeys(vrs.codes[cols].ravel().tolist()) if c]
            sig_ids = np.array([by_rinex(system, c).msm_id for c in codes])
            order = np.argsort(sig_ids)
            codes = [codes[i] for i in order]
            cells = []  # (slot, signal column, satellite rows, their columns in vrs, lock-state keys, wavelengths)
            for slot in range(2):
                code_of = vrs.codes[cols, slot]
                for j, c in enumerate(codes):
                    rows = np.flatnonzero(code_of == c)
                    if rows.size:
                        keys = np.array([self._key(str(sats[k]), c) for k in rows])
                        cells.append((slot, j, rows, cols[rows], keys,
                                      SPEED_OF_LIGHT_M_S / vrs.freq_hz[cols[rows], slot]))
            ctx.msm[system] = (cols, np.array([int(s[1:]) for s in sats]), codes, sig_ids[order], cells)
        self._ctx = ctx
        return ctx

    def _msm(self, plan, system: str, ids: list[str], vrs: VrsEpoch, final: bool):
        """This system's MSM for every client, as batches (one per group of satellites when the cells
        exceed one message); the multiple-message bit is clear only on the epoch's very last message."""
        cols, prn, codes, sig_ids, cells = plan
        T = len(ids)
        nsat, nsig = len(cols), len(codes)
        pr = np.full((T, nsat, nsig), np.nan)
        cp = np.full((T, nsat, nsig), np.nan)
        cnr = np.full((T, nsat, nsig), np.nan)
        lock_ms = np.zeros((T, nsat, nsig))
        t = vrs.t_gpst
        rows_c = np.array([self.clients[c].row for c in ids], dtype=int)
        self._grow(rows_c.max(initial=0) + 1, len(self._keys))
        for slot, j, rows, vcols, keys, lam in cells:
            pr[:, rows, j] = vrs.code_m[:, vcols, slot]
            cp[:, rows, j] = vrs.phase_cyc[:, vcols, slot]
            cnr[:, rows, j] = vrs.cnr_dbhz[:, vcols, slot]
            t0 = self._lock_t0[np.ix_(rows_c, keys)]
            off = self._offset[np.ix_(rows_c, keys)]
            have = np.isfinite(cp[:, rows, j])
            corr_now = vrs.corrected[:, vcols].astype(float)
            corr_before = self._corrected[np.ix_(rows_c, keys)]
            switched = np.isfinite(corr_before) & (corr_before != corr_now)
            self._corrected[np.ix_(rows_c, keys)] = np.where(have, corr_now, np.nan)
            restart = have & (np.isnan(t0) | ((vrs.lli[:, vcols, slot] & 1) != 0) | switched)
            new_off = phase_offset_cycles(pr[:, rows, j], cp[:, rows, j], lam[None, :])
            t0 = np.where(restart, t, np.where(have, t0, np.nan))
            off = np.where(restart, new_off, off)
            self._lock_t0[np.ix_(rows_c, keys)] = t0
            self._offset[np.ix_(rows_c, keys)] = off
            cp[:, rows, j] -= off
            lock_ms[:, rows, j] = np.where(have, (t - t0) * 1000.0, 0.0)
        station_ids = np.array([self.clients[c].station_id for c in ids])
        epoch = msm_epoch_ms(system, t)
        per_client = nsat * nsig
        if per_client > MSM_MAX_CELLS:  # more cells than one MSM holds: split the satellites
            groups = np.array_split(np.arange(nsat), int(np.ceil(per_client / MSM_MAX_CELLS)))
        else:
            groups = [np.arange(nsat)]
        parts = []
        for g_i, g in enumerate(groups):
            multiple = 0 if (final and g_i == len(groups) - 1) else 1
            parts.append(encode_msm_batch(system, self.level, prn[g], sig_ids, station_ids, epoch,
                                          pr[:, g], cp[:, g], None, cnr[:, g], lock_ms[:, g], multiple=multiple))
        return parts
