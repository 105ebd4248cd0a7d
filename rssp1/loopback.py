"""End-to-end over real sockets on one machine: a stand-in centre, the RBC simulator, time to alarm.

The centre is not built yet; `StandInCentre` plays its part with the public CentreRbcLink API (sections,
fresh corrections every cycle, then a fault). `time_to_alarm` opens both ends on loopback (UDP as
deployed, or length-prefixed TCP), waits for the RBC to hold a fresh picture, injects the fault at the
centre and measures, on the one monotonic clock both share, how long until the RBC simulator raises
its alarm, and how many main cycles of each end started meanwhile. `python -m rssp1 demo` prints the
time; tests/rssp1/test_loopback.py judges the cycle counts, which a loaded machine does not stretch.
"""

from __future__ import annotations

import asyncio
import random
import time
from dataclasses import dataclass

from rssp1.config import DeviceConfig, LinkTiming
from rssp1.endpoint import Endpoint
from rssp1.envelope import Keyring, SealedEndpoint
from rssp1.messages import AlarmCode, SectionStatus
from rssp1.rbc import CentreRbcLink, RbcSimulator
from rssp1.transport import TcpLink, UdpLink

DEMO_CENTRE = DeviceConfig(0x0101, (0x1A2B3C4D, 0x5E6F7081), dataver=(1, 2), name="centre")
DEMO_RBC = DeviceConfig(0x0029, (0x311616DC, 0x07643EDE), dataver=(10, 11), name="rbc")
DEMO_SECTIONS = tuple(range(1, 11))
FAULT_SECTION = 7
WAIT_LIMIT_S = 10.0  # give up waiting for link-up or alarm after this (a test then fails, never hangs)
CORRECTION_AGE_LIMIT_CYCLES = 4  # both ends' correction-age limit, in main cycles


class StandInCentre:
    """Drives a CentreRbcLink like the network engine would: fresh corrections every cycle."""

    def __init__(self, link: CentreRbcLink) -> None:
        self.link = link
        self.producing = True
        self.epoch_ms = 1_400_000_000_000
        for s in DEMO_SECTIONS:
            link.set_section(s, SectionStatus.OK, hpl_m=0.5)

    def cycle(self, now_s: float) -> list[bytes]:
        if self.producing:
            self.epoch_ms += 1000
            self.link.corrections_updated(self.epoch_ms, produced_at_s=now_s)
        return self.link.cycle(now_s)

    def receive(self, datagram: bytes, now_s: float | None = None) -> None:
        self.link.receive(datagram, now_s)


@dataclass(frozen=True)
class AlarmTiming:
    transport: str
    sealed: bool
    link_up_s: float  # from start to the RBC holding a fresh picture
    time_to_alarm_s: float  # fault injected at the centre -> RBC simulator alarm
    centre_cycles: int  # centre main cycles that started between the fault and the alarm
    rbc_cycles: int  # RBC main cycles that started between the fault and the alarm
    alarm: str
    rbc_stats: dict[str, int]


async def _wait_for(predicate, clock, limit_s: float = WAIT_LIMIT_S, poll_s: float = 0.002) -> float:
    start = clock()
    while not predicate():
        if clock() - start > limit_s:
            raise TimeoutError("condition not reached")
        await asyncio.sleep(poll_s)
    return clock()


async def time_to_alarm(
    timing: LinkTiming, *, transport: str = "udp", sealed: bool = False, fault: str = "section",
    host: str = "127.0.0.1", phase_s: float | None = None,
) -> AlarmTiming:
    """fault: "section" (a line section becomes DO_NOT_USE), "corrections" (the engine stops producing;
    the time counts from the moment the age passes the limit) or "link" (the centre goes silent).
    phase_s: when in the centre's cycle the fault comes (default: uniformly random in one cycle)."""
    clock = time.monotonic
    centre_ep, rbc_ep = Endpoint(DEMO_CENTRE, DEMO_RBC, timing), Endpoint(DEMO_RBC, DEMO_CENTRE, timing)
    if sealed:
        keys = Keyring({1: bytes(range(32))})
        centre_ep, rbc_ep = SealedEndpoint(centre_ep, keys), SealedEndpoint(rbc_ep, keys)
    max_age_s = CORRECTION_AGE_LIMIT_CYCLES * timing.cycle_s
    centre = StandInCentre(CentreRbcLink(centre_ep, max_correction_age_s=max_age_s))
    rbc = RbcSimulator(rbc_ep, max_correction_age_s=max_age_s)
    start = clock()
    if transport == "udp":
        rbc_link = await UdpLink.open(rbc, timing.cycle_s, (host, 0), (host, 9))
        centre_link = await UdpLink.open(centre, timing.cycle_s, (host, 0), rbc_link.local_address)
        rbc_link.remote = centre_link.local_address
    elif transport == "tcp":
        rbc_link = TcpLink(rbc, timing.cycle_s)
        centre_link = TcpLink(centre, timing.cycle_s)
        addr = await rbc_link.serve(host, 0)
        await centre_link.connect(*addr)
    else:
        raise ValueError(f"transport {transport!r}")
    tasks = [asyncio.create_task(rbc_link.run()), asyncio.create_task(centre_link.run())]
    try:
        up_at = await _wait_for(lambda: rbc.effective_status(FAULT_SECTION) is SectionStatus.OK, clock)
        # run steadily for a while, then fault at a random point of the cycle
        phase = random.uniform(0.0, timing.cycle_s) if phase_s is None else phase_s
        await asyncio.sleep(3 * timing.cycle_s + phase)
        centre_before, rbc_before = centre_link.stats["cycles"], rbc_link.stats["cycles"]
        if fault == "section":
            fault_at = clock()
            centre.link.set_section(FAULT_SECTION, SectionStatus.DO_NOT_USE)
            code, section = AlarmCode.SECTION_DO_NOT_USE, FAULT_SECTION
        elif fault == "corrections":
            centre.producing = False
            fault_at = centre.link._produced_at_s + max_age_s  # type: ignore[operator]
            code, section = AlarmCode.CORRECTION_STALE, None
        elif fault == "link":
            fault_at = clock()
            centre_link.stop()
            code, section = AlarmCode.LINK_LOST, None
        else:
            raise ValueError(f"fault {fault!r}")
        # polled every 2 ms on the loop that runs both ends: read before either end's next cycle
        await _wait_for(lambda: rbc.first_alarm(code, section) is not None, clock)
        alarm = rbc.first_alarm(code, section)
        assert alarm is not None
        return AlarmTiming(
            transport, sealed, up_at - start, alarm.at_s - fault_at, centre_link.stats["cycles"] - centre_before,
            rbc_link.stats["cycles"] - rbc_before, code.name, dict(rbc.stats),
        )
    finally:
        for link in (centre_link, rbc_link):
            result = link.close()
            if asyncio.iscoroutine(result):
                await result
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
