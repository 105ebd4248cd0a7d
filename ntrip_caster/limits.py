"""Every limit and timeout the caster enforces, named once, with its unit and the precedent it follows.

The server reads its defaults from here; a config file may override the ones marked configurable
(see `config.py`). Tests import these names rather than repeating numbers.
"""

from __future__ import annotations

from augwire.chunked import MAX_CHUNK_BYTES

# --- request head -----------------------------------------------------------------------------
# Whole request head (request line + headers + blank line). Apache LimitRequestFieldSize 8190 per
# line, Tomcat maxHttpHeaderSize 8 KiB, nginx large_client_header_buffers 8 KiB; an NTRIP request is
# a few hundred bytes (the largest real one is a v2 POST with an Ntrip-STR line, ~300 B).
MAX_REQUEST_HEAD_BYTES = 8 * 1024
# Header fields per request. Apache LimitRequestFields 100; real NTRIP clients send 3-8.
MAX_HEADER_FIELDS = 100
# Seconds a connection may take to deliver its whole request head before it is closed (slow-loris
# defence). nginx client_header_timeout 60 s, Apache mod_reqtimeout header=20-40 s; every NTRIP
# client sends its request in one write right after connecting, so 10 s is generous. Configurable.
REQUEST_HEAD_TIMEOUT_S = 10.0

# --- sources -----------------------------------------------------------------------------------
# A source silent this long is dropped so its mountpoint can be taken again (ntrip.md: 60 s is a
# common default; BKG's caster and Millipede both use a minute). Configurable.
SOURCE_IDLE_TIMEOUT_S = 60.0
# Largest chunk a v2 source may announce (64 KiB; configurable), and the longest chunk-size line
# (1 KiB): the chunked decoder's bounds, named with their reasons in augwire/chunked.py.
MAX_SOURCE_CHUNK_BYTES = MAX_CHUNK_BYTES

# --- clients -----------------------------------------------------------------------------------
# Bytes queued for one client beyond which the client is dropped: a slow client must never slow the
# others. Millipede's choice is 16 KiB (ntrip.md); at 1 KB/s that is 16 s of corrections, already
# useless to a train. Configurable.
MAX_CLIENT_BACKLOG_BYTES = 16 * 1024
# Kernel send buffer per client socket (SO_SNDBUF; Linux doubles it). Without it a stalled client
# can hold up to tcp_wmem max (4 MiB) of kernel memory before the backlog bound even sees it:
# 10,000 trains x 4 MiB is 40 GiB. 64 KiB still sustains 320 KB/s over a 200 ms cellular round
# trip, far above an RTCM stream's 1-10 KB/s. 0 leaves the kernel's autotuning. Configurable.
CLIENT_SEND_BUFFER_BYTES = 64 * 1024
# Longest line a client may send after its request (GGA updates). NMEA 0183 caps a sentence at 82
# characters; receivers with extra precision reach ~100. 256 bounds the line buffer.
MAX_NMEA_LINE_BYTES = 256
# Bytes a client may send upstream per second before it is considered hostile and dropped:
# ten GGA sentences a second (ntrip.md: some clients send 10 Hz) at ~100 B is 1 KB/s.
MAX_CLIENT_UPLOAD_BYTES_PER_S = 16 * 1024

# --- GGA handling (ntrip.md; one open caster's policy) -----------------------------------------
# Parse at most one GGA per client per second; a 10 Hz client costs the same as a 1 Hz one.
GGA_MIN_INTERVAL_S = 1.0
# Re-evaluate a client's VRS point / nearest base at most this often ...
REPOSITION_MIN_INTERVAL_S = 10.0
# ... and always after this long, even without movement ...
REPOSITION_MAX_INTERVAL_S = 120.0
# ... and otherwise only after this much movement.
REPOSITION_MIN_MOVE_M = 10.0
# A client switches to another base only when that base is this much nearer than its current one.
BASE_SWITCH_HYSTERESIS_M = 500.0

# --- server-wide (configurable) -----------------------------------------------------------------
# BKG's professional caster documents 1,000 clients by default; ours is sized for 10,000 trains
# per node (issue 4). Per-IP limit guards against one misbehaving host; 0 disables it.
MAX_CLIENTS = 20_000
MAX_CLIENTS_PER_MOUNT = 20_000
MAX_CLIENTS_PER_IP = 0
# Connections per address that are not yet a client or a source (request head or credentials pending).
# An NTRIP client sends its request at once and waits a few ms for the answer, so even 100 trains behind
# one carrier NAT starting together stay far below this; a flood of half-open guesses does not (issue 19).
MAX_PENDING_PER_IP = 256

# --- password verification (issue 19) -----------------------------------------------------------
# Threads that run scrypt, the caster's own pool (never the loop's default executor, which other parts
# of a process may use): the 2-core deployment gives one core at most to hashing.
AUTH_WORKERS = 1
# Verifications queued or running beyond which a new one is refused at once with 503 and Retry-After:
# at ~30 ms per scrypt (N=2^14) this bounds the wait to ~2 s, and a queue never grows without end.
AUTH_QUEUE_MAX = 64
# Retry-After [s] of that 503.
AUTH_BUSY_RETRY_S = 2
# Mountpoints unknown sources may create when the caster accepts them (open test casters): each
# holds a table entry and statistics, so a hostile uploader must not create them without end.
MAX_AUTO_MOUNTS = 1000
# Seconds graceful shutdown waits for queued output to drain before closing connections.
SHUTDOWN_DRAIN_S = 2.0
