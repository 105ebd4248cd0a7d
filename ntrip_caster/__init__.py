"""NTRIP 1.0 / 2.0 caster: a sans-IO protocol core and an asyncio server.

Protocol core (bytes in, events out; no sockets, no clock):
  request.py        parse one request head (client GET, v1 SOURCE, v2 POST) into NtripRequest
  connection.py     NtripServerConnection.receive_data(bytes) -> events (h11 style)
  response.py       every reply, per NTRIP version (ICY 200 OK, HTTP/1.1 + chunked, errors)
  sourcetable.py    STR / CAS / NET records, rendering, parsing, v2 filtering
  gga.py            GGA extraction, parsing and distances
  reposition.py     when a GGA moves a client's VRS point; nearest base with hysteresis
  limits.py         every limit and timeout, named once, with its precedent

From `augwire` (the wire package the caster shares with augnet, which it never imports): chunked
transfer coding, RTCM 3 frame boundaries and the frame aligner for frame-aligned fan-out, CRC-24Q,
scrypt password hashes, and NtripProtocolError(status), the one error the protocol core raises.

Server:
  server.py         Caster: mountpoints, sessions, auth, limits, fan-out, taps, stats, shutdown
  auth.py           users, groups, verified-credential cache
  config.py         TOML / YAML configuration
  stream_factory.py the interface VRS mountpoints use (implemented by augnet.centre later)
  relay_factory.py  a factory relaying one source mountpoint per client (tests, load tests)
  embedded.py       run a caster in a background thread
  cli.py            `ntrip-caster serve ...` / `augnet caster ...`
  loadtest.py       `augnet loadtest run|sweep`: per-epoch delivery latency under load
"""
