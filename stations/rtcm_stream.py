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

from augnet.gnss import time as gtime
from augnet.gnss.rtcm.codec import RtcmMessage, encode_frame, text_fields
from augnet.gnss.rtcm.observables import Observables, observables_to_msm_list
from augnet.gnss.signals import by_rinex
from stations.ephemeris_messages import ephemeris_message
from stations.world import EpochBlock, World

MSM_LEVEL = 7
ANTENNA_DESCRIPTOR = "AUGNET-ISOTROPIC"
RECEIVER_DESCRIPTOR = "AUGNET SIMULATOR"
FIRMWARE = "1"
SYSTEM_ORDER = ("G", "E", "C")


def arp_message(station_id: int, ecef_m) -> RtcmMessage:
    """1005: stationary antenna reference point, real station, GPS/Galileo (BDS signalled by MSM)."""
    x, y, z = (float(v) for v in ecef_m)
    return RtcmMessage(1005, dict(DF002=1005, DF003=station_id, DF021=0, DF022=1, DF023=0, DF024=1,
                                  DF141=0, DF025=x, DF142=1, DF001_1=0, DF026=y, DF364=0, DF027=z))


def descriptor_message(station_id: int, serial: str) -> RtcmMessage:
    """1033: antenna and receiver descriptors (what RINEX headers and casters show)."""
    f: dict[str, object] = dict(DF002=1033, DF003=station_id, DF031=0)
    f.update(text_fields("DF030", "DF029", ANTENNA_DESCRIPTOR))
    f.update(text_fields("DF033", "DF032", serial))
    f.update(text_fields("DF228", "DF227", RECEIVER_DESCRIPTOR))
    f.update(text_fields("DF230", "DF229", FIRMWARE))
    f.update(text_fields("DF232", "DF231", serial))
    return RtcmMessage(1033, f)


def msm_epoch_ms(system: str, t_gpst: float) -> int:
    """The MSM epoch field: time of week [ms] in the system's own time (BDT for BeiDou)."""
    _, tow = gtime.system_week_tow(system, t_gpst)
    return int(round(float(tow) * 1000.0)) % (7 * 86_400_000)


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
        self._static = {rx.id: encode_frame(arp_message(rx.rtcm_id, rx.ecef[0])) if rx.kind == "station" else b""
                        for rx in world.receivers}
        self._descr = {rx.id: encode_frame(descriptor_message(rx.rtcm_id, rx.id)) for rx in world.receivers}
        self._eph_frames: dict[int, bytes] = {}
        self._sat_cols = {s: np.flatnonzero(world.sat_system == s) for s in self.systems}
        self._prn = np.array([int(s[1:]) for s in world.sats])
        self._sig_ids = {s: np.array([by_rinex(s, c).msm_id for c in sc.signals[s]]) for s in self.systems}

    def _eph_frame(self, row: int) -> bytes:
        fr = self._eph_frames.get(row)
        if fr is None:
            fr = encode_frame(ephemeris_message(self.world.nav.table.records[row]))
            self._eph_frames[row] = fr
        return fr

    def add(self, blk: EpochBlock) -> None:
        w = self.world
        sc = w.scenario
        rows = w.nav.select(w.sats, blk.t_gpst)  # (E, N): the set each satellite broadcasts
        for e, t in enumerate(blk.t_gpst):
            t_rel = float(t - w.t0)
            for i, rx in enumerate(w.receivers):
                out = bytearray()
                tracked = blk.observed[e, i].any(-1)
                if not tracked.any():
                    continue  # nothing received (outage, tunnel): the receiver sends nothing
                if t_rel - self._last_station_msgs[rx.id] >= sc.rtcm_station_interval_s - 1e-9:
                    out += self._static[rx.id] + self._descr[rx.id]
                    self._last_station_msgs[rx.id] = t_rel
                sent = self._sent_set[rx.id]
                periodic = t_rel - self._last_eph[rx.id] >= sc.rtcm_ephemeris_interval_s - 1e-9
                due = tracked & (rows[e] >= 0) & (periodic | (rows[e] != sent))
                if periodic:
                    self._last_eph[rx.id] = t_rel
                for j in np.flatnonzero(due):
                    out += self._eph_frame(int(rows[e, j]))
                    sent[j] = rows[e, j]
                msgs = []
                for s in self.systems:
                    cols = self._sat_cols[s]
                    K = len(sc.signals[s])
                    obs = Observables(
                        system=s, sat_ids=self._prn[cols], sig_ids=self._sig_ids[s],
                        pseudorange_m=blk.pseudorange_m[e, i, cols, :K], phase_cycles=blk.phase_cyc[e, i, cols, :K],
                        doppler_hz=blk.doppler_hz[e, i, cols, :K], cnr_dbhz=blk.cnr_dbhz[e, i, cols, :K],
                        lock_ms=blk.lock_time_s[e, i, cols, :K] * 1000.0,
                        half_cycle=(blk.lli[e, i, cols, :K] & 2) != 0)
                    if not blk.observed[e, i, cols, :K].any():
                        continue
                    msgs.append(observables_to_msm_list(obs, MSM_LEVEL, rx.rtcm_id, msm_epoch_ms(s, float(t)),
                                                        multiple=1))
                for n, group in enumerate(msgs):
                    for k, m in enumerate(group):
                        if n == len(msgs) - 1 and k == len(group) - 1:
                            m.multiple = 0  # the epoch's last MSM
                        out += encode_frame(m)
                self.buffers[rx.id] += out
                if self.keep_epochs:
                    self.epoch_bytes[rx.id].append((float(t), bytes(out)))

    def write(self, out_dir: Path) -> list[str]:
        files = []
        for rid, buf in self.buffers.items():
            (Path(out_dir) / f"{rid}.rtcm3").write_bytes(bytes(buf))
            files.append(f"{rid}.rtcm3")
        return files
