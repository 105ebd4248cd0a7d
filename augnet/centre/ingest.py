"""From station RTCM streams to aligned network epochs (sans-IO: bytes and times in, epochs out).

`StationDecoder` turns one station's byte stream into complete `StationEpoch`s (all MSMs of an epoch,
closed by the multiple-message bit or by the next epoch), broadcast ephemerides, the antenna reference
point (1005/1006) and the antenna and receiver descriptors (1033: the antenna type the centre looks up in an
ANTEX file, IGS names as in RINEX ANT # / TYPE, e.g. `TRM41249.00     NONE`). Corrupt frames are counted and skipped by the framing layer; a message that passes its CRC but does
not decode is counted and skipped here.

`EpochAligner` gathers the stations' epochs by time tag and releases an epoch when every station that is
up has delivered it, or when a later epoch has arrived from some station and the laggards had
`MAX_WAIT_S` to catch up (a late or missing station never holds the network back for long).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from augnet.centre.observations import DEFAULT_SIGNAL_PLAN, StationEpoch
from augnet.gnss import time as gtime
from augnet.gnss.ephemeris import Ephemeris
from augnet.gnss.rtcm import MessageReader, MsmMessage, RtcmMessage, msm_to_observables
from augnet.gnss.rtcm.ephemeris import message_ephemeris
from augnet.gnss.signals import UnknownSignal, by_msm

SECONDS_PER_WEEK = 604_800.0
EPHEMERIS_TYPES = (1019, 1042, 1045, 1046)
# How long the aligner waits for late stations once a newer epoch exists [s]: a station's data normally
# arrives within a few hundred ms of another's; corrections must stay under ~2 s old (network-rtk.md).
MAX_WAIT_S = 1.0


@dataclass
class DecoderStats:
    frames: int = 0
    undecodable: int = 0
    msm: int = 0
    epochs: int = 0
    ephemerides: int = 0
    unsupported_signals: int = 0


@dataclass
class _Pending:
    t_gpst: float
    parts: list = field(default_factory=list)  # Observables of the epoch's MSMs


class StationDecoder:
    def __init__(self, name: str, t_ref_gpst: float, plan=None):
        self.name = name
        self.plan = plan or DEFAULT_SIGNAL_PLAN
        self.t_ref = float(t_ref_gpst)  # resolves MSM times of week to full GPST; follows the stream
        self.reader = MessageReader()
        self.stats = DecoderStats()
        self.arp_ecef: np.ndarray | None = None
        self.antenna_height_m: float | None = None  # 1006: ARP above the marker (the ARP is what 1005/1006 give)
        self.antenna_descriptor: str | None = None  # 1033 DF030: antenna type (and radome)
        self.antenna_setup_id: int | None = None  # 1033 DF031
        self.receiver_descriptor: str | None = None  # 1033 DF228
        self.ephemerides: list[Ephemeris] = []  # decoded since the last `take_ephemerides`
        self._pending: _Pending | None = None
        self._last_lock: dict[tuple[str, str], float] = {}

    def take_ephemerides(self) -> list[Ephemeris]:
        out, self.ephemerides = self.ephemerides, []
        return out

    def feed(self, data: bytes) -> list[StationEpoch]:
        done: list[StationEpoch] = []
        for msg in self.reader.feed(data):
            self.stats.frames += 1
            try:
                if isinstance(msg, MsmMessage):
                    done += self._msm(msg)
                elif isinstance(msg, RtcmMessage):
                    if msg.msg_type in EPHEMERIS_TYPES:
                        self.ephemerides.append(message_ephemeris(msg, self.t_ref))
                        self.stats.ephemerides += 1
                    elif msg.msg_type in (1005, 1006):
                        f = msg.fields
                        self.arp_ecef = np.array([float(f["DF025"]), float(f["DF026"]), float(f["DF027"])])
                        if msg.msg_type == 1006:
                            self.antenna_height_m = float(f["DF028"])
                    elif msg.msg_type == 1033:
                        self.antenna_descriptor = msg.text("DF030")
                        self.antenna_setup_id = int(msg.fields.get("DF031", 0))
                        self.receiver_descriptor = msg.text("DF228")
            except (ValueError, KeyError, IndexError):
                self.stats.undecodable += 1
        return done

    def flush(self) -> list[StationEpoch]:
        """Close the epoch being gathered (end of stream)."""
        if self._pending is None:
            return []
        ep = self._finish(self._pending)
        self._pending = None
        return [ep] if ep is not None else []

    def _msm(self, msg: MsmMessage) -> list[StationEpoch]:
        obs = msm_to_observables(msg)
        if obs.system not in self.plan:
            return []
        self.stats.msm += 1
        tow_s = int(msg.epoch) / 1000.0
        t_sys = gtime.gpst_to_system(obs.system, self.t_ref)
        week_start = t_sys - np.mod(t_sys, SECONDS_PER_WEEK)
        cand = week_start + tow_s
        cand += SECONDS_PER_WEEK * np.round((t_sys - cand) / SECONDS_PER_WEEK)
        t = float(gtime.system_to_gpst(obs.system, cand))
        out = []
        if self._pending is not None and abs(self._pending.t_gpst - t) > 1e-3:
            ep = self._finish(self._pending)
            self._pending = None
            if ep is not None:
                out.append(ep)
        if self._pending is None:
            self._pending = _Pending(t)
        self._pending.parts.append(obs)
        self.t_ref = t
        if not int(msg.multiple):  # the epoch's last MSM
            ep = self._finish(self._pending)
            self._pending = None
            if ep is not None:
                out.append(ep)
        return out

    def _finish(self, p: _Pending) -> StationEpoch | None:
        sats, code, phase, lli, cnr, freq, used = [], [], [], [], [], [], []
        for obs in p.parts:
            slots = self.plan[obs.system]
            try:
                codes = [by_msm(obs.system, int(s)).rinex_code for s in obs.sig_ids]
            except UnknownSignal:
                self.stats.unsupported_signals += 1
                continue
            for i, prn in enumerate(obs.sat_ids):
                sat = f"{obs.system}{int(prn):02d}"
                row_c = np.full(2, np.nan)
                row_l = np.full(2, np.nan)
                row_s = np.full(2, np.nan)
                row_f = np.full(2, np.nan)
                row_lli = np.zeros(2, np.int8)
                row_u = ["", ""]
                for k, candidates in enumerate(slots):
                    for rc in candidates:
                        if rc not in codes:
                            continue
                        j = codes.index(rc)
                        pr, ph = obs.pseudorange_m[i, j], obs.phase_cycles[i, j]
                        if not (np.isfinite(pr) and np.isfinite(ph)):
                            continue
                        row_c[k], row_l[k] = pr, ph
                        row_s[k] = obs.cnr_dbhz[i, j]
                        row_f[k] = by_msm(obs.system, int(obs.sig_ids[j])).freq_hz
                        row_u[k] = rc
                        lock = float(obs.lock_ms[i, j])
                        prev = self._last_lock.get((sat, rc))
                        # a lock time that went down (or a half-cycle flag) means the phase restarted
                        slipped = prev is None or lock < prev or bool(obs.half_cycle[i, j])
                        row_lli[k] = 1 if slipped and prev is not None else 0
                        if bool(obs.half_cycle[i, j]):
                            row_lli[k] |= 2
                        self._last_lock[(sat, rc)] = lock
                        break
                if np.isfinite(row_c).any():
                    sats.append(sat)
                    code.append(row_c)
                    phase.append(row_l)
                    cnr.append(row_s)
                    freq.append(row_f)
                    lli.append(row_lli)
                    used.append(row_u)
        if not sats:
            return None
        self.stats.epochs += 1
        return StationEpoch(self.name, p.t_gpst, np.array(sats), np.array(code), np.array(phase),
                            np.array(lli, dtype=np.int8), np.array(cnr), np.array(freq),
                            np.array(used, dtype="<U2"))


class EpochAligner:
    """Gathers station epochs by time tag; releases complete (or timed-out) network epochs in order."""

    def __init__(self, stations: list[str], max_wait_s: float = MAX_WAIT_S):
        self.stations = list(stations)
        self.max_wait_s = max_wait_s
        self._epochs: dict[float, dict[str, StationEpoch]] = {}
        self._first_seen: dict[float, float] = {}
        self._last_seen: dict[float, float] = {}
        # epochs released by the last `ready` call -> (first, last) arrival time of their stations' data
        self.arrivals: dict[float, tuple[float, float]] = {}
        self.expected: set[str] = set(stations)  # stations currently delivering (others are not waited for)
        self.late_dropped = 0
        self._released_up_to = -np.inf

    @staticmethod
    def _key(t: float) -> float:
        return round(t, 3)

    def add(self, ep: StationEpoch, now: float) -> None:
        k = self._key(ep.t_gpst)
        if k <= self._released_up_to:
            self.late_dropped += 1  # that epoch was already solved without this station
            return
        self._epochs.setdefault(k, {})[ep.station] = ep
        self._first_seen.setdefault(k, now)
        self._last_seen[k] = max(now, self._last_seen.get(k, now))
        self.expected.add(ep.station)

    def add_station(self, name: str) -> None:
        """A station joins: waited for once it delivers (`add`)."""
        if name not in self.stations:
            self.stations.append(name)

    def remove_station(self, name: str) -> None:
        """A station leaves: no longer waited for; its epochs not yet released are dropped."""
        self.stations = [s for s in self.stations if s != name]
        self.expected.discard(name)
        for k in list(self._epochs):
            self._epochs[k].pop(name, None)
            if not self._epochs[k]:  # it was the epoch's only station so far
                del self._epochs[k]
                self._first_seen.pop(k, None)
                self._last_seen.pop(k, None)

    def ready(self, now: float) -> list[tuple[float, dict[str, StationEpoch]]]:
        out = []
        self.arrivals = {}
        for k in sorted(self._epochs):
            got = self._epochs[k]
            complete = self.expected <= set(got)
            newer = any(k2 > k for k2 in self._epochs)
            waited = now - self._first_seen[k] >= self.max_wait_s
            if complete or (waited and newer) or now - self._first_seen[k] >= 3 * self.max_wait_s:
                if not complete:
                    # stations that missed the epoch are not waited for until they deliver again
                    self.expected = set(got) | {s for s in self.expected if any(s in e for e in self._epochs.values()
                                                                                 if e is not got)}
                out.append((k, got))
                self.arrivals[k] = (self._first_seen[k], self._last_seen.pop(k, self._first_seen[k]))
                del self._epochs[k]
                del self._first_seen[k]
                self._released_up_to = k
            else:
                break
        return out
