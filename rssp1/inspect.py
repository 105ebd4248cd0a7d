"""Capture inspection: per RSSP-I source, how many frames were seen, passed CRC16, passed both SVCs.

A frame's check words can only be verified knowing its sender's SIDs (and SINIT, which defaults to
the SID as in every capture we have); sources without them are counted as "not checked". Sources can
also be given `recover=True`: the SIDs are then solved from the source's first two frames
(rssp1.sid_recovery) and every other frame is verified against them, which is what shows the
recovery is right.

For every source whose SIDs are known, each path (source, destination, sending host, machine A/B) is
also replayed through a receiving `Endpoint` in monitor mode, its local cycles clocked by the capture
timestamps: what a receiver on that network would have accepted, dropped, and when its link would
have gone down. A monitor cannot send SSE, so after a link loss it re-primes at the next frame.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from rssp1.checkword import timestamp_from_svc
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.endpoint import DataReceived, Endpoint, FrameDropped, LinkDown, LinkState
from rssp1.frames import RSD_TYPES, TYPE_SSE, TYPE_SSR, FrameError, Rsd, Sse, decode_frame
from rssp1.pcapng import CaptureStats, udp_datagrams
from rssp1.sid_recovery import recover_sid
from rssp1.timestamp import timestamp_at

RSSP1_UDP_PORTS = (50000, 50001)  # the two redundant networks in the field captures (rssp1.md)
FRAME_TYPES = (*RSD_TYPES, TYPE_SSE, TYPE_SSR)


@dataclass
class SourceReport:
    source: int
    frames: int = 0
    rsd: int = 0
    sse: int = 0
    ssr: int = 0
    crc16_passed: int = 0
    svc_passed: int = 0
    svc_failed: int = 0
    svc_not_checked: int = 0
    sid: tuple[int, int] | None = None
    sid_recovered: bool = False
    first_tc: int | None = None
    last_tc: int | None = None
    networks: set[str] = field(default_factory=set)
    machines: set[str] = field(default_factory=set)


@dataclass
class PathReplay:
    """One path's frames through a receiving Endpoint in monitor mode."""

    source: int
    destination: int
    sender_ip: str
    machine: str
    file_index: int = 0
    frames: int = 0
    accepted: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    link_downs: dict[str, int] = field(default_factory=dict)


@dataclass
class CaptureReport:
    files: list[str]
    capture: CaptureStats
    sources: dict[int, SourceReport]
    undecodable: dict[str, int]  # datagrams on RSSP-I ports that are not frames (by reason)
    paths: list[PathReplay] = field(default_factory=list)

    @property
    def rsd_total(self) -> int:
        return sum(s.rsd for s in self.sources.values())


def parse_device(text: str) -> DeviceConfig:
    """`ADDR:SID1,SID2[:SINIT1,SINIT2]`, numbers in any Python base (0x29:0x311616DC,0x07643EDE)."""
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise ValueError(f"device {text!r}: expected ADDR:SID1,SID2[:SINIT1,SINIT2]")
    return DeviceConfig(address=int(parts[0], 0), sid=parts[1], sinit=parts[2] if len(parts) == 3 else None)


def inspect_captures(
    paths: list[str | Path],
    devices: list[DeviceConfig] = (),  # type: ignore[assignment]
    *,
    ports: tuple[int, ...] = RSSP1_UDP_PORTS,
    all_udp: bool = False,
    recover: bool = False,
    timing: LinkTiming | None = None,
) -> CaptureReport:
    known = {d.address: d for d in devices}
    capture = CaptureStats()
    sources: dict[int, SourceReport] = {}
    undecodable: dict[str, int] = defaultdict(int)
    rsds: dict[int, list[Rsd]] = defaultdict(list)
    by_path: dict[tuple[int, int, str, str, int], list[tuple[float, bytes]]] = defaultdict(list)
    for file_index, path in enumerate(paths):
        for dgram in udp_datagrams(path, capture):
            if not all_udp and dgram.dst_port not in ports and dgram.src_port not in ports:
                continue
            payload = dgram.payload
            if len(payload) < 6 or payload[1] not in FRAME_TYPES:
                undecodable["not_rssp1"] += 1
                continue
            source = int.from_bytes(payload[2:4], "little")
            report = sources.setdefault(source, SourceReport(source))
            report.frames += 1
            report.networks.add(f"{dgram.src_ip}->{dgram.dst_ip}:{dgram.dst_port}")
            try:
                frame = decode_frame(payload)
            except FrameError as exc:
                undecodable[exc.reason] += 1
                continue
            report.crc16_passed += 1
            if isinstance(frame, Rsd):
                report.rsd += 1
                report.machines.add(frame.machine)
                rsds[source].append(frame)
                key = (source, frame.destination, dgram.src_ip, frame.machine, file_index)
                by_path[key].append((dgram.timestamp_s, payload))
                report.first_tc = frame.tc if report.first_tc is None else min(report.first_tc, frame.tc)
                report.last_tc = frame.tc if report.last_tc is None else max(report.last_tc, frame.tc)
            elif isinstance(frame, Sse):
                report.sse += 1
            else:
                report.ssr += 1
    verified: dict[int, DeviceConfig] = {}
    for source, frames in rsds.items():
        report = sources[source]
        device = known.get(source)
        seed: tuple[int, int] | None = None
        if device is not None:
            report.sid, seed = device.sid, device.timestamp_seed
        elif recover:
            distinct = sorted({f.tc: f for f in frames}.values(), key=lambda f: f.tc)
            if len(distinct) >= 2:
                found = recover_sid(distinct[0], distinct[1])
                if len(found) == 1:
                    # T(0) = (T(tc) stepped back); we check the common SINIT = SID case by stepping forward.
                    ident = found[0]
                    report.sid, report.sid_recovered = ident.sid, True
                    seed = ident.sid if timestamp_at(ident.sid, ident.tc) == ident.timestamp else None
        if report.sid is None or seed is None:
            report.svc_not_checked += len(frames)
            continue
        verified[source] = DeviceConfig(source, report.sid, sinit=seed)
        for frame in frames:
            if timestamp_from_svc(frame.svc, frame.data, report.sid) == timestamp_at(seed, frame.tc):
                report.svc_passed += 1
            else:
                report.svc_failed += 1
    replays = [
        replay_path(key, sorted(stream), verified[key[0]], timing or LinkTiming())
        for key, stream in sorted(by_path.items())
        if key[0] in verified
    ]
    return CaptureReport([str(p) for p in paths], capture, dict(sorted(sources.items())), dict(undecodable), replays)


