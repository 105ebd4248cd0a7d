"""Two sans-IO endpoints in lockstep with a programmable bearer between them, for fault injection."""

from __future__ import annotations

from collections import deque
from typing import Callable

from rssp1.config import DeviceConfig, LinkTiming
from rssp1.endpoint import DataReceived, Endpoint, Event, LinkDown, LinkUp

CENTRE = DeviceConfig(0x0101, (0x1A2B3C4D, 0x5E6F7081), dataver=(0x00000001, 0x00000002), name="centre")
RBC = DeviceConfig(0x0029, (0x311616DC, 0x07643EDE), dataver=(0x0000000A, 0x0000000B), name="rbc")

# A bearer hook sees each frame sent towards the receiver and returns what to deliver now (any list
# of frames) -- drop, duplicate, corrupt, reorder or hold back.
Hook = Callable[[int, bytes], list[bytes]]


class LinkPair:
    def __init__(self, timing: LinkTiming | None = None, *, sender: DeviceConfig = CENTRE,
                 receiver: DeviceConfig = RBC, sender_as_seen: DeviceConfig | None = None,
                 receiver_as_seen: DeviceConfig | None = None, initial_tc: int = 1000) -> None:
        self.timing = timing or LinkTiming()
        # sender_as_seen: the sender's identity as configured at the receiver (differs for wrong SID)
        self.a = Endpoint(sender, receiver_as_seen or receiver, self.timing, initial_tc=initial_tc)
        self.b = Endpoint(receiver, sender_as_seen or sender, self.timing, initial_tc=50)
        self.cycle_no = 0
        self.to_b: Hook = lambda cycle, frame: [frame]
        self.to_a: Hook = lambda cycle, frame: [frame]
        self.b_events: list[Event] = []
        self.a_events: list[Event] = []
        self.held: deque[tuple[int, bytes]] = deque()
        self.sent_to_b: list[bytes] = []

    def step(self, data: bytes | None = b"status") -> list[Event]:
        """One main cycle for both ends; frames sent this cycle are delivered before the next."""
        fa, ea = self.a.cycle(data)
        fb, eb = self.b.cycle(b"ack")
        self.a_events += ea
        events = list(eb)
        for frame in fa:
            self.sent_to_b.append(frame)
            for f in self.to_b(self.cycle_no, frame):
                events += self.b.receive(f)
        for frame in fb:
            for f in self.to_a(self.cycle_no, frame):
                self.a_events += self.a.receive(f)
        self.b_events += events
        self.cycle_no += 1
        return events

    def run(self, cycles: int, data: bytes | None = b"status") -> list[Event]:
        out: list[Event] = []
        for _ in range(cycles):
            out += self.step(data)
        return out

    def bring_up(self, max_cycles: int = 10) -> int:
        for n in range(1, max_cycles + 1):
            self.step()
            if self.b.is_up and self.a.is_up:
                return n
        raise AssertionError(f"link not up after {max_cycles} cycles: {self.b.stats}")


def received(events: list[Event]) -> list[bytes]:
    return [e.data for e in events if isinstance(e, DataReceived)]


def downs(events: list[Event]) -> list[str]:
    return [e.reason for e in events if isinstance(e, LinkDown)]


def ups(events: list[Event]) -> int:
    return sum(isinstance(e, LinkUp) for e in events)
