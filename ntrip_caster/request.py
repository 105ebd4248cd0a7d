"""Parsing one NTRIP request head (request line + header fields) into a typed request.

What each client sends (ntrip.md):
  v1 client   GET /MOUNT HTTP/1.0 (or 1.1)     no Ntrip-Version header; GGA as a line after the head
  v2 client   GET /MOUNT HTTP/1.1              Ntrip-Version: Ntrip/2.0; GGA maybe in Ntrip-GGA
  v1 source   SOURCE <password> <MOUNT>        Source-Agent, optional STR; mount with or without '/'
  v2 source   POST /MOUNT HTTP/1.1             Ntrip-Version, Basic auth, Ntrip-STR, chunked body
The version is decided by the Ntrip-Version header alone, never by the HTTP version.
"""

from __future__ import annotations

import base64
import binascii
import re
from dataclasses import dataclass, field
from urllib.parse import unquote

from augwire.errors import NtripProtocolError

from .gga import GgaFix, parse_gga
from .limits import MAX_HEADER_FIELDS

# RFC 9110 token characters for header names.
_TOKEN_RE = re.compile(rb"^[!#$%&'*+\-.^_`|~0-9A-Za-z]+$")
# Mountpoint names: NTRIP 2.0 allows letters, digits, '-', '_' and '.'; anything else cannot name a
# mountpoint of ours, so it is treated as unknown (sourcetable / 404), not as malformed.
_MOUNT_RE = re.compile(r"^[A-Za-z0-9_.\-]{1,100}$")
_HTTP_VERSIONS = (b"HTTP/1.0", b"HTTP/1.1")
# Methods HTTP knows that NTRIP has no use for: 501, per RFC 9110 section 15.6.2.
_KNOWN_HTTP_METHODS = (b"HEAD", b"PUT", b"DELETE", b"OPTIONS", b"TRACE", b"CONNECT", b"PATCH")


@dataclass(frozen=True, slots=True)
class NtripRequest:
    """One parsed request head."""

    kind: str  # "client" (GET) or "source" (SOURCE / POST)
    version: int  # 1 or 2 (Ntrip-Version header)
    mount: str  # without leading '/'; "" asks for the sourcetable
    valid_mount: bool  # False when the name cannot be a mountpoint (answered like an unknown one)
    query: str  # after '?', percent-decoded (v2 sourcetable filter)
    user: str | None
    password: str | None
    headers: dict[str, str] = field(default_factory=dict)  # lower-case names; last value wins
    gga: GgaFix | None = None  # from Ntrip-GGA
    str_record: str | None = None  # v1 "STR:" / v2 "Ntrip-STR:" header of a source
    chunked: bool = False  # v2 source body uses chunked transfer coding
    http_version: str = "HTTP/1.0"

    @property
    def user_agent(self) -> str:
        return self.headers.get("user-agent", self.headers.get("source-agent", ""))


def _basic_credentials(value: str) -> tuple[str | None, str | None]:
    scheme, _, token = value.strip().partition(" ")
    if scheme.lower() != "basic" or not token.strip():
        return None, None
    try:
        decoded = base64.b64decode(token.strip(), validate=True).decode("utf-8")
    except (binascii.Error, UnicodeDecodeError, ValueError):
        return None, None
    user, sep, password = decoded.partition(":")
    if not sep:
        return None, None
    return user, password


def _split_target(target: bytes) -> tuple[str, bool, str]:
    text = target.decode("latin-1")
    if text.startswith("http://") or text.startswith("https://"):  # absolute-form (RFC 9112 3.2.2)
        rest = text.split("://", 1)[1]
        text = "/" + rest.split("/", 1)[1] if "/" in rest else "/"
    path, _, query = text.partition("?")
    mount = unquote(path.lstrip("/"))
    if mount == "":
        return "", True, unquote(query)
    return mount, bool(_MOUNT_RE.match(mount)), unquote(query)


