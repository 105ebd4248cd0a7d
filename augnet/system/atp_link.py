"""Each train's RSSP-I link to its ATP inside `augnet up`: virtual balise telegrams and the service brake.

The train's timer-based balise detector (`augnet.onboard.balise_timer`) emits a passage at its predicted
moment; `AtpLinkSink` (`augnet.onboard.balise_atp`) turns it into a `VirtualBaliseTelegram` on the onboard
end of an RSSP-I link, repeated every main cycle until the ATP acknowledges it; two consecutive linked groups
missed become a service-brake request on the same link. The ATP simulator (`rssp1.atp.AtpSimulator`, a task
on the loop at the other end of a loopback UDP link, as the RBC's in `rbc_link.py`) checks each telegram
against its own copy of the balise map and acknowledges it. Issue 15, decision 0281.

Numbering (the telegram carries integers): tracks 1..n and balise groups 1..m in the track map's order;
a group's chainage to the millimetre (`BaliseGroup.along_m` is the chainage in metres).
"""

from __future__ import annotations

import asyncio

from rssp1.atp import AtpSimulator, BaliseLocation, OnboardAtpLink
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.endpoint import Endpoint

from augnet.system import loopback_link
from augnet.onboard.balise_atp import AtpLinkSink
from augnet.onboard.balise_timer import BaliseGroup, Passage

LINK_TIMING = LinkTiming()  # 250 ms main cycle, as the RBC link
# Device identities of the demo links (rssp1's tests use 0x0301 / 0x0302 for an onboard unit and its ATP);
# one pair per train, the train's number added to both addresses.
ONBOARD_ADDRESS, ATP_ADDRESS = 0x0300, 0x0400
ONBOARD_SID = (0x0BADCAFE, 0x600DF00D)
ATP_SID = (0x13572468, 0x24681357)


def balise_groups(track_db) -> list[BaliseGroup]:
    """The track map's virtual balises as the timer's groups, placed by chainage [m] (as the scenario runner)."""
    return [BaliseGroup(b.id, b.track, b.km * 1000.0, b.telegram, b.linked) for b in track_db.balises]


class _RecordingSink(AtpLinkSink):
    """The link's sink, also keeping what the onboard sent (for the run report)."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.passages: list[Passage] = []
        self.brakes: list[tuple[float, str]] = []

    def passage(self, p: Passage) -> None:
        self.passages.append(p)
        super().passage(p)

    def service_brake(self, time: float, reason: str) -> None:
        self.brakes.append((time, reason))
        super().service_brake(time, reason)


class AtpConnection:
    """One train's onboard RSSP-I end and its ATP simulator, on loopback UDP, driven by rssp1's cycle loops."""

    def __init__(self, train_number: int, groups: list[BaliseGroup]):
        self.train_number = train_number
        tracks = sorted({g.track for g in groups})
        self.track_ids = {t: i + 1 for i, t in enumerate(tracks)}
        self.group_numbers = {g.id: i + 1 for i, g in enumerate(groups)}
        self.chainage_mm = {g.id: int(round(g.along_m * 1000.0)) for g in groups}
        self.group_of = {n: gid for gid, n in self.group_numbers.items()}  # the ATP's number -> map id
        onboard = DeviceConfig(ONBOARD_ADDRESS + train_number, ONBOARD_SID, dataver=(3, 4), name="onboard")
        atp = DeviceConfig(ATP_ADDRESS + train_number, ATP_SID, dataver=(5, 6), name="atp")
        self.link = OnboardAtpLink(Endpoint(onboard, atp, LINK_TIMING), train_id=train_number)
        self.atp = AtpSimulator(Endpoint(atp, onboard, LINK_TIMING),
                                {self.group_numbers[g.id]: BaliseLocation(self.track_ids[g.track], self.chainage_mm[g.id])
                                 for g in groups})
        self.sink = _RecordingSink(self.link, self.track_ids, self.chainage_mm, self.group_numbers)
        self.links: list = []
        self.tasks: list[asyncio.Task] = []

    async def start(self, host: str = "127.0.0.1") -> None:
        self.links, self.tasks = await loopback_link.open_pair(self.link, self.atp, LINK_TIMING.cycle_s, host)

    async def stop(self) -> None:
        await loopback_link.close(self.links, self.tasks)

    def snapshot(self) -> dict:
        """What the ATP received, in order, and what the link counted."""
        return {
            "link_up": self.link.is_up,
            "telegrams_received": [
                {"group": self.group_of.get(t.balise_group, t.balise_group), "time_ms": t.time_ms,
                 "chainage_mm": t.chainage_mm, "confidence_mm": t.confidence_mm, "speed_mm_s": t.speed_mm_s,
                 "reverse": t.reverse, "telegram_id": t.telegram_id} for t in self.atp.passages],
            "service_brake_requests": [{"time_ms": a.epoch_ms, "text": a.text} for a in self.atp.service_brake_requests],
            "atp_alarms": [a.kind for a in self.atp.alarms],
            "onboard_sent": len(self.sink.passages), "unacknowledged": len(self.link.pending),
            "onboard_stats": dict(self.link.stats), "atp_stats": dict(self.atp.stats),
        }


__all__ = ["AtpConnection", "balise_groups", "LINK_TIMING"]
