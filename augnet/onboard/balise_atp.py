"""The timer-based balise detector's sink that speaks RSSP-I: passages as virtual balise telegrams and the
service-brake request as an alarm, both through rssp1's sans-IO `OnboardAtpLink` (repeated until acked)."""

from __future__ import annotations

from rssp1.atp import BaliseLocation, OnboardAtpLink
from rssp1.messages import SectionStatus

from augnet.onboard.balise_timer import Miss, Passage


class AtpLinkSink:
    def __init__(self, link: OnboardAtpLink, track_ids: dict[str, int], chainage_mm: dict,
                 group_numbers: dict[str, int] | None = None):
        """`track_ids`: track name -> the ATP's numeric track id; `chainage_mm`: group id -> the chainage
        the ATP's balise map holds for it (the telegram must match it exactly); `group_numbers`: the
        ATP's numeric group id for each map id that is not already an int."""
        self.link = link
        self.group_numbers = group_numbers or {}
        self.track_ids = track_ids
        self.chainage_mm = chainage_mm
        self.misses: list[Miss] = []

    def passage(self, p: Passage) -> None:
        g = p.group
        self.link.report_balise(
            time_ms=round(p.time * 1000.0),
            balise_group=g.id if isinstance(g.id, int) else self.group_numbers[g.id],
            location=BaliseLocation(self.track_ids[g.track], self.chainage_mm[g.id]), reverse=p.direction < 0,
            confidence_mm=round(p.confidence_m * 1000.0), speed_mm_s=round(p.speed_mps * 1000.0),
            integrity=SectionStatus.OK)

    def missed(self, m: Miss) -> None:
        self.misses.append(m)

    def service_brake(self, time: float, reason: str) -> None:
        self.link.request_service_brake(time_ms=round(time * 1000.0), text=reason)
