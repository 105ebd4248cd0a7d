"""Each simulated receiver's RTCM 3 stream: exactly the bytes it would send to a caster.

Per epoch, in this order:
  * 1005 (stations: antenna reference point) and 1033 (antenna and receiver descriptors) every
    `rtcm_station_interval_s`; trains send 1033 only (a moving antenna has no fixed ARP);
  * ephemerides (1019 GPS, 1046 Galileo I/NAV, 1042 BeiDou) of the tracked satellites when a
    satellite's broadcast set changes, and all of them every `rtcm_ephemeris_interval_s`;
  * MSM7 (1077, 1097, 1127) for every system, with the multiple-message bit set on all but the
    epoch's last message so decoders know when the epoch is complete.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from augnet.gnss.rtcm.batch import encode_msm_batch
from augnet.gnss.rtcm.codec import RtcmMessage, encode_frame
from augnet.gnss.rtcm.layouts import MSM_MAX_CELLS
from augnet.gnss.rtcm.observables import Observables, observables_to_msm_list
from augnet.gnss.signals import by_rinex
from augnet.gnss.rtcm import station as station_msgs
from augnet.gnss.rtcm.ephemeris import ephemeris_message
from stations.world import EpochBlock, World

MSM_LEVEL = 7
ANTENNA_DESCRIPTOR = "AUGNET-ISOTROPIC"
RECEIVER_DESCRIPTOR = "AUGNET SIMULATOR"
FIRMWARE = "1"
SYSTEM_ORDER = ("G", "E", "C")
# MSM carries the phase range within +-1171 m (2^-8 ms) of the rough range, itself within 146 m (2^-11 ms) of the
# pseudorange (RTCM 10403.3 DF397, DF405): a phase further than this from its own pseudorange (after an unflagged
# phase reset of kilometres, decision 0272) is re-aligned to it by whole cycles and its lock time restarts, as a
# receiver streaming MSM must (augnet.gnss.rtcm.observables.phase_offset_cycles); else it goes out as invalid.
MSM_PHASE_FIT_M = 1000.0


def arp_message(station_id: int, ecef_m) -> RtcmMessage:
    return station_msgs.arp_message(station_id, ecef_m)


def descriptor_message(station_id: int, serial: str) -> RtcmMessage:
    return station_msgs.descriptor_message(station_id, serial, ANTENNA_DESCRIPTOR, RECEIVER_DESCRIPTOR, FIRMWARE)


msm_epoch_ms = station_msgs.msm_epoch_ms


class RtcmStreams:
    """Builds every receiver's stream block by block; `write` puts them in <id>.rtcm3 files."""

    def __init__(self, world: World):
        self.world = world
        sc = world.scenario
        self.systems = [s for s in SYSTEM_ORDER if s in sc.constellations]
        self.buffers = {rx.id: bytearray() for rx in world.receivers}
        self.epoch_bytes: dict[str, list[tuple[float, bytes]]] = {rx.id: [] for rx in world.receivers}
        self.keep_epochs = False  # the live station runner sets this to stream epoch by epoch
        self._sent_set = {rx.id: np.full(len(world.sats), -1) for rx in world.receivers}
        self._last_station_msgs = {rx.id: -np.inf for rx in world.receivers}
        self._last_eph = {rx.id: -np.inf for rx in world.receivers}
        self._static = {rx.id: encode_frame(arp_message(rx.rtcm_id, world.published_position(rx.id)))
                        if rx.kind == "station" else b""
                        for rx in world.receivers}
        self._descr = {rx.id: encode_frame(descriptor_message(rx.rtcm_id, rx.id)) for rx in world.receivers}
        self._eph_frames: dict[int, bytes] = {}
        self._sat_cols = {s: np.flatnonzero(world.sat_system == s) for s in self.systems}
        self._prn = np.array([int(s[1:]) for s in world.sats])
        self._sig_ids = {s: np.array([by_rinex(s, c).msm_id for c in sc.signals[s]]) for s in self.systems}
        # per receiver: whole cycles taken off each (satellite, signal)'s phase, and when it last changed [GPST s]
        self._phase_off = {rx.id: None for rx in world.receivers}
        self._realigned_t = {rx.id: None for rx in world.receivers}
        self._block_off: dict[str, np.ndarray] = {}  # the last block's offsets per epoch (E, N, K)

    def sent_ambiguity(self, blk: EpochBlock) -> np.ndarray:
        """The truth ambiguities (E, R, N, K) [cycles] of the phases as the stream carried them (the MSM
        re-alignment's whole cycles taken off): for the block just added."""
        amb = blk.ambiguity_cyc.copy()
        for i, rx in enumerate(self.world.receivers):
            off = self._block_off.get(rx.id)
            if off is not None:
                amb[:, i] -= off
        return amb

    def _fitted_phase(self, blk: EpochBlock, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Receiver i's phases [cycles] and lock times [s] (E, N, K) as its MSM carries them: a phase that drifts
        more than MSM_PHASE_FIT_M from its pseudorange is re-aligned by whole cycles, its lock time restarting."""
        rid = self.world.receivers[i].id
        ph = blk.phase_cyc[:, i].copy()
        lock = blk.lock_time_s[:, i].copy()
        pr = blk.pseudorange_m[:, i]
        lam = self.world.wavelength_m
        off = self._phase_off[rid] if self._phase_off[rid] is not None else np.zeros(ph.shape[1:])
        t_re = self._realigned_t[rid] if self._realigned_t[rid] is not None else np.full(ph.shape[1:], -np.inf)
        offs = np.zeros(ph.shape)
        for e in range(len(blk.t_gpst)):
            with np.errstate(invalid="ignore"):
                d = (ph[e] - off) - pr[e] / lam  # [cycles]
                out = np.abs(d * lam) > MSM_PHASE_FIT_M  # False where NaN
            if out.any():
                off = np.where(out, off + np.rint(d), off)
                t_re = np.where(out, blk.t_gpst[e], t_re)
            ph[e] -= off
            offs[e] = off
            lock[e] = np.minimum(lock[e], blk.t_gpst[e] - t_re)
        self._phase_off[rid], self._realigned_t[rid] = off, t_re
        self._block_off[rid] = offs
        return ph, lock

    def _eph_frame(self, row: int) -> bytes:
        fr = self._eph_frames.get(row)
        if fr is None:
            fr = encode_frame(ephemeris_message(self.world.nav.table.records[row]))
            self._eph_frames[row] = fr
        return fr

    def add(self, blk: EpochBlock) -> None:
        w = self.world
        sc = w.scenario
        E = len(blk.t_gpst)
        rows = w.nav.select(w.sats, blk.t_gpst)  # (E, N): the set each satellite broadcasts
        for i, rx in enumerate(w.receivers):
            tracked = blk.observed[:, i].any(-1)  # (E, N)
            heads = [bytearray() for _ in range(E)]
            for e in range(E):
                if not tracked[e].any():
                    continue  # nothing received (outage, tunnel): the receiver sends nothing
                t_rel = float(blk.t_gpst[e] - w.t0)
                if t_rel - self._last_station_msgs[rx.id] >= sc.rtcm_station_interval_s - 1e-9:
                    heads[e] += self._static[rx.id] + self._descr[rx.id]
                    self._last_station_msgs[rx.id] = t_rel
                sent = self._sent_set[rx.id]
                periodic = t_rel - self._last_eph[rx.id] >= sc.rtcm_ephemeris_interval_s - 1e-9
                due = tracked[e] & (rows[e] >= 0) & (periodic | (rows[e] != sent))
                if periodic:
                    self._last_eph[rx.id] = t_rel
                for j in np.flatnonzero(due):
                    heads[e] += self._eph_frame(int(rows[e, j]))
                    sent[j] = rows[e, j]
            msm = self._msm_frames(blk, i)
            for e in range(E):
                if not tracked[e].any():
                    continue
                out = bytes(heads[e]) + b"".join(msm[s][e] for s in self.systems if e in msm[s])
                self.buffers[rx.id] += out
                if self.keep_epochs:
                    self.epoch_bytes[rx.id].append((float(blk.t_gpst[e]), out))

    def _msm_frames(self, blk: EpochBlock, i: int) -> dict[str, dict[int, bytes]]:
        """MSM7 frames of receiver i for every epoch of the block, per system: {system: {epoch: bytes}}.

        One batch encode per system over the block's epochs (epochs play the batch encoder's
        receiver axis); the epoch's last system gets the multiple-message bit 0, the others 1.
        """
        w = self.world
        sc = w.scenario
        rx = w.receivers[i]
        E = len(blk.t_gpst)
        present = {s: blk.observed[:, i, self._sat_cols[s], :len(sc.signals[s])].any(axis=(1, 2))
                   for s in self.systems}
        last = np.full(E, "", dtype="<U1")
        for s in self.systems:
            last = np.where(present[s], s, last)
        out: dict[str, dict[int, bytes]] = {}
        phase_all, lock_all = self._fitted_phase(blk, i)
        for s in self.systems:
            cols = self._sat_cols[s]
            K = len(sc.signals[s])
            frames: dict[int, bytes] = {}
            for multiple in (0, 1):
                ep = np.flatnonzero(present[s] & ((last == s) == (multiple == 0)))
                if not len(ep):
                    continue
                pr = blk.pseudorange_m[ep][:, i][:, cols, :K]
                cells = (~np.isnan(pr)).sum(axis=(1, 2))
                ph = phase_all[ep][:, cols, :K]
                dop = blk.doppler_hz[ep][:, i][:, cols, :K]
                cnr = blk.cnr_dbhz[ep][:, i][:, cols, :K]
                lock = lock_all[ep][:, cols, :K] * 1000.0
                half = (blk.lli[ep][:, i][:, cols, :K] & 2) != 0
                epochs = np.array([msm_epoch_ms(s, float(t)) for t in blk.t_gpst[ep]])
                small = cells <= MSM_MAX_CELLS
                if small.any():
                    k = np.flatnonzero(small)
                    batch = encode_msm_batch(s, MSM_LEVEL, self._prn[cols], self._sig_ids[s], rx.rtcm_id,
                                             epochs[k], pr[k], ph[k], dop[k], cnr[k], lock[k], half[k],
                                             multiple=multiple)
                    for n, e in enumerate(ep[k]):
                        frames[int(e)] = batch[n]
                for n in np.flatnonzero(~small):  # more than 64 cells: split over several messages
                    obs = Observables(system=s, sat_ids=self._prn[cols], sig_ids=self._sig_ids[s],
                                      pseudorange_m=pr[n], phase_cycles=ph[n], doppler_hz=dop[n],
                                      cnr_dbhz=cnr[n], lock_ms=lock[n], half_cycle=half[n])
                    msgs = observables_to_msm_list(obs, MSM_LEVEL, rx.rtcm_id, int(epochs[n]), multiple=multiple)
                    frames[int(ep[n])] = b"".join(encode_frame(m) for m in msgs)
            out[s] = frames
        return out

    def write(self, out_dir: Path) -> list[str]:
        files = []
        for rid, buf in self.buffers.items():
            (Path(out_dir) / f"{rid}.rtcm3").write_bytes(bytes(buf))
            files.append(f"{rid}.rtcm3")
        return files
