"""The centre's RSSP-I link to the RBC inside `augnet up`: line sections, their integrity, alarms.

The line is cut into `SECTION_LENGTH_KM` sections (section ids 1..n from km 0). Each network epoch
sets every section's status from what the centre can vouch for there:
  OK          the two reference stations bracketing the section along the line delivered this epoch
              and the network has fixed ambiguities on the baselines touching them;
  DEGRADED    one of them is missing, or those baselines are not (yet) fixed: corrections there rest on
              stations farther away (interpolation over a longer distance);
  DO_NOT_USE  neither is delivering, or no correction model at all (the RBC's own age watchdog also
              turns every section DO_NOT_USE when reports stop).
Centre alarms (station down, satellite excluded) become RSSP-I alarms; the RBC simulator on the other
end of a loopback UDP link shows what a real RBC would believe. The RBC's own alarms, its watchdog's
(corrections stale, link lost) and a section reported DO_NOT_USE, come back to the centre's alarm store
through `on_alarm` (`rbc-correction-stale`, `rbc-section-do-not-use`, ...), raised when the RBC raises them
and cleared when it clears them (or the section is usable again), so the console shows every one.
"""

from __future__ import annotations

import asyncio
import logging
import math
from typing import Callable

import numpy as np

from rssp1.config import DeviceConfig, LinkTiming
from rssp1.endpoint import Endpoint
from rssp1.messages import AlarmCode, SectionStatus, Severity
from rssp1.rbc import CentreRbcLink, RbcSimulator

from augnet.system import loopback_link

log = logging.getLogger(__name__)

SECTION_LENGTH_KM = 10.0
FIXED_ENOUGH = 0.5  # share of a baseline's eligible DD ambiguities fixed for it to count as fixed
# Device identities of the demo link (as in rssp1.loopback: the RBC is source 0x0029 of the captures).
CENTRE_DEVICE = DeviceConfig(0x0101, (0x1A2B3C4D, 0x5E6F7081), dataver=(1, 2), name="centre")
RBC_DEVICE = DeviceConfig(0x0029, (0x311616DC, 0x07643EDE), dataver=(10, 11), name="rbc")
LINK_TIMING = LinkTiming()  # 250 ms main cycle
MAX_CORRECTION_AGE_S = 5.0  # network-rtk.md: corrections older than ~5 s lose the fix
# a station whose coordinates the network flagged serves no train, as a failed one (decision 0254)
ALARM_CODES = {"station-down": AlarmCode.STATION_FAILED, "satellite-fault": AlarmCode.SATELLITE_EXCLUDED,
               "station-coordinates": AlarmCode.STATION_FAILED}
SEVERITY = {"info": Severity.INFO, "warning": Severity.WARNING, "critical": Severity.CRITICAL}
RBC_ALARM_POLL_S = 1.0  # the RBC's watchdog alarms reach the alarm store within this (4 RSSP-I main cycles)


class SectionPlan:
    """Which stations bracket each line section (by their chainage along the line)."""

    def __init__(self, line_length_km: float, station_km: dict[str, float]):
        self.n = max(1, int(math.ceil(line_length_km / SECTION_LENGTH_KM)))
        self.ids = list(range(1, self.n + 1))
        names = sorted(station_km, key=station_km.get)
        kms = np.array([station_km[n] for n in names])
        self.bracket: dict[int, tuple[str, str]] = {}
        for sid in self.ids:
            mid = (sid - 0.5) * SECTION_LENGTH_KM
            i = int(np.searchsorted(kms, mid))
            a = names[max(i - 1, 0)]
            b = names[min(i, len(names) - 1)]
            self.bracket[sid] = (a, b)

    def statuses(self, present: set[str], fixed_stations: set[str]) -> dict[int, SectionStatus]:
        out = {}
        for sid, (a, b) in self.bracket.items():
            up = [s for s in (a, b) if s in present]
            if not up:
                out[sid] = SectionStatus.DO_NOT_USE
            elif len(up) == 2 and all(s in fixed_stations for s in up):
                out[sid] = SectionStatus.OK
            else:
                out[sid] = SectionStatus.DEGRADED
        return out


def fixed_stations(fixed_fraction: dict[str, float]) -> set[str]:
    """Stations touched by at least one baseline with enough fixed ambiguities ("A-B" keys)."""
    out: set[str] = set()
    for key, frac in fixed_fraction.items():
        if frac >= FIXED_ENOUGH:
            out.update(key.split("-"))
    return out


def _rbc_kind(code: AlarmCode) -> str:
    return "rbc-" + code.name.lower().replace("_", "-")


