"""Correction decoding (sans-IO): RTCM 3 bytes from the caster -> base epochs, base position, age.

Feeds any byte chunks (as they come off the NTRIP connection) through `augnet.gnss.rtcm`'s
stream reader.  MSM4-7 of GPS, Galileo, BeiDou and QZSS are assembled per epoch (the MSM
"multiple message" bit says when an epoch is complete; a newer epoch also completes older ones),
1005/1006 give the reference station's ARP and whether it is a physical station (DF141: a VRS is not,
and the RTK filter then estimates the network's residual ionosphere).  Ephemerides are not taken from the stream here: the
rover's own receiver decodes the broadcast navigation message, the same one the caster relays.

Loss of lock: an MSM lock-time indicator that went down (or is zero) since the previous epoch sets
the LLI slip bit, so the RTK filter re-initialises that ambiguity.  Nothing here raises on bad
bytes: CRC failures, undecodable and unsupported messages are counted in `stats`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.constants import SECONDS_PER_WEEK
from augnet.gnss.rtcm import MsmMessage, RtcmMessage, RtcmStreamReader, decode, msm_to_observables
from augnet.gnss.rtcm.correction_bound import CORRECTION_BOUND_MESSAGE, decode_correction_bound
from augnet.gnss.signals import UnknownSignal, by_msm
from augnet.onboard.correction_bound import CorrectionBounds
from augnet.onboard.observations import (
    ATTRIBUTE_PRIORITY,
    BAND_FREQ_HZ,
    LLI_HALF_CYCLE,
    LLI_SLIP,
    SUPPORTED_SYSTEMS,
    SYSTEM_BANDS,
    EpochObs,
)
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S

# MSM message numbers -> system letter (RTCM 10403.3 3.5.12: 107x GPS, 109x Galileo, 111x QZSS,
# 112x BeiDou; GLONASS 108x and SBAS 110x are not used by this rover).
MSM_SYSTEM = {107: "G", 109: "E", 111: "J", 112: "C"}
# Epochs still incomplete this long [s] after a newer one arrived are emitted anyway.
MAX_PENDING_EPOCHS = 3


@dataclass
class DecoderStats:
    bytes: int = 0
    frames: int = 0
    crc_failures: int = 0
    decode_errors: int = 0
    unsupported: int = 0
    epochs: int = 0
    by_type: dict[int, int] = field(default_factory=dict)


class CorrectionDecoder:
    def __init__(self, systems=SUPPORTED_SYSTEMS, n_slots: int = 2):
        self.systems = tuple(systems)
        self.n_slots = n_slots
        self.reader = RtcmStreamReader()
        self.stats = DecoderStats()
        self.base_position_m: np.ndarray | None = None
        self.station_id: int | None = None
        self.base_non_physical = False
        self.last_epoch: EpochObs | None = None
        self.bounds = CorrectionBounds()  # the centre's 4001 correction-error bounds on this stream
        self._pending: dict[float, list] = {}
        self._lock_prev: dict[tuple[str, str], float] = {}

    def feed(self, data: bytes, t_ref_gpst: float) -> list[EpochObs]:
        """Decode a chunk; returns the base epochs completed by it (oldest first).

        `t_ref_gpst`: the rover's current time, to put MSM times of week into the right week.
        """
        self.stats.bytes += len(data)
        try:
            frames = self.reader.feed(data)
        except Exception:  # noqa: BLE001 - a sans-IO reader must never take the loop down
            self.stats.decode_errors += 1
            return []
        self.stats.crc_failures = getattr(self.reader.stats, "crc_failures", self.stats.crc_failures)
        done: list[EpochObs] = []
        for fr in frames:
            self.stats.frames += 1
            self.stats.by_type[fr.msg_type] = self.stats.by_type.get(fr.msg_type, 0) + 1
            try:
                if fr.msg_type == CORRECTION_BOUND_MESSAGE:
                    self.bounds.add(decode_correction_bound(fr.payload))
                    continue
                msg = decode(fr)
            except Exception:  # noqa: BLE001 - corrupt payload with a good CRC
                self.stats.decode_errors += 1
                continue
            if isinstance(msg, MsmMessage):
                done.extend(self._msm(msg, t_ref_gpst))
            elif isinstance(msg, RtcmMessage) and fr.msg_type in (1005, 1006):
                f = msg.fields
                p = np.array([f.get("DF025", math.nan), f.get("DF026", math.nan), f.get("DF027", math.nan)], float)
                if np.all(np.isfinite(p)) and 6.0e6 < np.linalg.norm(p) < 6.5e6:
                    self.base_position_m = p
                    self.station_id = int(f.get("DF003", 0))
                    # DF141: 1 = a non-physical (computed) reference station such as a network VRS
                    self.base_non_physical = bool(f.get("DF141", 0))
                else:
                    self.stats.decode_errors += 1
            else:
                self.stats.unsupported += 1
        return done

    def flush(self) -> list[EpochObs]:
        """Emit every pending epoch (end of a stream)."""
        out = [self._assemble(t) for t in sorted(self._pending)]
        return [e for e in out if e is not None]

    def age_s(self, now_gpst: float) -> float:
        """Age of the latest complete base epoch at `now_gpst` (inf when none yet)."""
        return math.inf if self.last_epoch is None else now_gpst - self.last_epoch.time

    # ------------------------------------------------------------------------------------------

    def _msm(self, msg: MsmMessage, t_ref: float) -> list[EpochObs]:
        system = MSM_SYSTEM.get(msg.msg_type // 10)
        if system is None or system not in self.systems:
            self.stats.unsupported += 1
            return []
        try:
            obs = msm_to_observables(msg)
        except (UnknownSignal, ValueError, IndexError):
            self.stats.decode_errors += 1
            return []
        tow = (msg.epoch & 0x3FFFFFFF) / 1000.0
        t_sys_week, _ = gtime.system_week_tow(system, t_ref)
        t = float(gtime.gpst_from_system_week_tow(system, t_sys_week, tow))
        t += -round((t - t_ref) / SECONDS_PER_WEEK) * SECONDS_PER_WEEK
        t = round(t, 3)
        self._pending.setdefault(t, []).append(obs)
        out = []
        if msg.multiple == 0:
            out.append(self._assemble(t))
        # an epoch left open (final message lost) is completed by the arrival of newer ones
        for old in sorted(self._pending):
            if old < t and (len(self._pending) > MAX_PENDING_EPOCHS or msg.multiple == 0):
                out.insert(0, self._assemble(old))
        return [e for e in out if e is not None]

    def _assemble(self, t: float) -> EpochObs | None:
        parts = self._pending.pop(t, [])
        sats, rows = [], []
        seen: set[str] = set()
        for o in parts:
            sys_ = o.system
            bands = SYSTEM_BANDS[sys_][: self.n_slots]
            sigs = []
            for s in o.sig_ids:
                try:
                    sigs.append(by_msm(sys_, int(s)))
                except UnknownSignal:
                    sigs.append(None)  # a signal the table does not know is left out
            # per band, signal columns in priority order
            choice: list[list[int]] = []
            for band in bands:
                pri = ATTRIBUTE_PRIORITY[(sys_, band)]
                cols = [j for j, s in enumerate(sigs) if s is not None and s.rinex_code[0] == band]
                cols.sort(key=lambda j: pri.find(sigs[j].rinex_code[1]) % 100 if sigs[j].rinex_code[1] in pri else 99)
                choice.append(cols)
            for i, prn in enumerate(o.sat_ids):
                sat = f"{sys_}{int(prn):02d}"
                if sat in seen:
                    continue  # the same satellite in two MSM levels of one epoch: the first wins
                seen.add(sat)
                row = []
                for f, cols in enumerate(choice):
                    cell = None
                    for j in cols:
                        if np.isfinite(o.pseudorange_m[i, j]) or np.isfinite(o.phase_cycles[i, j]):
                            cell = j
                            break
                    row.append((cell, sigs[cell] if cell is not None else None))
                sats.append(sat)
                rows.append((o, i, row))
        if not sats:
            return None
        n, F = len(sats), self.n_slots
        code = np.full((n, F), np.nan)
        phase = np.full((n, F), np.nan)
        dop = np.full((n, F), np.nan)
        snr = np.full((n, F), np.nan)
        lli = np.zeros((n, F), dtype=np.int16)
        wl = np.full((n, F), np.nan)
        sig = np.full((n, F), "", dtype="<U3")
        for k, (o, i, row) in enumerate(rows):
            for f, (j, s) in enumerate(row):
                if j is None:
                    continue
                code[k, f] = o.pseudorange_m[i, j]
                phase[k, f] = o.phase_cycles[i, j]
                dop[k, f] = o.doppler_hz[i, j]
                snr[k, f] = o.cnr_dbhz[i, j]
                sig[k, f] = s.rinex_code
                wl[k, f] = SPEED_OF_LIGHT_M_S / BAND_FREQ_HZ[(o.system, s.rinex_code[0])]
                lock = float(o.lock_ms[i, j])
                key = (sats[k], s.rinex_code)
                prev = self._lock_prev.get(key)
                # a lock time that went down means the receiver lost lock in between (RTCM 10403.3
                # DF407 note); a sender stuck at 0 gives no information (the other slip tests remain)
                if math.isfinite(lock) and prev is not None and lock < prev:
                    lli[k, f] |= LLI_SLIP
                if bool(o.half_cycle[i, j]):
                    lli[k, f] |= LLI_HALF_CYCLE
                if math.isfinite(lock):
                    self._lock_prev[key] = lock
        order = np.argsort(np.array(sats))
        ep = EpochObs(t, np.array(sats, dtype="<U3")[order], code[order], phase[order], dop[order], snr[order],
                      lli[order], wl[order], sig[order])
        self.stats.epochs += 1
        if self.last_epoch is None or ep.time >= self.last_epoch.time:
            self.last_epoch = ep
        return ep
