"""The sans-IO RSSP-I endpoint: one device's end of one link, driven once per main cycle.

    ep = Endpoint(local, peer, timing)
    events = ep.receive(datagram)          # any time between cycles, once per frame received
    frames, events = ep.cycle(data)        # once per main cycle: watchdogs, then the frames to send

No sockets, no clocks: the caller owns both (rssp1.transport is one such caller, tests are others).
Both directions live here: our RSDs to the peer (own TC, own timestamps) and the peer's RSDs to us
(synchronised by our SSE and its SSR).

Receive rules (rssp1.md "Synchronisation and freshness"), in the order applied to an RSD:

1. CRC16, length, type                  -> dropped, counted `crc16`/`length`/...   (corruption)
2. source / destination addresses      -> dropped, `address`                        (insertion)
3. not synchronised                     -> dropped, `unsynchronised`; an SSE goes out
4. TC <= last accepted TC               -> dropped silently, `repeat`                (repetition,
                                                                                      re-sequencing)
   (right after an SSR, the RSD with TC = TC_R is dropped as `at_sync_point`; see _receive_ssr)
5. both safety check words (SVC) against the peer's timestamp at the frame's TC, T(TC), stepped
   from the last verified (TC, T) pair   -> dropped, `svc`                            (corruption past
                                                                                      CRC16, wrong SID)
6. TC gap >= deltaTime                  -> link down, `gap`; SSE                      (deletion)
7. TC older than our estimate of the sender's TC by >= deltaTime
                                        -> dropped, `late`                           (delay)
8. otherwise accepted; the first accepted RSD after an SSR brings the link up.

TC binding. The TC field of every frame is protected by CRC16 only; the safety code covers it
through the timestamp: SVC_i carries T_i(TC), and T_i(TC) = LFSR_i^TC(SINIT_i) (rssp1.md "Codes":
T(0) = SID_i by default, T(n) = LFSR_i(T(n-1)); SINIT from configuration, rssp1.config). So a TC label
is taken only together with a timestamp that belongs to it:
- an SSR is taken only if the timestamp it reveals, T(TC_R) = SEQINI ^ SEQENQ ^ SID ^ DATAVER, equals
  the peer's SINIT advanced TC_R cycles (else `ssr_inconsistent`); a refresh SSR only if it continues
  the verified chain, which is the same test;
- an RSD is taken only if the timestamp its check words claim equals T(TC) for its TC field, computed
  from the last verified pair (one step per cycle of gap), which by induction is T(TC) from SINIT.
Without the first rule a bearer that rewrites TC_R and then the TCs of the following RSDs by the same
offset (recomputing CRC16) shifts every label: the relative check of step 5 cannot see an offset
common to the SSR and the RSDs. The same rule refuses an SSR computed with a wrong DATAVER, and with
a wrong SID unless the SID error cancels at TC_R (TC_R = 0 with SINIT = SID), which the sync-point
rule and step 5 then catch.
TC is a u32: when it wraps to 0 the sender's timestamp starts again from SINIT (T is a function of the
TC field, as the check binds it), and a receiver whose gap crosses the wrap computes T(TC) from SINIT.

While the link is up, accepted frames arriving at lag deltaTime - 1 trigger a refresh SSE; its SSR
(taken only if its timestamp continues the verified chain) re-anchors the estimate, so clock drift
between the two ends never drops an authentic link (see _refresh_anchor).

The SVC check runs before the gap rule so that only a frame that proves it comes from the peer can
take the link down. A local watchdog drops the link after DelayTime cycles in a row without an
accepted RSD (`timeout`), which also catches a stream that is entirely late or that never verifies
(a wrong SID that got past the SSR check). At most one SSE leaves per lifeTime cycles; an SSR counts only when it echoes
the TC of our last SSE and arrives less than lifeTime cycles after it.
"""

from __future__ import annotations

import enum
from collections import Counter
from dataclasses import dataclass

from rssp1 import checkword
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.frames import (
    CATEGORY_ACTIVE,
    NUM_DATAVER,
    TYPE_RSD_A,
    TYPE_RSD_B,
    FrameError,
    Rsd,
    Sse,
    Ssr,
    decode_frame,
    encode_rsd,
    encode_sse,
    encode_ssr,
)
from rssp1.timestamp import advance_pair, step_pair, timestamp_at

TC_MODULUS = 1 << 32  # TC is a u32 on the wire