class RbcConnection:
    """Both ends of the link on loopback UDP, driven by rssp1's cycle loops."""

    def __init__(self, plan: SectionPlan, station_ids: dict[str, int],
                 on_alarm: Callable[[str, str, str, str, bool], None] | None = None):
        self.on_alarm = on_alarm  # on_alarm(kind, subject, severity, message, cleared), as the centre's
        self._watchdog_seen = 0  # RBC alarms already looked at
        self._watchdog_open: set[AlarmCode] = set()
        self._sections_open: set[int] = set()  # sections whose DO_NOT_USE alarm is in the store
        self.plan = plan
        self.station_ids = station_ids
        self.centre = CentreRbcLink(Endpoint(CENTRE_DEVICE, RBC_DEVICE, LINK_TIMING),
                                    max_correction_age_s=MAX_CORRECTION_AGE_S)
        self.rbc = RbcSimulator(Endpoint(RBC_DEVICE, CENTRE_DEVICE, LINK_TIMING),
                                max_correction_age_s=MAX_CORRECTION_AGE_S)
        for sid in plan.ids:
            self.centre.set_section(sid, SectionStatus.DO_NOT_USE)
        self.links: list = []
        self.tasks: list = []

    async def start(self, host: str = "127.0.0.1") -> None:
        self.links, self.tasks = await loopback_link.open_pair(self.centre, self.rbc, LINK_TIMING.cycle_s, host)
        if self.on_alarm is not None:
            self.tasks.append(asyncio.ensure_future(self._forward_alarms()))

    def rbc_alarm_events(self) -> list[tuple[str, str, str, str, bool]]:
        """The RBC's own alarms raised and cleared since the last call, as alarm-store events: its watchdog's
        (subject "rbc"), and a section reported DO_NOT_USE (subject "section <id>", cleared when the
        section is reported usable again). Alarms the centre sent it are the centre's, stored already."""
        out = []
        for a in self.rbc.alarms[self._watchdog_seen:]:
            if a.origin == "watchdog" and a.code not in self._watchdog_open:
                self._watchdog_open.add(a.code)
                out.append((_rbc_kind(a.code), "rbc", "critical", f"RBC: {a.text}", False))
            elif a.origin == "status" and a.section_id not in self._sections_open:
                self._sections_open.add(a.section_id)
                out.append((_rbc_kind(a.code), f"section {a.section_id}", "warning",
                            f"RBC: section {a.section_id} reported DO_NOT_USE", False))
        self._watchdog_seen = len(self.rbc.alarms)
        for sid in sorted(self._sections_open):
            reported = self.rbc.view.reported.get(sid)
            if reported is not None and reported.status is not SectionStatus.DO_NOT_USE:
                self._sections_open.discard(sid)
                out.append((_rbc_kind(AlarmCode.SECTION_DO_NOT_USE), f"section {sid}", "warning",
                            "RBC: cleared", True))
        for code in sorted(self._watchdog_open, key=lambda c: c.value):
            name = code.name.lower()
            if self.rbc.stats[f"cleared_{name}"] >= self.rbc.stats[f"alarm_{name}"]:
                self._watchdog_open.discard(code)
                out.append((_rbc_kind(code), "rbc", "critical", "RBC: cleared", True))
        return out

    async def _forward_alarms(self) -> None:
        while True:
            await asyncio.sleep(RBC_ALARM_POLL_S)
            try:
                for event in self.rbc_alarm_events():
                    self.on_alarm(*event)
            except Exception:  # noqa: BLE001 - the alarm store's trouble must not stop the link
                log.exception("RBC alarm forwarding failed")

    def on_epoch(self, t_gpst: float, produced_at_s: float, present: set[str], fixed_fraction: dict[str, float],
                 excluded_sats, alarms) -> None:
        """One network epoch: sections, exclusions, correction age, alarms (produced_at_s: monotonic)."""
        for sid, status in self.plan.statuses(present, fixed_stations(fixed_fraction)).items():
            self.centre.set_section(sid, status)
        down = [self.station_ids[s] for s in self.station_ids if s not in present]
        self.centre.set_exclusions(sorted(excluded_sats), down)
        self.centre.corrections_updated(int(round(t_gpst * 1000)), produced_at_s)
        for a in alarms:
            if getattr(a, "cleared", False):
                continue
            code = ALARM_CODES.get(a.kind, AlarmCode.OPERATOR)
            self.centre.raise_alarm(code, SEVERITY.get(a.severity, Severity.WARNING), text=f"{a.subject}: {a.message}"[:60])

    def snapshot(self) -> dict:
        counts = {s.name: 0 for s in SectionStatus}
        for sid in self.plan.ids:
            counts[self.rbc.effective_status(sid).name] += 1
        return {"link_up": self.centre.is_up, "rbc_fresh": self.rbc.fresh, "sections": counts,
                "rbc_alarms": len(self.rbc.alarms),
                # the section register's pictures the RBC holds (SECTION_TRAINS) and the trains in them
                "section_trains": {"pictures": len(self.rbc.view.section_trains),
                                   "trains": sum(len(m.trains) for m in self.rbc.view.section_trains.values())},
                "last_rbc_alarm": (self.rbc.alarms[-1].code.name if self.rbc.alarms else None)}

    async def stop(self) -> None:
        await loopback_link.close(self.links, self.tasks)
