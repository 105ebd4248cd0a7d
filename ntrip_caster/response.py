"""Every byte string the caster answers with, per NTRIP version (ntrip.md).

Pure functions: inputs in, bytes out. The exact v1 stream reply matters: RTKLIB accepts only
`ICY 200 OK\r\n` and keeps whatever follows it as stream data, so nothing else is sent before the
RTCM bytes.
"""

from __future__ import annotations

from email.utils import formatdate
from http import HTTPStatus

SERVER_NAME = "augnet-ntrip-caster/0.1"
DEFAULT_REALM = "augnet"

V1_STREAM_OK = b"ICY 200 OK\r\n"
V1_SOURCE_OK = b"ICY 200 OK\r\n"
V1_SOURCE_BAD_PASSWORD = b"ERROR - Bad Password\r\n"
V1_SOURCE_MOUNT_TAKEN = b"ERROR - Mount Point Taken or Invalid\r\n"
# Throttled or busy: no NTRIP 1 source reply exists for these; BKG's caster style, read as a refusal.
V1_SOURCE_TOO_MANY = b"ERROR - Too many attempts\r\n"
V1_SOURCE_BUSY = b"ERROR - Server busy\r\n"


def http_date() -> str:
    return formatdate(usegmt=True)


def _reason(status: int) -> str:
    try:
        return HTTPStatus(status).phrase
    except ValueError:
        return "Error"


def _lines(first: str, headers: list[tuple[str, str]]) -> bytes:
    return ("\r\n".join([first] + [f"{k}: {v}" for k, v in headers]) + "\r\n\r\n").encode("latin-1")


def stream_ok(version: int) -> bytes:
    """Reply that starts a correction stream to a client."""
    if version == 1:
        return V1_STREAM_OK
    return _lines("HTTP/1.1 200 OK", [
        ("Ntrip-Version", "Ntrip/2.0"),
        ("Server", SERVER_NAME),
        ("Date", http_date()),
        ("Cache-Control", "no-store,no-cache,max-age=0"),
        ("Pragma", "no-cache"),
        ("Connection", "close"),
        ("Content-Type", "gnss/data"),
        ("Transfer-Encoding", "chunked"),
    ])


def source_ok(version: int) -> bytes:
    """Reply that accepts an upload from a source."""
    if version == 1:
        return V1_SOURCE_OK
    return _lines("HTTP/1.1 200 OK", [
        ("Ntrip-Version", "Ntrip/2.0"),
        ("Server", SERVER_NAME),
        ("Date", http_date()),
        ("Connection", "close"),
    ])


def sourcetable_response(version: int, body: bytes) -> bytes:
    """The sourcetable with its head; `body` already ends with ENDSOURCETABLE."""
    if version == 1:
        return _lines("SOURCETABLE 200 OK", [
            ("Server", SERVER_NAME),
            ("Date", http_date()),
            ("Connection", "close"),
            ("Content-Type", "text/plain"),
            ("Content-Length", str(len(body))),
        ]) + body
    return _lines("HTTP/1.1 200 OK", [
        ("Ntrip-Version", "Ntrip/2.0"),
        ("Server", SERVER_NAME),
        ("Date", http_date()),
        ("Connection", "close"),
        ("Content-Type", "gnss/sourcetable"),
        ("Content-Length", str(len(body))),
    ]) + body


def error_response(version: int, status: int, message: str = "", *, realm: str = DEFAULT_REALM,
                   source_v1: bool = False, retry_after: int | None = None) -> bytes:
    """An error reply. v1 sources get the `ERROR - ...` lines RTKLIB and BKG's server expect;
    v1 clients an HTTP/1.0 status; v2 peers an HTTP/1.1 status with Ntrip-Version.
    `retry_after` [s] adds Retry-After (429, 503; RFC 9110 10.2.3) where the reply is HTTP."""
    if source_v1:
        if status == 503 and retry_after is not None:  # busy for now (a full caster stays "taken")
            return V1_SOURCE_BUSY
        return {401: V1_SOURCE_BAD_PASSWORD, 429: V1_SOURCE_TOO_MANY}.get(status, V1_SOURCE_MOUNT_TAKEN)
    body = (message or _reason(status)).replace("\r", " ").replace("\n", " ").encode("utf-8") + b"\r\n"
    headers: list[tuple[str, str]] = []
    if version == 2:
        headers.append(("Ntrip-Version", "Ntrip/2.0"))
    headers += [("Server", SERVER_NAME), ("Date", http_date())]
    if status == 401:
        headers.append(("WWW-Authenticate", f'Basic realm="{realm}"'))
    if retry_after is not None:
        headers.append(("Retry-After", str(int(retry_after))))
    headers += [("Connection", "close"), ("Content-Type", "text/plain"),
                ("Content-Length", str(len(body)))]
    first = f"{'HTTP/1.1' if version == 2 else 'HTTP/1.0'} {status} {_reason(status)}"
    return _lines(first, headers) + body


def json_response(body: bytes) -> bytes:
    """An HTTP/1.1 200 carrying a JSON document (the statistics endpoint)."""
    return _lines("HTTP/1.1 200 OK", [
        ("Server", SERVER_NAME),
        ("Date", http_date()),
        ("Connection", "close"),
        ("Cache-Control", "no-store"),
        ("Content-Type", "application/json"),
        ("Content-Length", str(len(body))),
    ]) + body