def replay_path(
    key: tuple[int, int, str, str, int], stream: list[tuple[float, bytes]], sender: DeviceConfig, timing: LinkTiming
) -> PathReplay:
    """Feed one path's frames (of one capture file), at their captured times, to a monitoring receiver."""
    source, destination, sender_ip, machine, file_index = key
    result = PathReplay(source, destination, sender_ip, machine, file_index)
    receiver = DeviceConfig(destination, (0, 0))  # a monitor never signs anything
    ep = Endpoint(receiver, sender, timing)
    t0 = stream[0][0]
    dropped: Counter[str] = Counter()
    downs: Counter[str] = Counter()

    def note(events) -> None:
        for e in events:
            if isinstance(e, DataReceived):
                result.accepted += 1
            elif isinstance(e, FrameDropped):
                dropped[e.reason] += 1
            elif isinstance(e, LinkDown):
                downs[e.reason] += 1

    for ts, raw in stream:
        target = int((ts - t0) / timing.cycle_s)
        while ep.local_cycle < target:
            note(ep.cycle(None)[1])
        if ep.state is LinkState.DOWN:
            ep.monitor_from(int.from_bytes(raw[6:10], "little"))
        result.frames += 1
        note(ep.receive(raw))
    result.dropped, result.link_downs = dict(dropped), dict(downs)
    return result


def format_report(report: CaptureReport) -> str:
    lines = [
        f"files: {', '.join(report.files)}",
        f"packets {report.capture.packets}, UDP {report.capture.udp}, damaged blocks {report.capture.damaged_blocks}",
        f"{'source':>8} {'frames':>7} {'RSD':>5} {'SSE':>4} {'SSR':>4} {'CRC16 ok':>9} {'SVC ok':>7} "
        f"{'SVC bad':>7} {'unchecked':>9}  SID",
    ]
    for s in report.sources.values():
        sid = "-" if s.sid is None else f"{s.sid[0]:#010x},{s.sid[1]:#010x}" + (" (recovered)" if s.sid_recovered else "")
        address = f"0x{s.source:04x}"
        lines.append(
            f"{address:>8} {s.frames:7d} {s.rsd:5d} {s.sse:4d} {s.ssr:4d} {s.crc16_passed:9d} {s.svc_passed:7d} "
            f"{s.svc_failed:7d} {s.svc_not_checked:9d}  {sid}"
        )
    lines.append(f"RSD frames: {report.rsd_total}")
    if report.paths:
        lines.append("replayed through a monitoring receiver (local cycles from capture times):")
        lines.append(
            f"{'file':>4} {'source':>6} {'dest':>6} {'from':>15} {'AB':>2} {'frames':>7} {'accepted':>8}  link downs / drops"
        )
        for p in report.paths:
            downs = ", ".join(f"{k} {v}" for k, v in sorted(p.link_downs.items())) or "-"
            drops = ", ".join(f"{k} {v}" for k, v in sorted(p.dropped.items())) or "-"
            lines.append(
                f"{p.file_index + 1:>4} 0x{p.source:04x} 0x{p.destination:04x} {p.sender_ip:>15} {p.machine:>2} {p.frames:7d} {p.accepted:8d}"
                f"  {downs} / {drops}"
            )
    if report.undecodable:
        lines.append("not decodable: " + ", ".join(f"{k} {v}" for k, v in sorted(report.undecodable.items())))
    return "\n".join(lines)
