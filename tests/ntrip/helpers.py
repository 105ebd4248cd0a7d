"""Test helpers for the caster: a config with users and mountpoints, raw-socket NTRIP peers."""

from __future__ import annotations

import base64
import socket
import time
from pathlib import Path

from augwire.passwords import hash_password
from augwire.rtcm_framing import split_frames as split_rtcm3_frames
from ntrip_caster.auth import PUBLIC, User
from ntrip_caster.config import CasterConfig, Limits, MountConfig

# Cheap scrypt (N=2^10) for test users: the format and code path are the real ones.
FAST = {"log2_n": 10}
TRAIN_PW = "train-secret"
STATION_PW = "station-secret"


def make_config(*, limits: Limits | None = None, extra_mounts: tuple[MountConfig, ...] = (),
                allow_unknown_sources: bool = False) -> CasterConfig:
    users = {
        "train1": User("train1", hash_password(TRAIN_PW, **FAST), frozenset({"trains"})),
        "station1": User("station1", hash_password(STATION_PW, **FAST), frozenset({"stations"})),
        "intruder": User("intruder", hash_password("x", **FAST), frozenset({"visitors"})),
        "ops": User("ops", hash_password("ops-secret", **FAST), frozenset({"admin"})),
    }
    mounts = (
        MountConfig("OPEN", "source", frozenset({PUBLIC}), frozenset({"stations"}),
                    {"latitude": 31.0, "longitude": 121.0, "identifier": "Open"}),
        MountConfig("BASE01", "source", frozenset({"trains"}), frozenset({"stations"}),
                    {"latitude": 31.00, "longitude": 121.00}),
        MountConfig("BASE02", "source", frozenset({"trains"}), frozenset({"stations"}),
                    {"latitude": 31.00, "longitude": 121.50}),
        MountConfig("NEAR", "nearest", frozenset({"trains"})),
    ) + extra_mounts
    return CasterConfig(host="127.0.0.1", port=0, limits=limits or Limits(), users=users,
                        mounts=mounts, allow_unknown_sources=allow_unknown_sources)


def basic(user: str, password: str) -> str:
    return "Basic " + base64.b64encode(f"{user}:{password}".encode()).decode()


def connect(port: int, timeout: float = 5.0) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def read_until(sock: socket.socket, marker: bytes, limit: int = 1 << 20) -> bytes:
    buf = b""
    while marker not in buf:
        data = sock.recv(65536)
        if not data:
            break
        buf += data
        if len(buf) > limit:
            break
    return buf


def read_all(sock: socket.socket, timeout: float = 5.0) -> bytes:
    sock.settimeout(timeout)
    out = b""
    while True:
        try:
            data = sock.recv(65536)
        except (TimeoutError, ConnectionResetError):  # a dropped client is aborted (RST)
            break
        if not data:
            break
        out += data
    return out


def read_exactly(sock: socket.socket, n: int, timeout: float = 10.0) -> bytes:
    sock.settimeout(timeout)
    out = bytearray()
    while len(out) < n:
        data = sock.recv(n - len(out))
        if not data:
            break
        out += data
    return bytes(out)


def open_v1_source(port: int, mount: str, password: str = STATION_PW) -> socket.socket:
    s = connect(port)
    s.sendall(f"SOURCE {password} /{mount}\r\nSource-Agent: NTRIP test\r\n\r\n".encode())
    reply = read_until(s, b"\r\n")
    assert reply == b"ICY 200 OK\r\n", reply
    return s


def open_v2_source(port: int, mount: str, user: str = "station1", password: str = STATION_PW
                   ) -> socket.socket:
    s = connect(port)
    s.sendall((f"POST /{mount} HTTP/1.1\r\nHost: x\r\nNtrip-Version: Ntrip/2.0\r\n"
               f"Authorization: {basic(user, password)}\r\nUser-Agent: NTRIP test\r\n"
               "Transfer-Encoding: chunked\r\n\r\n").encode())
    reply = read_until(s, b"\r\n\r\n")
    assert reply.startswith(b"HTTP/1.1 200 OK\r\n"), reply
    return s


def open_client(port: int, mount: str, version: int = 1, user: str | None = "train1",
                password: str = TRAIN_PW, gga: bytes | None = None) -> tuple[socket.socket, bytes]:
    """Connect a raw client; returns the socket and the response head (stream data not consumed)."""
    s = connect(port)
    lines = [f"GET /{mount} HTTP/1.1" if version == 2 else f"GET /{mount} HTTP/1.0",
             "Host: 127.0.0.1", "User-Agent: NTRIP test"]
    if version == 2:
        lines.append("Ntrip-Version: Ntrip/2.0")
        if gga is not None:
            lines.append("Ntrip-GGA: " + gga.decode().strip())
    if user is not None:
        lines.append("Authorization: " + basic(user, password))
    req = ("\r\n".join(lines) + "\r\n\r\n").encode()
    if version == 1 and gga is not None:
        req += gga
    s.sendall(req)
    head = read_until(s, b"\r\n\r\n" if version == 2 else b"\r\n")
    return s, head


def dechunk(data: bytes) -> bytes:
    out, pos = b"", 0
    while True:
        end = data.index(b"\r\n", pos)
        size = int(data[pos:end].split(b";")[0], 16)
        if size == 0:
            return out
        out += data[end + 2:end + 2 + size]
        assert data[end + 2 + size:end + 4 + size] == b"\r\n"
        pos = end + 4 + size


def wait_for(pred, timeout: float = 10.0, interval: float = 0.02) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return
        time.sleep(interval)
    raise AssertionError(f"condition not met within {timeout} s")


def rtcm_sample(shared_data: Path, name: str = "GMSD7_20121014.rtcm3", n_bytes: int | None = None
                ) -> bytes:
    """Whole frames from a real capture (the GMSD7 file is cut mid-frame: keep whole frames)."""
    raw = (shared_data / "rtcm" / name).read_bytes()
    frames = split_rtcm3_frames(raw if n_bytes is None else raw[: n_bytes + 1100])
    out = b""
    for f in frames:
        if n_bytes is not None and len(out) + len(f) > n_bytes:
            break
        out += f
    return out