def parse_request_head(head: bytes) -> NtripRequest:
    """Parse a request head (everything before the blank line, line ends CRLF or LF).

    Raises `NtripProtocolError` with 400 (malformed), 501 (a method NTRIP does not use) or 505
    (an HTTP version other than 1.0/1.1).
    """
    lines = head.replace(b"\r\n", b"\n").split(b"\n")
    request_line = lines[0].strip()
    if not request_line:
        raise NtripProtocolError(400, "empty request line")
    if any(b < 0x20 and b != 0x09 for b in request_line) or b"\x7f" in request_line:
        raise NtripProtocolError(400, "control characters in request line")
    parts = request_line.split()
    method = parts[0]

    headers: dict[str, str] = {}
    header_lines = [ln for ln in lines[1:] if ln.strip()]
    if len(header_lines) > MAX_HEADER_FIELDS:
        raise NtripProtocolError(431, f"more than {MAX_HEADER_FIELDS} header fields")
    for raw in header_lines:
        if raw[:1] in (b" ", b"\t"):
            raise NtripProtocolError(400, "obsolete header line folding")
        name, sep, value = raw.partition(b":")
        if not sep or not _TOKEN_RE.match(name):
            raise NtripProtocolError(400, f"malformed header line {raw[:40]!r}")
        headers[name.decode("ascii").lower()] = value.strip().decode("latin-1")

    version = 2 if headers.get("ntrip-version", "").strip().lower() == "ntrip/2.0" else 1

    if method == b"SOURCE":
        # SOURCE <password> <mount> [HTTP/1.x]; an empty password leaves only the mount.
        if len(parts) == 2:
            password, target = b"", parts[1]
        elif len(parts) in (3, 4):
            password, target = parts[1], parts[2]
        else:
            raise NtripProtocolError(400, "SOURCE needs a password and a mountpoint")
        mount, valid, _ = _split_target(target if target.startswith(b"/") else b"/" + target)
        if not mount:
            raise NtripProtocolError(400, "SOURCE without a mountpoint")
        user, pw = _basic_credentials(headers.get("authorization", ""))
        return NtripRequest(
            kind="source", version=1, mount=mount, valid_mount=valid, query="",
            user=user, password=password.decode("latin-1") if user is None else pw,
            headers=headers, str_record=headers.get("str"), http_version="",
        )

    if method not in (b"GET", b"POST"):
        if method in _KNOWN_HTTP_METHODS:
            raise NtripProtocolError(501, f"method {method[:20]!r} not implemented")
        raise NtripProtocolError(400, f"unknown method {method[:20]!r}")
    if len(parts) != 3:
        raise NtripProtocolError(400, "request line must be METHOD TARGET HTTP/1.x")
    if parts[2] not in _HTTP_VERSIONS:
        if parts[2].startswith(b"HTTP/"):
            raise NtripProtocolError(505, f"HTTP version {parts[2][:12]!r} not supported")
        raise NtripProtocolError(400, "request line must end with HTTP/1.0 or HTTP/1.1")
    mount, valid, query = _split_target(parts[1])
    user, password = _basic_credentials(headers.get("authorization", ""))
    http_version = parts[2].decode("ascii")

    if method == b"POST":
        if not mount:
            raise NtripProtocolError(400, "POST without a mountpoint")
        te = headers.get("transfer-encoding", "").strip().lower()
        if te not in ("", "chunked"):
            raise NtripProtocolError(501, f"transfer coding {te[:20]!r} not implemented")
        return NtripRequest(
            kind="source", version=version, mount=mount, valid_mount=valid, query=query,
            user=user, password=password, headers=headers,
            str_record=headers.get("ntrip-str"), chunked=te == "chunked", http_version=http_version,
        )

    gga_header = headers.get("ntrip-gga")
    gga = parse_gga(gga_header.encode("latin-1")) if gga_header else None
    return NtripRequest(
        kind="client", version=version, mount=mount, valid_mount=valid, query=query,
        user=user, password=password, headers=headers, gga=gga, http_version=http_version,
    )