class LinkState(enum.Enum):
    DOWN = "down"  # not synchronised: RSDs are dropped, SSEs go out
    SYNCING = "syncing"  # SSR accepted, waiting for the first RSD that verifies
    UP = "up"


@dataclass(slots=True)  # not frozen: a frozen __init__ costs a microsecond per frame
class DataReceived:
    data: bytes
    tc: int
    machine: str  # "A" or "B"


@dataclass(slots=True)  # not frozen: a frozen __init__ costs a microsecond per frame
class LinkUp:
    cycle: int


@dataclass(slots=True)  # not frozen: a frozen __init__ costs a microsecond per frame
class LinkDown:
    reason: str
    cycle: int


@dataclass(slots=True)  # not frozen: a frozen __init__ costs a microsecond per frame
class FrameDropped:
    reason: str


Event = DataReceived | LinkUp | LinkDown | FrameDropped


class Endpoint:
    """One end of an RSSP-I link. See the module docstring for the rules."""

    def __init__(
        self,
        local: DeviceConfig,
        peer: DeviceConfig,
        timing: LinkTiming | None = None,
        *,
        initial_tc: int = 0,
        machine: int = TYPE_RSD_A,
        category: int = CATEGORY_ACTIVE,
    ) -> None:
        if machine not in (TYPE_RSD_A, TYPE_RSD_B):
            raise ValueError("machine must be TYPE_RSD_A or TYPE_RSD_B")
        self.local = local
        self.peer = peer
        self.timing = timing or LinkTiming()
        self.machine = machine
        self.category = category
        self.stats: Counter[str] = Counter()
        # Sending side: our TC and timestamps, T(TC) = LFSR^TC(SINIT).
        self.tc = initial_tc % TC_MODULUS
        self._seed = local.timestamp_seed
        self._t = timestamp_at(self._seed, self.tc)
        self._pending_sse: tuple[int, tuple[int, int]] | None = None  # (TC_E, SEQENQ) to answer
        # Receiving side.
        self._peer_seed = peer.timestamp_seed  # the peer's SINIT: T(TC) of the peer = LFSR^TC(SINIT)
        self.state = LinkState.DOWN
        self.local_cycle = -1  # index of the last cycle run
        self._sse_tc_e: int | None = None
        self._sse_seqenq: tuple[int, int] = (0, 0)
        self._sse_cycle = 0
        self._last_tc = 0  # last accepted TC (or TC_R - 1 right after an SSR)
        self._last_t: tuple[int, int] = (0, 0)  # peer timestamps at _last_tc
        self._anchor_tc = 0  # our estimate of the peer's TC: _anchor_tc + (local_cycle - _anchor_cycle)
        self._anchor_cycle = 0
        self._missed_cycles = 0
        self._good_since_tick = False
        self._refresh_wanted = False

    # ----------------------------------------------------------------- receiving
    def receive(self, frame: bytes | bytearray | memoryview) -> list[Event]:
        """Process one received frame. Never raises on bad input: it is counted and dropped."""
        self.stats["rx_frames"] += 1
        try:
            decoded = decode_frame(frame)
        except FrameError as exc:
            return self._drop(exc.reason)
        if decoded.source != self.peer.address or decoded.destination != self.local.address:
            return self._drop("address")
        if isinstance(decoded, Rsd):
            return self._receive_rsd(decoded)
        if isinstance(decoded, Sse):
            self.stats["rx_sse"] += 1
            self._pending_sse = (decoded.tc_e, decoded.seqenq)
            return []
        return self._receive_ssr(decoded)

    def _drop(self, reason: str) -> list[Event]:
        self.stats[f"dropped_{reason}"] += 1
        return [FrameDropped(reason)]

    def _receive_ssr(self, ssr: Ssr) -> list[Event]:
        self.stats["rx_ssr"] += 1
        if self._sse_tc_e is None or ssr.tc_e != self._sse_tc_e:
            return self._drop("ssr_unexpected")
        if self.local_cycle - self._sse_cycle >= self.timing.life_time:
            return self._drop("ssr_stale")
        if ssr.num_dataver != NUM_DATAVER:
            return self._drop("ssr_num_dataver")
        t_r = checkword.timestamp_from_ssr(ssr.seqini, self._sse_seqenq, self.peer.sid, self.peer.dataver)
        if self.state is LinkState.UP:
            return self._refresh_anchor(ssr.tc_r, t_r)
        # TC_R is covered by CRC16 only; the timestamp the SSR reveals is covered by the safety code
        # (SEQINI). Take TC_R only if that timestamp is T(TC_R), the peer's SINIT advanced TC_R cycles:
        # otherwise a bearer that shifts TC_R and then every following TC field by the same offset
        # would shift every label we deliver, since the RSD checks below only bind TC differences.
        # A refused SSR does not use up our SSE: a good copy of the SSR may still follow.
        if t_r != timestamp_at(self._peer_seed, ssr.tc_r):
            return self._drop("ssr_inconsistent")
        self._sse_tc_e = None
        # The RSD sent with TC_R itself is not taken: at TC_R an error d in the SID we hold for the
        # peer cancels out (the SSR gives us T ^ d, the RSD claims T ^ d). The check above sees d
        # too (with SINIT = SID it compares T ^ d with T ^ M^TC_R d), except where M^TC_R = I: TC_R = 0
        # (a peer that just started) or 2^32 - 1, the LFSRs' period. From TC_R + k on, the
        # prediction carries M^k d instead, and I ^ M^k is invertible for the gaps a link allows
        # (tests/rssp1/test_faults.py checks k < 64), so a wrong SID never verifies.
        self._last_tc = ssr.tc_r
        self._last_t = t_r
        self._anchor_tc = ssr.tc_r
        self._anchor_cycle = self.local_cycle
        self._missed_cycles = 0
        self.state = LinkState.SYNCING
        self.stats["ssr_accepted"] += 1
        return []

    def monitor_from(self, tc: int) -> None:
        """Passive monitoring: take the peer's configured SINIT (T(0) = SINIT) instead of an SSE/SSR
        handshake, as if synchronised just before TC `tc`.

        For a line monitor or a capture replay that can only listen. It relies on the sender seeding
        its timestamps with SINIT from TC 0, which every device in the captures does; the check words
        are verified exactly as after an SSR.
        """
        before = (tc - 1) % TC_MODULUS
        self._last_tc = before
        self._last_t = timestamp_at(self._peer_seed, before)
        self._anchor_tc, self._anchor_cycle = before, self.local_cycle
        self._missed_cycles = 0
        self._sse_tc_e = None
        self.state = LinkState.SYNCING
        self.stats["monitor_primed"] += 1

    def _refresh_anchor(self, tc_r: int, t_r: tuple[int, int]) -> list[Event]:
        """An SSR answering a refresh SSE while the link is up: re-anchor the estimate of the peer's TC.

        Clock drift: the peer's TC and our local cycle count drift apart (100 ppm is one cycle in
        10,000), and without this the freshness rule would eventually drop authentic frames and take
        the link down. When accepted frames come in at lag deltaTime - 1, we ask for a fresh SSR
        (bounded by lifeTime, so it cannot hide a delay beyond the limits) and move the estimate to it.
        Its timestamp must continue the chain we verify RSDs with, else it is refused (and, like a
        refused first SSR, does not use up our SSE).
        """
        ahead = (tc_r - self._last_tc) % TC_MODULUS
        if ahead >= TC_MODULUS // 2:
            return self._drop("ssr_stale")
        if self._timestamp_after(tc_r, ahead) != t_r:  # T(TC_R) from the chain = from SINIT
            return self._drop("ssr_inconsistent")
        self._sse_tc_e = None
        self._anchor_tc, self._anchor_cycle = tc_r, self.local_cycle
        self.stats["ssr_refresh"] += 1
        return []

    def _timestamp_after(self, tc: int, gap: int) -> tuple[int, int]:
        """The peer's T(tc), `gap` cycles after the last verified pair (_last_tc, _last_t).

        One LFSR step per cycle of gap; when the gap crosses the u32 wrap of TC (tc < gap), the
        sender started again from SINIT at TC 0, so T(tc) comes from SINIT.
        """
        if tc < gap:
            return timestamp_at(self._peer_seed, tc)
        return advance_pair(self._last_t, gap)

    def _receive_rsd(self, rsd: Rsd) -> list[Event]:
        if self.state is LinkState.DOWN:
            return self._drop("unsynchronised")
        tc = rsd.tc
        gap = (tc - self._last_tc) % TC_MODULUS
        if gap == 0 or gap >= TC_MODULUS // 2:  # not newer (u32 serial-number arithmetic)
            if self.state is LinkState.SYNCING and gap == 0:
                return self._drop("at_sync_point")
            return self._drop("repeat")
        # T(TC) for this frame's TC field (see _timestamp_after; inlined for the common case)
        t = advance_pair(self._last_t, gap) if tc >= gap else timestamp_at(self._peer_seed, tc)
        if checkword.timestamp_from_svc(rsd.svc, rsd.data, self.peer.sid) != t:
            return self._drop("svc")
        if gap >= self.timing.delta_time:
            self.stats["dropped_gap"] += 1
            return [FrameDropped("gap"), *self._link_down("gap")]
        estimate = (self._anchor_tc + (self.local_cycle - self._anchor_cycle)) % TC_MODULUS
        lag = (estimate - tc) % TC_MODULUS
        if lag < TC_MODULUS // 2:
            if lag >= self.timing.delta_time:
                return self._drop("late")
            if lag and lag >= self.timing.delta_time - 1 and self.state is LinkState.UP:
                self._refresh_wanted = True  # close to the limit: re-anchor before drift drops us
        else:  # the peer runs ahead of our estimate (its clock is a little faster): follow it
            self._anchor_tc, self._anchor_cycle = tc, self.local_cycle
        self._last_tc, self._last_t = tc, t
        self._good_since_tick = True
        self.stats["rx_rsd_ok"] += 1
        events: list[Event] = []
        if self.state is LinkState.SYNCING:
            self.state = LinkState.UP
            self.stats["link_up"] += 1
            events.append(LinkUp(self.local_cycle))
        events.append(DataReceived(rsd.data, tc, rsd.machine))
        return events

    def _link_down(self, reason: str) -> list[Event]:
        previous = self.state
        self.state = LinkState.DOWN
        self._missed_cycles = 0
        self._refresh_wanted = False
        if previous is LinkState.SYNCING:
            # an SSR was taken but no RSD verified against it (wrong SID/DATAVER, or lost again)
            self.stats["sync_failed"] += 1
            return []
        if previous is LinkState.DOWN:
            return []
        self.stats["link_down"] += 1
        self.stats[f"link_down_{reason}"] += 1
        return [LinkDown(reason, self.local_cycle)]

    # ------------------------------------------------------------------- cycling
    def cycle(self, data: bytes | None = None) -> tuple[list[bytes], list[Event]]:
        """Run one main cycle: receive watchdogs, then build this cycle's frames (SSR, SSE, RSD).

        `data` is this cycle's user data (None: no RSD this cycle; TC advances anyway).
        """
        self.local_cycle += 1
        events: list[Event] = []
        if self.state is not LinkState.DOWN:
            if self._good_since_tick:
                self._missed_cycles = 0
            else:
                self._missed_cycles += 1
                if self._missed_cycles >= self.timing.delay_time:
                    events.extend(self._link_down("timeout"))
        self._good_since_tick = False

        frames: list[bytes] = []
        src, dst = self.local.address, self.peer.address
        if self._pending_sse is not None:
            tc_e, enq = self._pending_sse
            self._pending_sse = None
            ini = checkword.seqini(enq, self.local.sid, self.local.dataver, self._t)
            frames.append(encode_ssr(src, dst, self.tc, tc_e, ini, category=self.category))
            self.stats["tx_ssr"] += 1
        refresh = self._refresh_wanted and self.state is LinkState.UP
        if (self.state is LinkState.DOWN or refresh) and (
            self._sse_tc_e is None or self.local_cycle - self._sse_cycle >= self.timing.life_time
        ):
            if refresh:
                self._refresh_wanted = False
                self.stats["tx_sse_refresh"] += 1
            self._sse_tc_e = self.tc
            self._sse_seqenq = checkword.seqenq(self.local.sid, self._t)
            self._sse_cycle = self.local_cycle
            frames.append(encode_sse(src, dst, self.tc, self._sse_seqenq, category=self.category))
            self.stats["tx_sse"] += 1
        if data is not None:
            words = checkword.svc(data, self.local.sid, self._t)
            frames.append(encode_rsd(src, dst, self.tc, words, data, msg_type=self.machine, category=self.category))
            self.stats["tx_rsd"] += 1
        self.tc = (self.tc + 1) % TC_MODULUS
        # T(TC) = LFSR^TC(SINIT): one step per cycle, and SINIT again when TC wraps to 0 (the LFSR's
        # period is 2^32 - 1, so stepping on would leave T one step ahead of its TC after the wrap)
        self._t = step_pair(self._t) if self.tc else self._seed
        return frames, events

    @property
    def is_up(self) -> bool:
        return self.state is LinkState.UP
