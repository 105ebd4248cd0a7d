"""A small capture reader: pcapng (and classic pcap), Ethernet/VLAN/Linux-cooked/raw IP, IPv4/IPv6, UDP.

Enough to pull RSSP-I datagrams out of Wireshark captures, with the standard library only. Damaged
blocks end the walk (counted in `CaptureStats.damaged_blocks`) rather than raising: a truncated capture
still yields what precedes the damage.

References: pcapng, IETF draft-ietf-opsawg-pcapng (block types 0x0A0D0D0A SHB, 1 IDB, 2 obsolete PB,
3 SPB, 6 EPB); link types from the tcpdump LINKTYPE registry (1 Ethernet, 101 raw IP, 113 Linux SLL,
228 IPv4, 229 IPv6, 276 Linux SLL2).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

SHB = 0x0A0D0D0A
IDB = 0x00000001
OBSOLETE_PB = 0x00000002
SPB = 0x00000003
EPB = 0x00000006
BYTE_ORDER_MAGIC = 0x1A2B3C4D
PCAP_MAGICS = {
    b"\xd4\xc3\xb2\xa1": ("<", 1e-6),
    b"\xa1\xb2\xc3\xd4": (">", 1e-6),
    b"\x4d\x3c\xb2\xa1": ("<", 1e-9),
    b"\xa1\xb2\x3c\x4d": (">", 1e-9),
}

LINKTYPE_ETHERNET = 1
LINKTYPE_RAW = 101
LINKTYPE_LINUX_SLL = 113
LINKTYPE_IPV4 = 228
LINKTYPE_IPV6 = 229
LINKTYPE_LINUX_SLL2 = 276

ETHERTYPE_IPV4 = 0x0800
ETHERTYPE_IPV6 = 0x86DD
ETHERTYPE_VLAN = (0x8100, 0x88A8, 0x9100)
IPPROTO_UDP = 17
OPT_IF_TSRESOL = 9


@dataclass(frozen=True, slots=True)
class Packet:
    timestamp_s: float
    linktype: int
    data: bytes


@dataclass(frozen=True, slots=True)
class UdpDatagram:
    timestamp_s: float
    src_ip: str
    src_port: int
    dst_ip: str
    dst_port: int
    payload: bytes


@dataclass
class CaptureStats:
    packets: int = 0
    udp: int = 0
    not_udp: int = 0
    fragments: int = 0  # IPv4 fragments after the first: not reassembled, counted
    damaged_blocks: int = 0
    unsupported_linktype: int = 0
    truncated: int = 0
    notes: list[str] = field(default_factory=list)


def _tsresol_seconds(options: bytes, endian: str) -> float:
    off = 0
    while off + 4 <= len(options):
        code, length = struct.unpack_from(endian + "HH", options, off)
        if code == 0:
            break
        value = options[off + 4 : off + 4 + length]
        if code == OPT_IF_TSRESOL and length >= 1:
            v = value[0]
            return 2.0 ** -(v & 0x7F) if v & 0x80 else 10.0 ** -v
        off += 4 + ((length + 3) & ~3)
    return 1e-6


def _read_pcapng(buf: bytes, stats: CaptureStats) -> Iterator[Packet]:
    off = 0
    endian = "<"
    interfaces: list[tuple[int, float]] = []
    while off + 12 <= len(buf):
        block_type = struct.unpack_from("<I", buf, off)[0]
        if block_type == SHB:
            magic = buf[off + 8 : off + 12]
            if magic == struct.pack("<I", BYTE_ORDER_MAGIC):
                endian = "<"
            elif magic == struct.pack(">I", BYTE_ORDER_MAGIC):
                endian = ">"
            else:
                stats.damaged_blocks += 1
                stats.notes.append(f"bad section header at byte {off}")
                return
            interfaces = []
        block_type, length = struct.unpack_from(endian + "II", buf, off)
        if length < 12 or length % 4 or off + length > len(buf):
            stats.damaged_blocks += 1
            stats.notes.append(f"damaged block at byte {off} (length {length})")
            return
        body = buf[off + 8 : off + length - 4]
        if block_type == IDB and len(body) >= 8:
            linktype = struct.unpack_from(endian + "H", body, 0)[0]
            interfaces.append((linktype, _tsresol_seconds(body[8:], endian)))
        elif block_type in (EPB, OBSOLETE_PB) and len(body) >= 20:
            if block_type == EPB:
                iface, ts_hi, ts_lo, cap_len, _orig = struct.unpack_from(endian + "IIIII", body, 0)
            else:
                iface, _drops, ts_hi, ts_lo, cap_len, _orig = struct.unpack_from(endian + "HHIIII", body, 0)
            if iface >= len(interfaces) or 20 + cap_len > len(body):
                stats.damaged_blocks += 1
            else:
                linktype, resol = interfaces[iface]
                yield Packet(((ts_hi << 32) | ts_lo) * resol, linktype, body[20 : 20 + cap_len])
        elif block_type == SPB and len(body) >= 4 and interfaces:
            orig = struct.unpack_from(endian + "I", body, 0)[0]
            yield Packet(0.0, interfaces[0][0], body[4 : 4 + min(orig, len(body) - 4)])
        off += length
    if off != len(buf):
        stats.damaged_blocks += 1
        stats.notes.append(f"{len(buf) - off} trailing bytes")


def _read_pcap(buf: bytes, stats: CaptureStats) -> Iterator[Packet]:
    endian, resol = PCAP_MAGICS[buf[:4]]
    linktype = struct.unpack_from(endian + "I", buf, 20)[0] & 0x0FFFFFFF
    off = 24
    while off + 16 <= len(buf):
        ts_s, ts_frac, cap_len, _orig = struct.unpack_from(endian + "IIII", buf, off)
        if off + 16 + cap_len > len(buf):
            stats.damaged_blocks += 1
            return
        yield Packet(ts_s + ts_frac * resol, linktype, buf[off + 16 : off + 16 + cap_len])
        off += 16 + cap_len


def read_packets(path: str | Path, stats: CaptureStats | None = None) -> Iterator[Packet]:
    """Every captured packet of a pcapng or pcap file."""
    stats = stats if stats is not None else CaptureStats()
    buf = Path(path).read_bytes()
    if buf[:4] in PCAP_MAGICS:
        reader = _read_pcap(buf, stats)
    elif len(buf) >= 12 and struct.unpack_from("<I", buf, 0)[0] == SHB:
        reader = _read_pcapng(buf, stats)
    else:
        raise ValueError(f"{path}: neither pcapng nor pcap")
    for packet in reader:
        stats.packets += 1
        yield packet


def _ip_payload(linktype: int, data: bytes) -> tuple[int, bytes] | None:
    """(ethertype-like IP version tag, IP packet) from a link-layer frame."""
    if linktype == LINKTYPE_ETHERNET:
        off = 12
        if len(data) < off + 2:
            return None
        ethertype = struct.unpack_from(">H", data, off)[0]
        off += 2
        while ethertype in ETHERTYPE_VLAN and len(data) >= off + 4:
            ethertype = struct.unpack_from(">H", data, off + 2)[0]
            off += 4
        return ethertype, data[off:]
    if linktype == LINKTYPE_LINUX_SLL and len(data) >= 16:
        return struct.unpack_from(">H", data, 14)[0], data[16:]
    if linktype == LINKTYPE_LINUX_SLL2 and len(data) >= 20:
        return struct.unpack_from(">H", data, 0)[0], data[20:]
    if linktype in (LINKTYPE_RAW, LINKTYPE_IPV4, LINKTYPE_IPV6) and data:
        return (ETHERTYPE_IPV4 if data[0] >> 4 == 4 else ETHERTYPE_IPV6), data
    return None


def _ipv6_text(b: bytes) -> str:
    return ":".join(f"{x:x}" for x in struct.unpack(">8H", b))


def udp_datagrams(path: str | Path, stats: CaptureStats | None = None) -> Iterator[UdpDatagram]:
    """The UDP datagrams in a capture (IPv4 and IPv6, VLAN tags skipped, first fragments only)."""
    stats = stats if stats is not None else CaptureStats()
    for packet in read_packets(path, stats):
        link = _ip_payload(packet.linktype, packet.data)
        if link is None:
            stats.unsupported_linktype += 1
            continue
        ethertype, ip = link
        if ethertype == ETHERTYPE_IPV4 and len(ip) >= 20 and ip[0] >> 4 == 4:
            ihl = (ip[0] & 0x0F) * 4
            total = struct.unpack_from(">H", ip, 2)[0]
            frag = struct.unpack_from(">H", ip, 6)[0]
            proto = ip[9]
            src, dst = ".".join(map(str, ip[12:16])), ".".join(map(str, ip[16:20]))
            if frag & 0x1FFF:
                stats.fragments += 1
                continue
            transport = ip[ihl:total] if ihl <= total <= len(ip) else ip[ihl:]
        elif ethertype == ETHERTYPE_IPV6 and len(ip) >= 40:
            proto = ip[6]  # extension headers are not followed: RSSP-I links do not use them
            src, dst = _ipv6_text(ip[8:24]), _ipv6_text(ip[24:40])
            transport = ip[40:]
        else:
            stats.not_udp += 1
            continue
        if proto != IPPROTO_UDP or len(transport) < 8:
            stats.not_udp += 1
            continue
        sport, dport, ulen = struct.unpack_from(">HHH", transport, 0)
        payload = transport[8:ulen] if 8 <= ulen <= len(transport) else transport[8:]
        if ulen > len(transport):
            stats.truncated += 1
        stats.udp += 1
        yield UdpDatagram(packet.timestamp_s, src, sport, dst, dport, payload)
